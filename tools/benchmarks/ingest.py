"""Ingest of a full-rate log (decode + align) vs cantools per frame, bare mcap iteration and the
decompression limit.

The log (10 h full size, 6 min with --quick) is a contract-correct synthetic one (contract 2; the
same log as contract 1 writes it, JSON sensor topics, is ingested beside it): J1939 broadcast
at truck rates plus unrelated traffic to ~1390 frames/s (about 50 M frames in 10 h), IMU at
952 Hz (34 M samples), barometer, humidity, magnetometer, GPS and time sync, written by
`logger.writer.LogWriter` in 256 KiB zstd chunks, cached in ``.bench-cache/``. Each of these runs
in a fresh process (seconds and peak RSS of that process), one after the other in one run:
our ingest (read + decode + align, table built), our reader alone (`contract.reader`, every
chunk checked, walked and its CAN/IMU records scattered into arrays), decompress-only (zstd of
every chunk on the same number of threads, nothing else: the limit) and the bare mcap iteration.
A fresh process's fixed cost (imports, then a 10 s log through the same code so numba's cached
kernels are loaded) is timed inside the ingest's and the reader's own processes and reported apart,
with the figures after it beside the peers' after their imports, so the quick figures mean something.
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


def _log(quick: bool, contract_version: int = 2, hours: float | None = None) -> tuple[Path, float]:
    """The cached synthetic log (contract 2: packed sensor topics, as today's logger writes; 1: a
    JSON message per barometer, humidity and magnetometer sample, as the logger wrote before)."""
    from haulprofile.testing import logs as synthetic

    hours = hours if hours is not None else 0.1 if quick else 10.0
    path = CACHE_DIR / f"ingest-{hours:g}h-{'v1' if contract_version == 1 else f'contract{contract_version}'}.mcap"
    if not path.exists():
        partial = path.with_suffix(".partial")
        with open(partial, "wb") as stream:
            synthetic.write_log(stream, hours * 3600, seed=10, filler_hz=FRAMES_PER_S - PERIODIC_HZ,
                                contract_version=contract_version)
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
imported = time.perf_counter() - t0
ingest_logs([sys.argv[2]])  # a 10 s log: numba's cached kernels loaded, the fixed cost paid
ready, ready_cpu = time.perf_counter(), time.process_time()
frame, summary = ingest_logs([sys.argv[1]])
elapsed = time.perf_counter() - t0
print(json.dumps({"seconds": elapsed, "cpu_s": time.process_time(), "rows": len(frame), "can_frames": summary["can_frames"],
                  "imu_samples": summary["imu_samples"], "valid": summary["valid_fraction"],
                  "startup_s": ready - t0, "startup_cpu_s": ready_cpu, "import_s": imported,
                  "work_s": time.perf_counter() - ready, "work_cpu_s": time.process_time() - ready_cpu,
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
t1 = time.perf_counter()
count = size = 0
with open(sys.argv[1], "rb") as stream:
    for _, _, message in make_reader(stream).iter_messages(log_time_order=False):
        count += 1
        size += len(message.data)
print(json.dumps({"seconds": time.perf_counter() - t0, "work_s": time.perf_counter() - t1, "cpu_s": time.process_time(),
                  "messages": count, "bytes": size, "peak_rss_mb": peak_rss_mb()}))
"""


_READER = """
import json, sys, time
def peak_rss_mb():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM")) / 1024
t0 = time.perf_counter()
from haulprofile.contract import reader
for window in reader.read_windows(sys.argv[2]):  # a 10 s log: numba's cached kernels loaded
    pass
ready, ready_cpu = time.perf_counter(), time.process_time()
records = messages = 0
for window in reader.read_windows(sys.argv[1]):
    messages += len(window)
    for name in reader.PACKED_TOPICS:
        records += len(window.topic_records(name))
print(json.dumps({"seconds": time.perf_counter() - t0, "cpu_s": time.process_time(), "messages": messages, "records": records,
                  "startup_s": ready - t0, "startup_cpu_s": ready_cpu, "work_s": time.perf_counter() - ready,
                  "work_cpu_s": time.process_time() - ready_cpu, "threads": reader.default_threads(),
                  "peak_rss_mb": peak_rss_mb()}))
"""

_DECOMPRESS = """
import json, mmap, struct, sys, time
t0 = time.perf_counter()
from concurrent.futures import ThreadPoolExecutor
import zstandard
from haulprofile.contract import reader
def chunks(buf):
    pos, size = 8, len(buf)
    while pos + 9 <= size:
        opcode, length = struct.unpack_from("<BQ", buf, pos)
        if opcode == 0x06:
            yield pos + 9, pos + 9 + length
        elif opcode not in range(1, 16):
            break
        pos += 9 + length
def decompress(span):
    body = view[span[0]:span[1]]
    size, = struct.unpack_from("<Q", body, 16)
    n, = struct.unpack_from("<I", body, 28)
    return len(zstandard.ZstdDecompressor().decompress(body[32 + n + 8:], max_output_size=size))
t1 = time.perf_counter()
with open(sys.argv[1], "rb") as handle:
    buf = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)
    view = memoryview(buf)
    spans = list(chunks(buf))
    with ThreadPoolExecutor(reader.default_threads()) as pool:
        total = sum(pool.map(decompress, spans, chunksize=16))
    view.release()
print(json.dumps({"seconds": time.perf_counter() - t0, "work_s": time.perf_counter() - t1, "cpu_s": time.process_time(),
                  "chunks": len(spans), "bytes": total}))
"""


def _fresh(code: str, path: Path, *more: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", code, str(path), *map(str, more)], capture_output=True, text=True,
                          check=True)
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
    from haulprofile import contract
    from haulprofile.contract.reader import packed_records

    parts, have = [], 0
    for records in packed_records(path, contract.CAN_FRAMES):
        parts.append(records)
        have += len(records)
        if have >= count:
            break
    return np.concatenate(parts)[:count]


def _feed_cpu_s_per_hour(path: Path, n_windows: int = 8) -> tuple[float, float]:
    """Thread CPU of the decoding thread's `Ingest.feed_window` over the first windows of a log
    (read beforehand; best of 3) per hour of log, and the log's messages per hour."""
    from haulprofile.analysis.ingest.table import Ingest
    from haulprofile.contract import reader

    windows = []
    for window in reader.read_windows(path, threads=1):
        windows.append(window)
        if len(windows) >= n_windows:
            break
    best = np.inf
    for _ in range(3):
        ingest = Ingest(10.0)
        t0 = time.thread_time()
        for window in windows:
            ingest.feed_window(window, 0)
        best = min(best, time.thread_time() - t0)
    hours = (int(windows[-1].publish_times_ns.max()) - int(windows[0].publish_times_ns.min())) / 3.6e12
    return best / hours, sum(len(w) for w in windows) / hours


def bench_ingest(quick: bool):
    from haulprofile.analysis.ingest import j1939_decode
    from haulprofile.analysis.ingest.columns import build_table
    from haulprofile.analysis.ingest.table import BLOCK_FRAMES, Ingest

    path, hours = _log(quick)
    tiny, _ = _log(quick, hours=10 / 3600)
    _fresh(_OURS, tiny, tiny)  # numba's cache filled (compiled once), so every process below only loads it
    ours = _fresh(_OURS, path, tiny)
    alone = _fresh(_READER, path, tiny)
    limit = _fresh(_DECOMPRESS, path)
    bare = _fresh(_BARE, path)
    old_path, _ = _log(quick, contract_version=1)
    ours_v1 = _fresh(_OURS, old_path, tiny)
    limit_v1 = _fresh(_DECOMPRESS, old_path)
    feed_new, messages_new = _feed_cpu_s_per_hour(path)
    feed_old, messages_old = _feed_cpu_s_per_hour(old_path)
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
               frames_per_s=n_frames / ours["seconds"], messages=bare["messages"], cpu_s=ours["cpu_s"],
               peer_cpu_s=bare["cpu_s"]),
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
        result("ingest_read_s_vs_decompress_only", alone["seconds"], "s (contract.reader: every chunk checked, "
               "walked, CAN+IMU scattered; ratio = limit / ours)", "decompress-only (zstd of every chunk, same threads)",
               limit["seconds"], hours=hours, threads=alone["threads"], chunks=limit["chunks"],
               decompressed_bytes=limit["bytes"], messages=alone["messages"], records=alone["records"],
               reader_peak_rss_mb=alone["peak_rss_mb"], cpu_s=alone["cpu_s"], peer_cpu_s=limit["cpu_s"]),
        result("ingest_read_s_vs_bare_mcap", alone["seconds"], "s (contract.reader; ratio = bare mcap / ours)",
               "bare mcap iteration (make_reader.iter_messages)", bare["seconds"], hours=hours, cpu_s=alone["cpu_s"],
               peer_cpu_s=bare["cpu_s"]),
        result("ingest_decode_align_s_vs_decompress_only", ours["seconds"], "s (whole ingest; ratio = limit / ours)",
               "decompress-only (zstd of every chunk, same threads)", limit["seconds"], hours=hours,
               cpu_s=ours["cpu_s"], peer_cpu_s=limit["cpu_s"]),
        result("ingest_startup_s", ours["startup_s"], "s (the ingest's process before the log: imports, numba's "
               "cached kernels loaded by a 10 s log; in every fresh-process figure above)", None, None,
               cpu_s=ours["startup_cpu_s"], import_s=ours["import_s"], reader_startup_s=alone["startup_s"],
               reader_startup_cpu_s=alone["startup_cpu_s"]),
        result("ingest_minus_startup_s_vs_decompress_only", ours["work_s"],
               "s (whole ingest after the start-up; ratio = limit / ours)", "decompress-only after its imports",
               limit["work_s"], hours=hours, cpu_s=ours["work_cpu_s"]),
        result("ingest_reader_minus_startup_s_vs_bare_mcap", alone["work_s"],
               "s (contract.reader after its start-up; ratio = bare mcap / ours)", "bare mcap iteration after its import",
               bare["work_s"], hours=hours, cpu_s=alone["work_cpu_s"]),
        result("ingest_decoding_thread_cpu_s_per_log_hour_vs_contract1", feed_new, "s CPU per hour of log "
               "(Ingest.feed_window, windows read beforehand; ratio = contract 1 / contract 2)",
               "the same log as contract 1 writes it", feed_old, messages_per_hour=messages_new,
               peer_messages_per_hour=messages_old),
        result("ingest_contract1_log_s_vs_decompress_only", ours_v1["seconds"], "s (whole ingest of the same log "
               "written as contract 1: JSON sensor topics; ratio = limit / ours)", "decompress-only of that log",
               limit_v1["seconds"], hours=hours, cpu_s=ours_v1["cpu_s"], peer_cpu_s=limit_v1["cpu_s"]),
    ]


BENCHMARKS = [bench_ingest]
