"""The contract's reader against the mcap library's decoding (the old path, kept here as the
reference), its numba walk against the plain-Python one, threads against none, the summary's
chunk index against a scan, and the damaged-file corpus."""

import io
import struct

import numpy as np
import pytest
from mcap.reader import make_reader

from haulprofile import contract
from haulprofile.testing import logs as synthetic
from haulprofile.contract import chunk_walk, reader


def _log(seconds: float = 8.0, chunk_size: int = 16 * 1024) -> bytes:
    stream = io.BytesIO()
    synthetic.write_log(stream, seconds, seed=4, filler_hz=300.0, chunk_size=chunk_size)
    return stream.getvalue()


@pytest.fixture(scope="module")
def log() -> bytes:
    return _log()


def _reference(data: bytes, shift_ns: int = 0) -> dict:
    """The old decoding: mcap's reader, one ``np.frombuffer`` per packed message (whole records),
    the time shift on a copy, JSON payloads as they are."""
    out: dict = {}
    for _, channel, message in make_reader(io.BytesIO(data)).iter_messages(log_time_order=False):
        topic = contract.TOPICS.get(channel.topic)
        if topic is not None and topic.encoding == contract.PACKED_ENCODING and (
                topic.name not in contract.SENSOR_TOPICS or channel.message_encoding == contract.PACKED_ENCODING):
            size = topic.dtype.itemsize
            records = np.frombuffer(message.data, topic.dtype, count=len(message.data) // size)
            if shift_ns:
                records = records.copy()
                records["t_mono_ns"] += np.uint64(shift_ns)
            out.setdefault(channel.topic, []).append(records)
        else:
            out.setdefault(channel.topic, []).append(message.data)
    return {topic: np.concatenate(parts) if isinstance(parts[0], np.ndarray) else parts
            for topic, parts in out.items()}


def _ours(source, shift_ns: int = 0, report=None, **options) -> dict:
    out: dict = {}
    for window in reader.read_windows(source, report, **options):
        for name in reader.PACKED_TOPICS:
            records = window.topic_records(name)
            if len(records):
                out.setdefault(name, []).append(contract.shift_times(records, shift_ns))
        for cid, payload in zip(window.channel_ids.tolist(), window.payloads(np.arange(len(window)))):
            topic = window.channels[cid].topic
            if cid not in window.packed_channels(topic):
                out.setdefault(topic, []).append(payload)
    return {topic: np.concatenate(parts) if isinstance(parts[0], np.ndarray) else parts
            for topic, parts in out.items()}


def _same(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    for topic in a:
        if isinstance(a[topic], np.ndarray):
            if a[topic].dtype != b[topic].dtype or a[topic].tobytes() != b[topic].tobytes():
                return False
        elif a[topic] != b[topic]:
            return False
    return True


@pytest.mark.parametrize("threads,use_numba,ahead", [(2, True, 0), (0, True, 0), (0, False, 0), (1, True, 1), (0, True, 3)])
def test_arrays_are_bit_identical_to_the_mcap_library_decoding(log, threads, use_numba, ahead):
    shift = 3_600_000_000_123
    ours = _ours(log, shift, threads=threads, use_numba=use_numba, window_bytes=64 * 1024, ahead=ahead)
    theirs = _reference(log, shift)
    assert _same(ours, theirs)
    assert len(ours[contract.CAN_FRAMES.name]) > 3_000 and len(ours[contract.IMU.name]) > 5_000


def test_the_demo_log_reads_as_the_mcap_library_reads_it(tmp_path):
    """The log `analyze demo --direct` ingests (regional-tunnel, seed 0)."""
    from haulprofile.analysis.virtual_truck import drive, load_scenario, write_mcap

    virtual = drive(load_scenario("regional-tunnel"), seed=0)
    path = write_mcap(virtual, tmp_path / "virtual.mcap")
    report = reader.ReadReport(str(path))
    assert _same(_ours(path, report=report), _reference(path.read_bytes()))
    assert report.warning() is None


@pytest.mark.parametrize("version", [1, 2])
def test_the_demo_log_of_either_contract_reads_as_the_mcap_library_reads_it(tmp_path, version):
    """A shorter demo drive with JSON (contract 1) or packed (contract 2) sensor topics."""
    from haulprofile.analysis.virtual_truck import drive, load_scenario, write_mcap

    virtual = drive(load_scenario("urban-delivery"), seed=1)
    path = write_mcap(virtual, tmp_path / "virtual.mcap", contract_version=version)
    ours = _ours(path)
    assert _same(ours, _reference(path.read_bytes()))
    assert isinstance(ours[contract.BAROMETER.name], np.ndarray) == (version == 2)


def test_the_old_loggers_log_reads_as_the_mcap_library_reads_it(data_dir):
    path = data_dir / "logger-v1" / "haulprofile-contract-1-30s.mcap"
    ours = _ours(path)
    assert _same(ours, _reference(path.read_bytes()))
    assert isinstance(ours[contract.HUMIDITY.name], list)


def test_without_summary_the_scan_finds_the_same(log):
    """A file cut just before its summary (no footer, no chunk index) gives the same messages."""
    footer = len(log) - 8 - 9 - 20
    (summary_start,) = struct.unpack_from("<Q", log, footer + 9)
    cut = log[:summary_start]
    report = reader.ReadReport("cut")
    assert _same(_ours(cut, report=report), _reference(log))
    assert not report.complete and report.warning() is not None
    assert len(reader._expected_chunks(cut)) == len(reader._expected_chunks(log)) > 10


def test_numba_walk_equals_the_python_walk(log):
    """Every chunk of a log, and chunks of random and truncated bytes (the error codes)."""
    walk = chunk_walk.kernels()["walk_records"]
    rng = np.random.default_rng(8)
    chunks = [reader._decompress(memoryview(log)[at + 9:at + 9 + struct.unpack_from("<Q", log, at + 1)[0]])
              for at in reader._expected_chunks(log).tolist()]
    samples = chunks + [c[:len(c) - int(rng.integers(1, 40))] for c in chunks[:10]] + \
        [rng.integers(0, 256, int(n), dtype=np.uint8).tobytes() for n in rng.integers(0, 200, 30)] + \
        [bytes([5]) + struct.pack("<Q", 3) + b"abc", b""]
    statuses = set()
    for data in samples:
        (status, table), (status_py, table_py) = walk(np.frombuffer(data, np.uint8)), \
            chunk_walk.walk_records_python(data)
        assert status == status_py and table.dtype == table_py.dtype and np.array_equal(table, table_py)
        assert table.shape == (len(chunk_walk.COLUMNS), max(status, 0))
        statuses.add(int(np.sign(status)) if status >= 0 else status)
    assert statuses >= {1, chunk_walk.NOT_TILED, chunk_walk.MESSAGE_CUT}


def test_scatter_equals_the_python_scatter():
    rng = np.random.default_rng(2)
    source = rng.integers(0, 256, 5000, dtype=np.uint8)
    starts = np.sort(rng.choice(4000, 50, replace=False)).astype(np.int64)
    lengths = rng.integers(0, 60, 50).astype(np.int64)
    offsets = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    ours, reference = np.zeros(int(lengths.sum()), np.uint8), np.zeros(int(lengths.sum()), np.uint8)
    chunk_walk.kernels()["scatter"](source, starts, lengths, ours, offsets)
    chunk_walk.scatter_python(source, starts, lengths, reference, offsets)
    assert np.array_equal(ours, reference)
    assert np.array_equal(ours[:lengths[0]], source[starts[0]:starts[0] + lengths[0]])


def test_damaged_files_read_the_same_every_way(log):
    """Threads or not, numba or not, every damaged file gives the same messages and report."""
    from test_ingest_robustness import _damage

    rng = np.random.default_rng(44)
    for _ in range(60):
        damaged, _, _ = _damage(log, rng)
        results = []
        for threads, use_numba in ((2, True), (0, False)):
            report = reader.ReadReport("damaged")
            messages = [(m.channel.topic, m.sequence, m.log_time_ns, m.publish_time_ns, m.data)
                        for m in reader.read_messages(damaged, report, threads=threads, use_numba=use_numba)]
            results.append((messages, vars(report)))
        assert results[0] == results[1]


def test_record_struct_is_the_dtype():
    frames = np.zeros(3, contract.CAN_FRAME_DTYPE)
    frames["t_mono_ns"] = [1, 2**63, 5]
    frames["arbitration_id"] = [0x18FEF100, 0x7DF, 0]
    frames["flags"], frames["dlc"] = [1, 0, 8], [8, 3, 0]
    frames["data"][0] = np.arange(8)
    pack = contract.record_struct(contract.CAN_FRAMES).pack
    packed = b"".join(pack(int(f["t_mono_ns"]), int(f["arbitration_id"]), int(f["flags"]), int(f["dlc"]), 0, 0,
                           f["data"].tobytes()) for f in frames)
    assert packed == contract.pack(contract.CAN_FRAMES, frames)
    assert contract.first_time_ns(packed) == 1
    shifted = contract.unpack(contract.CAN_FRAMES, packed, shift_ns=10)
    assert shifted["t_mono_ns"].tolist() == [11, 2**63 + 10, 15] and shifted["data"].tobytes() == frames["data"].tobytes()
    with pytest.raises(ValueError):
        contract.unpack(contract.CAN_FRAMES, packed[:-1])
    assert len(contract.unpack(contract.CAN_FRAMES, packed[:-1], whole_only=True)) == 2
    imu = contract.record_struct(contract.IMU)
    assert imu.size == contract.IMU_SAMPLE_DTYPE.itemsize and imu.format == "<Q3h3h"


def test_metadata_and_attachments_are_read_and_a_damaged_attachment_is_not_believed():
    from mcap.writer import CompressionType, Writer

    from haulprofile.contract.reader import ReadReport, read_messages

    stream = io.BytesIO()
    writer = Writer(stream, chunk_size=1024, compression=CompressionType.ZSTD)
    writer.start(profile="haulprofile", library="test-writer")
    channel = writer.register_channel("/diagnostics", "json", 0)
    writer.add_message(channel, log_time=1, data=b"{}", publish_time=1)
    writer.add_metadata("haulprofile.logger", {"boot_id": "b1"})
    writer.add_attachment(create_time=5, log_time=6, name="note.txt", media_type="text/plain", data=b"payload")
    writer.finish()
    data = stream.getvalue()
    report = ReadReport("<buffer>")
    assert len(list(read_messages(data, report))) == 1
    assert (report.profile, report.library) == ("haulprofile", "test-writer")
    assert report.metadata == [("haulprofile.logger", {"boot_id": "b1"})]
    assert [(a.name, a.media_type, a.create_time_ns, a.log_time_ns, a.data) for a in report.attachments] == [
        ("note.txt", "text/plain", 5, 6, b"payload")]
    flipped = bytearray(data)
    at = data.index(b"payload")
    flipped[at] ^= 0xFF
    damaged = ReadReport("<buffer>")
    assert len(list(read_messages(bytes(flipped), damaged))) == 1
    assert damaged.attachments == [] and damaged.skipped_bytes > 0 and damaged.warning()


def test_repair_of_a_cut_log_runs_without_numba_or_pandas(tmp_path):
    """The logger repairs a power cut's file on the Pi, whose extra has neither numba nor pandas."""
    import subprocess
    import sys

    whole = tmp_path / "whole.mcap"
    with open(whole, "wb") as stream:
        synthetic.write_log(stream, 20, seed=2, chunk_size=16 * 1024)
    data = whole.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    script = ("import sys; sys.modules['numba'] = None; sys.modules['pandas'] = None\n"
              "from haulprofile.contract.repair import is_complete, repair\n"
              f"kept = repair({str(cut)!r}); assert is_complete({str(cut)!r})\n"
              "assert 'numba' not in [m for m, v in sys.modules.items() if v is not None]\n"
              "print(kept)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    kept = int(done.stdout)
    assert 0 < kept == sum(1 for _ in reader.read_messages(cut)) < sum(1 for _ in reader.read_messages(whole))
    with open(cut, "rb") as stream:
        assert make_reader(stream).get_summary() is not None


def test_windows_built_ahead_give_the_same_report_and_stop_with_the_caller(log, monkeypatch):
    """On a thread of their own, windows come in the same order with the same read report; a
    caller that stops early stops the thread, and an error there is raised in the caller."""
    import threading

    cut = log[: len(log) * 3 // 4]
    reports = [reader.ReadReport("cut"), reader.ReadReport("cut")]
    plain = [len(w) for w in reader.read_windows(cut, reports[0], window_bytes=32 * 1024)]
    ahead = [len(w) for w in reader.read_windows(cut, reports[1], window_bytes=32 * 1024, ahead=2)]
    assert plain == ahead and len(plain) > 3
    assert vars(reports[0]) == vars(reports[1])

    windows = reader.read_windows(log, window_bytes=32 * 1024, ahead=1)
    next(windows)
    windows.close()
    assert not any(t.name == "mcap-windows" for t in threading.enumerate())

    def broken(*_args, **_kwargs):
        raise MemoryError("no memory for the window")

    monkeypatch.setattr(reader, "Window", broken)
    with pytest.raises(MemoryError, match="no memory"):
        list(reader.read_windows(log, window_bytes=32 * 1024, ahead=1))
    assert not any(t.name == "mcap-windows" for t in threading.enumerate())


def test_chunks_load_ahead_in_runs_each_once_and_an_error_waits_for_its_chunk(log, monkeypatch):
    """Whatever the run of chunks one pool task loads, the messages and the report are those of a
    sequential read and every chunk is loaded once; an error while loading one chunk of a run is
    raised where the walk reaches that chunk, after the windows before it, as a sequential read
    raises it."""
    import collections

    expected = reader._expected_chunks(log).tolist()
    sequential_report = reader.ReadReport("log")
    sequential = _ours(log, report=sequential_report, threads=0)
    loads: collections.Counter = collections.Counter()
    load_chunk = reader._load_chunk

    def counted(view, pos, use_numba):
        loads[pos] += 1
        return load_chunk(view, pos, use_numba)

    monkeypatch.setattr(reader, "_load_chunk", counted)
    for task_bytes in (1, 40_000, 1 << 20):
        monkeypatch.setattr(reader, "TASK_BYTES", task_bytes)
        loads.clear()
        report = reader.ReadReport("log")
        assert _same(_ours(log, report=report, threads=2, window_bytes=64 * 1024), sequential)
        assert vars(report) == vars(sequential_report)
        assert [loads[pos] for pos in expected] == [1] * len(expected)

    bad = expected[len(expected) // 2]

    def failing(view, pos, use_numba):
        if pos == bad:
            raise RuntimeError("chunk loader failed")
        return load_chunk(view, pos, use_numba)

    monkeypatch.setattr(reader, "_load_chunk", failing)
    before = []
    for threads in (0, 2):
        windows = 0
        with pytest.raises(RuntimeError, match="chunk loader failed"):
            for _ in reader.read_windows(log, threads=threads, window_bytes=1):
                windows += 1
        before.append(windows)
    assert before[0] == before[1] > 0


def test_a_walk_waiting_for_a_busy_pool_loads_the_unstarted_runs_itself(log):
    """While the pool's only thread is busy, the walk loads the runs no pool thread has started
    instead of waiting: the chunks come before the pool is free, equal to chunks loaded one by one."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    free = threading.Event()
    unblock = threading.Timer(30.0, free.set)  # a walk that only waited would hang the test, not CI
    unblock.start()
    positions = reader._expected_chunks(log).tolist()[:6]
    view = memoryview(log)
    with ThreadPoolExecutor(1) as executor:
        busy = executor.submit(free.wait)
        scanner = reader._Scanner(log, view, executor, True, ahead_bytes=64 * 1024)
        scanner.release(0)
        chunks = [scanner.chunk(pos) for pos in positions]
        assert not busy.done()
        free.set()
        scanner.close()
    unblock.cancel()
    for pos, chunk in zip(positions, chunks):
        alone = reader._load_chunk(view, pos, True)
        assert chunk.valid and alone.valid
        assert chunk.records.data == alone.records.data
        assert np.array_equal(chunk.records.table, alone.records.table)


def test_the_scanner_forgets_finished_runs(monkeypatch):
    """Runs the walk has passed are not kept (their futures hold their chunks): the runs the
    scanner holds never add up to more than its bytes ahead and a chunk or two, however long the file."""
    log = _log(30.0)
    monkeypatch.setattr(reader, "TASK_BYTES", 1)  # a run per chunk
    ahead = 8 * 1024
    length = {at: struct.unpack_from("<Q", log, at + 1)[0] for at in reader._expected_chunks(log).tolist()}
    held_bytes = []
    release = reader._Scanner.release

    def noting_release(self, below):
        release(self, below)
        held_bytes.append(sum(length[at] for _, run in self._tasks for at in run))

    monkeypatch.setattr(reader._Scanner, "release", noting_release)
    for _ in reader.read_windows(log, threads=1, window_bytes=ahead):
        pass
    assert sum(length.values()) > 10 * ahead
    assert max(held_bytes) <= ahead + 2 * max(length.values())


def test_a_window_keeps_the_channels_of_its_own_time_while_later_ones_are_defined():
    """A channel first defined late in a file does not appear in the windows before it: the
    ingest's decoding thread walks a window's channels while the reader, on its own thread,
    builds the next windows (a dict that grew under it raised "changed size during iteration")."""
    from mcap.writer import Writer

    stream = io.BytesIO()
    writer = Writer(stream, chunk_size=4 * 1024)
    writer.start()
    schema = writer.register_schema("t", "jsonschema", b"{}")
    early = writer.register_channel("/early", "json", schema)
    for k in range(400):
        writer.add_message(early, log_time=k, publish_time=k, data=b'{"v": %d}' % k, sequence=k)
    late = writer.register_channel("/late", "json", schema)
    for k in range(400, 800):
        writer.add_message(late, log_time=k, publish_time=k, data=b'{"v": %d}' % k, sequence=k)
    writer.finish()
    windows = list(reader.read_windows(stream.getvalue(), window_bytes=8 * 1024))
    topics = [{channel.topic for channel in window.channels.values()} for window in windows]
    assert len(windows) > 2
    assert topics[0] == {"/early"} and topics[-1] == {"/early", "/late"}
