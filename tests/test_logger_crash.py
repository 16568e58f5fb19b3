"""Done-when crash test: ``kill -9`` the daemon (the console entry point ``logger.cli.main`` in a
forked process, emulators inside) at random moments, 20 times. Every file must be readable with a
linear read, at most 2 s of data may be lost per kill, and each restart must start a new file and
leave the old ones untouched. Forking from a process that has already imported everything keeps
the 20 restarts quick; the SIGTERM and bad-config tests start the real console script.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

import haulprofile.logger.daemon  # noqa: F401  (imported before forking: restarts then cost no imports)
import haulprofile.logger.emulators.rig  # noqa: F401
import haulprofile.logger.sources.can  # noqa: F401
import haulprofile.logger.sources.gps  # noqa: F401
import haulprofile.logger.sources.i2c.lsm9ds1  # noqa: F401  (imported for the forked children)
from haulprofile import contract
from haulprofile.logger import cli

KILLS = 20
MAX_LOSS_S = 2.0

CONFIG = """
[logger]
directory = "{directory}"
[storage]
chunk_interval_s = 1.0
min_free_mb = 1
[can]
interface = "virtual"
channel = "haulprofile-emulated"
[i2c.lsm9ds1]
odr_hz = 952
[emulation]
enabled = true
signals = "synthetic"
"""


def read_linear(path: Path) -> tuple[dict[str, int], int | None, bool]:
    """Messages per topic, the newest monotonic time [ns] of any CAN frame, and whether the file
    ended with its footer (clean close) — by a linear read that stops at a cut."""
    topics, counts, newest, complete = {}, {}, None, False
    with open(path, "rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message):
                    topic = topics[record.channel_id]
                    counts[topic] = counts.get(topic, 0) + 1
                    if topic == contract.CAN_FRAMES.name:
                        newest = max(newest or 0, int(contract.unpack(contract.CAN_FRAMES, record.data)["t_mono_ns"].max()))
            complete = True
        except (EndOfFile, struct.error):
            pass
    return counts, newest, complete


def _run_cli(config: str) -> None:
    os._exit(cli.main(["--config", config]))


def _wait_for_file(directory: Path, known: set, timeout_s: float = 20.0) -> Path:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        new = [p for p in directory.glob("*.mcap") if p not in known]
        if new and new[0].stat().st_size > 0:
            return new[0]
        time.sleep(0.02)
    raise AssertionError("the daemon wrote no file")


def test_kill_9_twenty_times(tmp_path):
    directory = tmp_path / "logs"
    config = tmp_path / "logger.toml"
    config.write_text(CONFIG.format(directory=directory.as_posix()))
    rng = np.random.default_rng(20240514)
    known: dict[Path, tuple[int, int]] = {}
    losses = []
    fork = multiprocessing.get_context("fork")
    for kill in range(KILLS):
        process = fork.Process(target=_run_cli, args=(str(config),), daemon=True)
        process.start()
        try:
            path = _wait_for_file(directory, set(known))
            file_seen_ns = time.monotonic_ns()
            time.sleep(rng.uniform(0.2, 1.4))
            killed_at_ns = time.monotonic_ns()
            os.kill(process.pid, signal.SIGKILL)
            process.join(10)
        finally:
            if process.is_alive():
                process.kill()
        assert process.exitcode == -signal.SIGKILL
        for old, stat in known.items():
            assert (old.stat().st_size, old.stat().st_mtime_ns) == stat, f"{old.name} changed after kill {kill}"
        files = sorted(directory.glob("*.mcap"))
        assert len(files) == kill + 1, "a restart must start a new file"
        counts, newest_ns, _ = read_linear(path)
        losses.append((killed_at_ns - (newest_ns or file_seen_ns)) * 1e-9)
        known[path] = (path.stat().st_size, path.stat().st_mtime_ns)
    assert max(losses) <= MAX_LOSS_S, losses
    assert sum(1 for loss in losses if loss < 1.5) >= KILLS // 2, losses


def test_sigterm_closes_the_file_with_its_summary(tmp_path):
    from mcap.reader import make_reader
    directory = tmp_path / "logs"
    config = tmp_path / "logger.toml"
    config.write_text(CONFIG.format(directory=directory.as_posix()))
    process = subprocess.Popen([sys.executable, "-m", "haulprofile.logger.cli", "--config", str(config)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _wait_for_file(directory, set())
    time.sleep(1.2)
    process.send_signal(signal.SIGHUP)
    time.sleep(0.8)
    process.send_signal(signal.SIGTERM)
    assert process.wait(20) == 0, process.stderr.read().decode()
    files = sorted(directory.glob("*.mcap"))
    assert len(files) == 2, "SIGHUP rotates to a new file"
    for file in files:
        with open(file, "rb") as stream:
            summary = make_reader(stream).get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        assert read_linear(file)[2]


@pytest.mark.parametrize("text, key", [
    ("[can]\nbitrate = 'fast'\n", "can.bitrate"),
    ("[can.obd]\nrate = 30\n", "can.obd.rate"),
    ("[storage]\non_low_space = 'panic'\n", "storage.on_low_space"),
])
def test_bad_config_is_one_line_naming_the_key(tmp_path, text, key):
    config = tmp_path / "bad.toml"
    config.write_text(text)
    result = subprocess.run([sys.executable, "-m", "haulprofile.logger.cli", "--config", str(config)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in result.stderr
