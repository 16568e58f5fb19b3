"""Encryption at rest: CPU per MB of `haulprofile.logger.encryption.encrypt_log` (age via pyrage:
read the closed log, X25519 header, ChaCha20-Poly1305 in 64 KiB chunks, write, fsync, rename,
remove the plaintext), related to what the logger writes (94 MB/h at full load, docs/logger.md).

The log's bytes are random: a zstd-compressed MCAP is as incompressible and the cipher's cost does
not depend on content. CPU is the process's (``time.process_time``: the encryption runs in the
calling thread), median of 5 runs; the peer is copying the same file with fsync (what any
at-rest step costs at least).
"""

from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from bench import result

LOGGER_MB_PER_HOUR = 94.0


def _cpu(action) -> float:
    start = time.process_time()
    action()
    return time.process_time() - start


def logger_encryption(quick: bool) -> list[dict]:
    import pyrage

    from haulprofile.logger.encryption import encrypt_log, parse_recipients
    size_mb = 8 if quick else 64
    recipients = parse_recipients([str(pyrage.x25519.Identity.generate().to_public())])
    payload = os.urandom(size_mb * 1024 * 1024)
    ours, peer = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(5):
            log = Path(tmp) / f"haulprofile_0badf00d_20240514T080000Z_{run:04d}.mcap"
            log.write_bytes(b"\x89MCAP0\r\n" + payload + b"\x89MCAP0\r\n")
            copy = log.with_name(log.name + ".copy")

            def plain_copy():
                shutil.copyfile(log, copy)
                with open(copy, "rb+") as stream:
                    os.fsync(stream.fileno())
            peer.append(_cpu(plain_copy) / size_mb)
            copy.unlink()
            ours.append(_cpu(lambda: encrypt_log(log, recipients)) / size_mb)
            log.with_name(log.name + ".age").unlink()
    per_mb = statistics.median(ours)
    cpu_s_per_hour = per_mb * LOGGER_MB_PER_HOUR
    return [result("logger_encryption_cpu_per_mb (ratio = plain copy / ours)", per_mb * 1e3, "ms/MB",
                   peer="copy + fsync", peer_value=statistics.median(peer) * 1e3,
                   cpu_s_per_hour_at_94_mb=round(cpu_s_per_hour, 3),
                   percent_of_one_core=round(100 * cpu_s_per_hour / 3600, 4), runs_ms_per_mb=[
                       round(v * 1e3, 2) for v in ours], size_mb=size_mb)]


BENCHMARKS = [logger_encryption]
