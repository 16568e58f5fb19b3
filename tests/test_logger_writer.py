"""The crash-safe writer and the log directory: chunks closed by time, fsync, files cut short,
summary on close, file names, rotation and the free-space watermark."""

from __future__ import annotations

import errno
import io
import struct

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader

from haulprofile import contract
from haulprofile.contract.naming import log_files
from haulprofile.logger.storage import LogDirectory, StorageOptions
from haulprofile.logger.writer import LogWriter

SECOND = 1_000_000_000


def _frames(t_ns: int, n: int = 50) -> bytes:
    records = np.zeros(n, contract.CAN_FRAME_DTYPE)
    records["t_mono_ns"] = t_ns
    records["arbitration_id"] = np.arange(n)
    return contract.pack(contract.CAN_FRAMES, records)


def _linear(data: bytes) -> int:
    """Messages a linear read recovers from ``data``."""
    messages = 0
    try:
        for record in StreamReader(io.BytesIO(data), skip_magic=False).records:
            messages += isinstance(record, Message)
    except (EndOfFile, struct.error):
        pass
    return messages


def test_chunks_close_by_data_age_not_only_by_size():
    stream = io.BytesIO()
    writer = LogWriter(stream, chunk_size=64 * 1024 * 1024, chunk_interval_s=1.0)
    for k in range(10):  # 0.0 .. 2.7 s, one message per 0.3 s
        writer.write(contract.CAN_FRAMES, _frames(k * 300_000_000), k * 300_000_000, 0)
    # chunks close at the messages of 1.2 s and 2.7 s (first message of the chunk >= 1 s old)
    assert writer.chunk_flushes == 2
    assert _linear(stream.getvalue()) == 10
    writer.write(contract.CAN_FRAMES, _frames(3 * SECOND), 3 * SECOND, 0)
    assert writer.chunk_flushes == 2 and _linear(stream.getvalue()) == 10


def test_fsync_callable_is_called_once_per_closed_chunk():
    synced = []
    stream = io.BytesIO()
    stream.fileno = lambda: 42
    writer = LogWriter(stream, chunk_interval_s=0.5, fsync=synced.append)
    for k in range(6):
        writer.write(contract.CAN_FRAMES, _frames(k * SECOND // 4), k * SECOND // 4, 0)
    assert synced == [42] * writer.chunk_flushes and writer.chunk_flushes == 2


def test_a_file_cut_anywhere_keeps_every_complete_chunk(tmp_path):
    path = tmp_path / "cut.mcap"
    flushes = [(0, 0)]  # (file offset after the flush, messages written by then)
    with open(path, "wb") as stream:
        writer = LogWriter(stream, chunk_interval_s=1.0, fsync=True)
        for k in range(40):
            before = writer.chunk_flushes
            writer.write(contract.CAN_FRAMES, _frames(k * SECOND // 4), k * SECOND // 4, 0)
            if writer.chunk_flushes > before:
                flushes.append((stream.tell(), k + 1))
        writer.close()
    data = path.read_bytes()
    assert len(flushes) == 9  # a chunk per 5 messages (0.0-1.0 s, 1.25-2.25 s, ...)
    rng = np.random.default_rng(3)
    for cut in rng.integers(8, flushes[-1][0], 40):
        messages = _linear(data[:cut])
        index = max(i for i, (offset, _) in enumerate(flushes) if offset <= cut)
        lower = flushes[index][1]
        upper = flushes[index + 1][1] if index + 1 < len(flushes) else 40
        assert messages in (lower, upper), (cut, messages, lower, upper)
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary.statistics.message_count == 40
    assert _linear(data) == 40 and summary.statistics.chunk_count == 8


def _options(tmp_path, **kwargs) -> StorageOptions:
    return StorageOptions(**{"directory": tmp_path, "fsync": False, "min_free_bytes": 0, **kwargs})


def test_file_names_and_a_new_file_per_start(tmp_path):
    first = LogDirectory(_options(tmp_path))
    a = first.open()
    first.writer.write(contract.CAN_FRAMES, _frames(1), 1, 1)
    first.close()
    second = LogDirectory(_options(tmp_path))
    b = second.open()
    second.close()
    assert a != b and a.exists() and b.exists()
    assert a.name.startswith(f"haulprofile_{first.boot_id}_") and a.name.endswith("_0000.mcap")
    assert b.name.endswith("_0001.mcap")
    assert log_files(tmp_path) == [a, b]


def test_file_order_is_the_sequence_not_a_clock_running_behind(tmp_path, monkeypatch):
    """A Pi without RTC may boot with a clock days behind: its new file must still count as newest."""
    earlier_boot = tmp_path / "haulprofile_0badf00d_20300101T000000Z_0007.mcap"  # clock was right then
    earlier_boot.write_bytes(b"x" * 1000)
    directory = LogDirectory(_options(tmp_path, min_free_bytes=10_000))
    new = directory.open()  # named with this machine's clock, years before 2030
    assert new.name.endswith("_0008.mcap")
    assert log_files(tmp_path) == [earlier_boot, new]
    monkeypatch.setattr(directory, "free_bytes", lambda: 9_500)
    assert directory.enforce_free_space()
    assert directory.deleted == [earlier_boot] and new.exists()
    directory.close()
    new.unlink()  # every file copied off and removed: the numbers still do not go back
    again = LogDirectory(_options(tmp_path))
    assert again.open().name.endswith("_0009.mcap")
    again.close()


def test_rotation_by_size_closes_the_old_file_with_its_summary(tmp_path):
    directory = LogDirectory(_options(tmp_path, rotate_size_bytes=3_000))
    directory.open()
    for k in range(60):
        directory.writer.write(contract.CAN_FRAMES, _frames(k * SECOND // 10, 200), k * SECOND // 10, 0)
        directory.writer.flush()
        directory.rotate_if_due()
    directory.close()
    assert len(directory.files_written) >= 3
    total = 0
    for path in directory.files_written:
        with open(path, "rb") as stream:
            total += make_reader(stream).get_summary().statistics.message_count
    assert total == 60


def test_watermark_deletes_the_oldest_files_first(tmp_path, monkeypatch):
    old = []
    for seq in range(3):
        path = tmp_path / f"haulprofile_0badf00d_2024010{seq + 1}T000000Z_{seq:04d}.mcap"
        path.write_bytes(b"x" * 1000)
        old.append(path)
    directory = LogDirectory(_options(tmp_path, min_free_bytes=10_000))
    directory.open()
    free = {"bytes": 8_500}
    monkeypatch.setattr(directory, "free_bytes", lambda: free["bytes"])
    assert directory.enforce_free_space()
    assert directory.deleted == old[:2] and old[2].exists() and directory.path.exists()
    assert any("deleted" in m for m in directory.messages)


def test_watermark_pause_stops_and_resumes_writing(tmp_path, monkeypatch):
    directory = LogDirectory(_options(tmp_path, min_free_bytes=10_000, on_low_space="pause"))
    first = directory.open()
    free = {"bytes": 5_000}
    monkeypatch.setattr(directory, "free_bytes", lambda: free["bytes"])
    assert not directory.enforce_free_space()
    assert directory.paused and directory.writer is None and first.exists()
    free["bytes"] = 50_000
    assert directory.enforce_free_space()
    assert not directory.paused and directory.writer is not None and directory.path != first
    assert [m.split(":")[-1].strip() for m in directory.messages] == ["writing paused", "writing resumed"]


class _FillingDisk(io.FileIO):
    """A real file whose writes fail with ENOSPC once ``budget`` bytes are written, partly
    written first, as a full disk does."""

    budget = 0

    def write(self, data) -> int:
        room = _FillingDisk.budget - self.tell()
        if room <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        if len(data) > room:
            return super().write(bytes(data)[:room])
        return super().write(data)


def _open_on_filling_disk(path, exclusive=True):
    return io.BufferedWriter(_FillingDisk(path, "xb"))


def _cut_on_a_full_disk(tmp_path, monkeypatch, budget: int) -> tuple[list, list]:
    """Write flushed chunks until the disk fills at ``budget`` bytes; the daemon's reaction
    (`write_failed`). Returns the files and the messages flushed before the failure."""
    monkeypatch.setattr("haulprofile.logger.storage.open_new", _open_on_filling_disk)
    _FillingDisk.budget = budget
    directory = LogDirectory(_options(tmp_path, on_low_space="pause"))
    directory.open()
    flushed = []
    try:
        for k in range(1000):
            directory.writer.write(contract.CAN_FRAMES, _frames(k * SECOND), k * SECOND, 0)
            directory.writer.flush()
            flushed.append(k)
    except OSError as exc:
        directory.write_failed(exc)
    return sorted(tmp_path.glob("*.mcap")), flushed


def test_a_full_disk_leaves_the_file_cut_at_its_last_complete_chunk(tmp_path, monkeypatch):
    """ENOSPC anywhere in a chunk (its opcode, its length, its header fields, its data): the partly
    written chunk (and the summary the close tried to write) is cut off, so a linear read ends
    cleanly at a record boundary with every message that was flushed before the failure."""
    for budget in range(1_000, 6_000, 29):
        folder = tmp_path / str(budget)
        folder.mkdir()
        files, flushed = _cut_on_a_full_disk(folder, monkeypatch, budget)
        assert len(files) == 1 and 0 < len(flushed) < 1000
        data = files[0].read_bytes()
        messages = 0
        try:
            for record in StreamReader(io.BytesIO(data), skip_magic=False).records:
                messages += isinstance(record, Message)
        except EndOfFile:
            pass
        assert messages == len(flushed), budget


def test_a_disk_full_before_any_complete_chunk_leaves_no_file(tmp_path, monkeypatch):
    """A file that holds not even its header when the disk fills is removed, not left as a log."""
    files, flushed = _cut_on_a_full_disk(tmp_path, monkeypatch, budget=5)
    assert files == [] and flushed == []
