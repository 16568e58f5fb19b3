"""Ingest of a full-rate log (decode + align) vs cantools per frame and bare mcap iteration.

The log (10 h full size, 6 min with --quick) is a contract-correct synthetic one: J1939 broadcast
at truck rates plus unrelated traffic to ~1390 frames/s (about 50 M frames in 10 h), IMU at
952 Hz (34 M samples), barometer, humidity, magnetometer, GPS and time sync, written by
`logger.writer.LogWriter` in 256 KiB zstd chunks, cached in ``.bench-cache/``. Our ingest and
the bare mcap iteration each run in a fresh process (seconds and peak RSS of that process).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from bench import CACHE_DIR, result

FRAMES_PER_S = 1389.0
CANTOOLS_SAMPLE = 200_000
DECODE_SAMPLE = 4_000_000
PERIODIC_HZ = 100 + 20 + 10 + 5 + 10 + 10 + 1 + 7 / 5.0
"""The synthetic log's J1939 broadcasts (EEC1, EEC2, CCVS1 ×2, ETC2, LFE, CVW, EC1 BAM)."""


def _log(quick: bool) -> tuple[Path, float]:
    from haulprofile.testing import logs as synthetic

    hours = 0.1 if quick else 10.0
    path = CACHE_DIR / f"ingest-{hours:g}h-v1.mcap"
    if not path.exists():
        partial = path.with_suffix(".partial")
        with open(partial, "wb") as stream:
            synthetic.write_log(stream, hours * 3600, seed=10, filler_hz=FRAMES_PER_S - PERIODIC_HZ)
        partial.rename(path)
    return path, hours


_OURS = """
import json, sys, time
def peak_rss_mb():
    # VmHWM: this process's own high-water mark (ru_maxrss would include the parent's at fork)
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM")) / 1024
t0 = time.perf_counter()
from haulprofile.analysis.ingest import ingest_logs
frame, summary = ingest_logs([sys.argv[1]])
elapsed = time.perf_counter() - t0
print(json.dumps({"seconds": elapsed, "rows": len(frame), "can_frames": summary["can_frames"],
                  "imu_samples": summary["imu_samples"], "valid": summary["valid_fraction"],
                  "peak_rss_mb": peak_rss_mb()}))
"""

_BARE = """
import json, sys, time
def peak_rss_mb():
    # VmHWM: this process's own high-water mark (ru_maxrss would include the parent's at fork)
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM")) / 1024
t0 = time.perf_counter()
from mcap.reader import make_reader
count = size = 0
with open(sys.argv[1], "rb") as stream:
    for _, _, message in make_reader(stream).iter_messages(log_time_order=False):
        count += 1
        size += len(message.data)
print(json.dumps({"seconds": time.perf_counter() - t0, "messages": count, "bytes": size,
                  "peak_rss_mb": peak_rss_mb()}))
"""


def _fresh(code: str, path: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _j1939_database():
    import cantools
    from haulprofile.contract import j1939

    lines = ['VERSION ""', "", "NS_ :", "", "BS_:", "", "BU_:", ""]
    for pgn in sorted({s.pgn for s in j1939.SPNS.values()} - set(j1939.PGN_LENGTH)):
        lines.append(f"BO_ {j1939.make_id(pgn, 0xFE) | 0x80000000} {j1939.PGN_NAMES[pgn]}: 8 Vector__XXX")
        for spn in j1939.spns_of(pgn):
            lines.append(f' SG_ {spn.name} : {spn.bit_offset}|{spn.length_bits}@1+ ({spn.resolution!r},'
                         f'{spn.offset!r}) [0|0] "{spn.unit}" Vector__XXX')
    lines += ['BA_DEF_  "ProtocolType" STRING ;', 'BA_ "ProtocolType" "J1939";']
    return cantools.database.load_string("\n".join(lines) + "\n", "dbc", frame_id_mask=0x03FFFF00)


def _frame_sample(path: Path, count: int) -> np.ndarray:
    """The first ``count`` CAN frames of the log."""
    from haulprofile.analysis.ingest import iter_log_messages
    from haulprofile import contract

    parts, have = [], 0
    for message in iter_log_messages([path]):
        if message.topic == contract.CAN_FRAMES.name:
            parts.append(message.data)
            have += len(message.data) // contract.CAN_FRAME_DTYPE.itemsize
            if have >= count:
                break
    return np.frombuffer(b"".join(parts), contract.CAN_FRAME_DTYPE)[:count]


def bench_ingest(quick: bool):
    from haulprofile.analysis.ingest import j1939_decode
    from haulprofile.analysis.ingest.columns import build_table
    from haulprofile.analysis.ingest.table import BLOCK_FRAMES, Ingest

    path, hours = _log(quick)
    ours = _fresh(_OURS, path)
    bare = _fresh(_BARE, path)
    frames = _frame_sample(path, DECODE_SAMPLE)
    database = _j1939_database()
    known = {m.frame_id & 0x03FFFF00 for m in database.messages}
    work = [(int(f["arbitration_id"]), f["data"].tobytes()) for f in frames[:CANTOOLS_SAMPLE]
            if int(f["arbitration_id"]) & 0x03FFFF00 in known]
    t0 = time.perf_counter()
    for frame_id, data in work:
        # decode_message looks ids up unmasked; J1939 matching needs get_message_by_frame_id
        database.get_message_by_frame_id(frame_id).decode(data, decode_choices=False)
    cantools_s = time.perf_counter() - t0
    decoded_by_cantools = len(work)
    t0 = time.perf_counter()
    j1939_decode.decode_block(frames)
    vector_s = time.perf_counter() - t0
    ingest = Ingest(10.0)
    t0 = time.perf_counter()
    for start in range(0, len(frames), BLOCK_FRAMES):
        ingest.feed_frames(frames[start:start + BLOCK_FRAMES])
    ingest.finish_streams()
    build_table(ingest)
    decode_align_s = time.perf_counter() - t0
    n_frames = ours["can_frames"]
    per_frame_ours_ns = ours["seconds"] / n_frames * 1e9
    cantools_per_frame_ns = cantools_s / max(decoded_by_cantools, 1) * 1e9
    return [
        result("ingest_decode_align_s_per_log_hour", ours["seconds"] / hours, "s per hour of log",
               "bare mcap iteration (make_reader.iter_messages)", bare["seconds"] / hours,
               hours=hours, can_frames=n_frames, imu_samples=ours["imu_samples"], rows=ours["rows"],
               frames_per_s=n_frames / ours["seconds"], messages=bare["messages"]),
        result("ingest_whole_pipeline_ns_per_can_frame", per_frame_ours_ns, "ns/frame (read+decode+align, all topics)",
               "cantools per-frame decode (J1939 DBC, sample)", cantools_per_frame_ns,
               cantools_sample_frames=CANTOOLS_SAMPLE, cantools_decoded=decoded_by_cantools),
        result("ingest_decode_align_no_io_ns_per_frame", decode_align_s / len(frames) * 1e9,
               "ns/frame (J1939+TP+OBD decode, binning, table; first 4 M frames)", "cantools per-frame decode (frames it knows)",
               cantools_per_frame_ns),
        result("ingest_vectorised_j1939_decode_ns_per_frame", vector_s / len(frames) * 1e9,
               "ns/frame (first 4 M frames)", "cantools per-frame decode (frames it knows)",
               cantools_per_frame_ns),
        result("ingest_peak_rss_mb", ours["peak_rss_mb"], "MB (fresh process)", "bare mcap iteration",
               bare["peak_rss_mb"]),
    ]


BENCHMARKS = [bench_ingest]
