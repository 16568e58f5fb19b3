"""1000 random cuts and byte flips of MCAP logs: no crash, every intact chunk's messages recovered,
a warning whenever something was lost. Two logs: one the logger daemon wrote (emulated devices,
the real daemon and storage), one the foundation's LogWriter wrote with small chunks."""

import io
import struct

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import breakup_chunk
from mcap.data_stream import ReadDataStream

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.ingest import ingest_logs
from haulprofile.testing import logs as synthetic
from haulprofile.contract.reader import ReadReport, read_messages

ITERATIONS = 1000


def _daemon_log(tmp_path) -> bytes:
    from haulprofile.logger.config import Config
    from haulprofile.logger.emulators import record_drive

    t = np.arange(0, 8, 0.01)
    config = Config()
    config.storage.chunk_interval_s = 0.2
    path = record_drive({"time_s": t, "speed_mps": 10 + 3 * np.sin(t), "engine_speed_rpm": 1100 + 0 * t,
                         "actual_engine_torque_pct": 30 + 5 * np.cos(t), "pressure_pa": 98000 + 0 * t},
                        tmp_path, time_scale=4.0, config=config)
    return path.read_bytes()


def _writer_log() -> bytes:
    stream = io.BytesIO()
    synthetic.write_log(stream, 6.0, seed=11, filler_hz=200.0, chunk_size=4 * 1024)
    return stream.getvalue()


@pytest.fixture(scope="module", params=["logger-daemon", "log-writer"])
def original(request, tmp_path_factory):
    """A log and per chunk (byte range, message keys) from the mcap library."""
    if request.param == "logger-daemon":
        data = _daemon_log(tmp_path_factory.mktemp("daemon"))
    else:
        data = _writer_log()
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    topics = {cid: c.topic for cid, c in summary.channels.items()}
    messages = {}
    for _, channel, message in reader.iter_messages(log_time_order=False):
        messages[(channel.topic, message.sequence)] = message.data
    chunks = []
    for index in summary.chunk_indexes:
        record = ReadDataStream(io.BytesIO(data[index.chunk_start_offset + 9:
                                                index.chunk_start_offset + index.chunk_length]))
        keys = [(topics[r.channel_id], r.sequence) for r in breakup_chunk(Chunk.read(record))
                if hasattr(r, "sequence")]
        chunks.append((index.chunk_start_offset, index.chunk_start_offset + index.chunk_length, keys))
    assert len(chunks) > 25 and sum(len(k) for *_, k in chunks) == len(messages)
    return data, chunks, messages


def _damage(data: bytes, rng) -> tuple[bytes, int, list[int]]:
    mode = rng.integers(0, 3)
    cut = len(data) if mode == 1 else int(rng.integers(0, len(data)))
    flips = [] if mode == 0 else sorted(int(p) for p in rng.integers(0, len(data), rng.integers(1, 5)))
    damaged = bytearray(data[:cut])
    for position in flips:
        if position < cut:
            damaged[position] ^= int(rng.integers(1, 256))
    return bytes(damaged), cut, [p for p in flips if p < cut]


def test_random_cuts_and_flips(original):
    data, chunks, messages = original
    rng = np.random.default_rng(20261122)
    lost_runs = 0
    for iteration in range(ITERATIONS):
        damaged, cut, flips = _damage(data, rng)
        report = ReadReport(f"damaged-{iteration}")
        recovered = {}
        for message in read_messages(damaged, report):
            key = (message.channel.topic, message.sequence)
            assert messages.get(key) == message.data, "a recovered message must be byte-identical"
            recovered[key] = message.data
        intact = [key for start, end, keys in chunks
                  if end <= cut and not any(start <= p < end for p in flips) for key in keys]
        missing = [key for key in intact if key not in recovered]
        assert len(missing) <= report.unattributed_messages, (iteration, cut, flips, len(missing))
        if len(recovered) < len(messages):
            lost_runs += 1
            assert report.warning() is not None, (iteration, cut, flips)
    assert lost_runs > ITERATIONS // 2


def test_ingest_on_damaged_logs_never_tracebacks(original, tmp_path):
    data, _, _ = original
    rng = np.random.default_rng(5)
    path = tmp_path / "damaged.mcap"
    for _ in range(40):
        damaged, _, _ = _damage(data, rng)
        path.write_bytes(damaged)
        try:
            frame, summary = ingest_logs([path])
        except UserError:
            continue
        assert len(frame) > 0 and "files" in summary


@pytest.mark.parametrize("top_byte", [0x80, 0x01])
def test_a_chunk_whose_size_field_is_damaged_is_skipped(original, top_byte):
    """A flipped high bit of a chunk's uncompressed size (beyond what a C size can hold, or just
    absurd) loses that chunk, not the read: every other chunk's messages come back."""
    data, chunks, messages = original
    start, end, keys = chunks[len(chunks) // 2]
    size_msb = start + 9 + 16 + 7  # record head, message start/end times, last byte of uncompressed size
    damaged = bytearray(data)
    damaged[size_msb] ^= top_byte
    report = ReadReport("size-flip")
    recovered = {(m.channel.topic, m.sequence) for m in read_messages(bytes(damaged), report)}
    assert recovered == set(messages) - set(keys)
    assert report.warning() is not None


def test_a_damaged_summary_never_names_the_messages(original):
    """Records outside chunks have no CRC: when the chunk defining a channel is lost, the summary's
    copy may name its messages only if the footer's summary CRC holds, never a damaged copy."""
    data, chunks, messages = original
    footer = len(data) - 8 - 9 - 20
    (summary_start,) = struct.unpack_from("<Q", data, footer + 9)
    damaged = bytearray(data)
    pos = summary_start
    while pos < footer:
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x04:  # Channel: id u16, schema id u16, topic (u32 length, bytes)
            damaged[pos + 9 + 8] ^= 0x20
        pos += 9 + length
    start, end, first_keys = chunks[0]
    damaged[(start + end) // 2] ^= 0xFF
    report = ReadReport("summary-damaged")
    recovered = list(read_messages(bytes(damaged), report))
    topics = {topic for topic, _ in messages}
    assert {m.channel.topic for m in recovered} <= topics
    assert all(messages[(m.channel.topic, m.sequence)] == m.data for m in recovered)
    assert report.unattributed_messages > 0 and report.warning() is not None


@pytest.mark.parametrize("opcode", [0x05, 0x04, 0x02])
def test_a_chunk_whose_opcode_was_flipped_is_still_the_chunk(original, opcode):
    """Its CRC proves it a chunk: read as one, not as a message, a channel or the footer."""
    data, chunks, messages = original
    start, _, _ = chunks[len(chunks) // 2]
    damaged = bytearray(data)
    damaged[start] = opcode
    report = ReadReport("opcode-flip")
    recovered = {(m.channel.topic, m.sequence): m.data for m in read_messages(bytes(damaged), report)}
    assert recovered == messages


@pytest.mark.parametrize("opcode", [0x05, 0x02])
def test_a_message_index_flipped_into_a_message_or_footer_is_not_believed(original, opcode):
    """Message index records sit between chunks without a CRC: one whose opcode was flipped must
    neither add a message nor end the file."""
    data, chunks, messages = original
    index = make_reader(io.BytesIO(data)).get_summary().chunk_indexes[len(chunks) // 2]
    assert index.message_index_offsets
    damaged = bytearray(data)
    for offset in index.message_index_offsets.values():
        damaged[offset] = opcode
    report = ReadReport("index-flip")
    recovered = {(m.channel.topic, m.sequence): m.data for m in read_messages(bytes(damaged), report)}
    assert recovered == messages
