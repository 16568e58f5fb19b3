"""MF4 export of a full-rate log (`analyze export --to mf4`) beside asammdf's own write of the same
frames.

The log is the ingest benchmark's (10 h, 50 M CAN frames; 6 min with --quick), cached in
``.bench-cache/``. Ours, in a fresh process: the whole export (read the log, decode the signals
table, write CAN_DataFrame bus-logging records and the decoded channels, asammdf's transposed
deflate). The peer, in another fresh process after it: the same frames already in memory in the
same bus-logging layout, handed to asammdf as one structure signal and saved with the same
compression (what a user of asammdf alone would write); our write step alone is timed in that
process too, on the same frames. Wall and CPU seconds both (a shared machine inflates wall time).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

from bench import result
from benchmarks.ingest import _log

_OURS = """
import json, sys, time
def peak_rss_mb():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM")) / 1024
t0 = time.perf_counter()
from haulprofile.analysis.export import export_logs
done = export_logs([sys.argv[1]], "mf4", sys.argv[2])[0]
print(json.dumps({"seconds": time.perf_counter() - t0, "cpu_s": time.process_time(), "frames": done.frames,
                  "rows": done.signals, "bytes": done.target.stat().st_size, "peak_rss_mb": peak_rss_mb()}))
"""

_PEER = """
import json, sys, time
from pathlib import Path
import numpy as np
from asammdf import MDF, Signal
from haulprofile.analysis.export import mf4, source
content = source.load(Path(sys.argv[1]))
frames = content.frames
seconds = (frames["t_mono_ns"].astype(np.int64) - int(frames["t_mono_ns"][0])) / 1e9
records = mf4.bus_records(frames, mf4.DATA_DTYPE)
t0, c0 = time.perf_counter(), time.process_time()
out = MDF(version="4.11")
bus = mf4._bus_source()
out.append(Signal(records, seconds, name="CAN_DataFrame", source=bus), acq_name="CAN_DataFrame", acq_source=bus)
out.save(Path(sys.argv[2]) / "asammdf.mf4", compression=2)
out.close()
peer_s, peer_cpu = time.perf_counter() - t0, time.process_time() - c0
t0, c0 = time.perf_counter(), time.process_time()
mf4.write(content, Path(sys.argv[2]) / "ours-write.mf4")
ours_s, ours_cpu = time.perf_counter() - t0, time.process_time() - c0
print(json.dumps({"asammdf_s": peer_s, "asammdf_cpu_s": peer_cpu, "ours_write_s": ours_s, "ours_write_cpu_s": ours_cpu,
                  "frames": len(frames),
                  "asammdf_bytes": (Path(sys.argv[2]) / "asammdf.mf4").stat().st_size,
                  "ours_bytes": (Path(sys.argv[2]) / "ours-write.mf4").stat().st_size}))
"""


def _fresh(code: str, *args) -> dict:
    done = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def bench_export_mf4(quick: bool):
    path, hours = _log(quick)
    with tempfile.TemporaryDirectory(dir=path.parent) as folder:
        ours = _fresh(_OURS, path, Path(folder) / "ours")
        peer = _fresh(_PEER, path, folder)
    return [
        result("export_mf4_whole_s_per_log_hour", ours["seconds"] / hours, "s per hour of log (read, decode, write)",
               "asammdf append + save of the same frames (in memory, same layout and compression)",
               peer["asammdf_s"] / hours, hours=hours, frames=ours["frames"], rows=ours["rows"],
               cpu_s=ours["cpu_s"], peer_cpu_s=peer["asammdf_cpu_s"], cpu_ratio=peer["asammdf_cpu_s"] / ours["cpu_s"],
               peak_rss_mb=ours["peak_rss_mb"], mf4_bytes=ours["bytes"]),
        result("export_mf4_write_step_s_per_log_hour", peer["ours_write_s"] / hours,
               "s per hour of log (frames in memory to MF4)", "asammdf append + save of the same frames",
               peer["asammdf_s"] / hours, hours=hours, frames=peer["frames"], cpu_s=peer["ours_write_cpu_s"],
               peer_cpu_s=peer["asammdf_cpu_s"], cpu_ratio=peer["asammdf_cpu_s"] / peer["ours_write_cpu_s"],
               ours_bytes=peer["ours_bytes"], peer_bytes=peer["asammdf_bytes"]),
    ]


BENCHMARKS = [bench_export_mf4]
