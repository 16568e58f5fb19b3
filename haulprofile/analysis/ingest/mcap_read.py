"""A linear, damage-tolerant MCAP reader: whole files, files cut by power loss, flipped bytes.

The mcap library's seeking reader needs the footer and summary, which a file cut by power loss
does not have; its stream reader stops at the first damaged record. This reader walks the records
itself: every chunk whose CRC (and decompression) checks out yields its messages, a damaged chunk
is counted and skipped, and after damage it resynchronises on the next chunk record that
validates. Messages whose channel record was lost stay unattributed and are counted. Records
outside chunks have no CRC of their own, so: in a chunked file a message record outside a chunk is
damage (a flipped opcode of a message index, say), not data; the summary's copies of schema and
channel records stand in only if the footer's summary CRC holds; a footer is only the footer
with its 20 bytes and the closing magic.
"""

from __future__ import annotations

import mmap
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, NamedTuple

import zstandard

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_DATA_END = 0x0F
_VALID_OPS = set(range(0x01, 0x10))
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
_CHUNK_HEAD = struct.Struct("<QQQII")
_ZSTD_MARK = b"\x04\x00\x00\x00zstd"
_LZ4_MARK = b"\x03\x00\x00\x00lz4"
MAX_CHUNK_BYTES = 1 << 32
"""Largest uncompressed chunk believed (writers use 1 MiB by default, the logger 256 KiB); a
larger size field is a damaged one, not a reason to allocate that much."""


class DamagedRecord(Exception):
    """A record that does not parse or whose CRC does not match."""


@dataclass(frozen=True)
class Channel:
    id: int
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    metadata: dict


@dataclass
class ReadReport:
    """What a linear read found in one file [bytes, counts]."""

    path: str
    file_bytes: int = 0
    read_bytes: int = 0
    """Bytes up to the end of the last record that parsed (the recovered part of the file)."""
    chunks: int = 0
    bad_chunks: int = 0
    skipped_bytes: int = 0
    messages: int = 0
    unattributed_messages: int = 0
    complete: bool = False
    """True when the footer and closing magic were read."""
    header_ok: bool = True
    profile: str = ""
    problems: list[str] = field(default_factory=list)

    def warning(self) -> str | None:
        """One line for the user when anything was lost; None for an intact file."""
        if (self.complete and not self.bad_chunks and not self.skipped_bytes and not self.unattributed_messages
                and not self.problems):
            return None
        parts = list(self.problems)
        if not self.complete:
            parts.append(f"cut short (no footer): recovered {self.read_bytes} of {self.file_bytes} bytes")
        if self.bad_chunks:
            parts.append(f"{self.bad_chunks} of {self.chunks} chunks damaged (bad CRC or data) and skipped")
        if self.skipped_bytes:
            parts.append(f"{self.skipped_bytes} damaged bytes skipped")
        if self.unattributed_messages:
            parts.append(f"{self.unattributed_messages} messages of channels whose definition was lost")
        return f"{self.path}: " + "; ".join(parts) + f"; {self.messages} messages read"


class RawMessage(NamedTuple):
    channel: Channel
    sequence: int
    log_time_ns: int
    publish_time_ns: int
    data: bytes


def _string(buf, pos: int) -> tuple[str, int]:
    (n,) = _U32.unpack_from(buf, pos)
    end = pos + 4 + n
    if end > len(buf):
        raise DamagedRecord("string beyond record")
    return bytes(buf[pos + 4:end]).decode("utf-8"), end


def _parse_schema(body) -> tuple[int, str, str, bytes]:
    (schema_id,) = _U16.unpack_from(body, 0)
    name, pos = _string(body, 2)
    encoding, pos = _string(body, pos)
    (n,) = _U32.unpack_from(body, pos)
    if pos + 4 + n > len(body):
        raise DamagedRecord("schema data beyond record")
    return schema_id, name, encoding, bytes(body[pos + 4:pos + 4 + n])


def _parse_channel(body) -> tuple[int, int, str, str, dict]:
    channel_id, schema_id = struct.unpack_from("<HH", body, 0)
    topic, pos = _string(body, 4)
    encoding, pos = _string(body, pos)
    (map_len,) = _U32.unpack_from(body, pos)
    pos += 4
    end = pos + map_len
    if end > len(body):
        raise DamagedRecord("channel metadata beyond record")
    metadata = {}
    while pos < end:
        key, pos = _string(body, pos)
        value, pos = _string(body, pos)
        metadata[key] = value
    return channel_id, schema_id, topic, encoding, metadata


class _Channels:
    """Schema and channel records seen so far, and messages waiting for their channel."""

    def __init__(self):
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, Channel] = {}
        self.pending: dict[int, tuple[int, int, int, bytes]] = {}

    def add_schema(self, body) -> None:
        schema_id, name, encoding, data = _parse_schema(body)
        self.schemas.setdefault(schema_id, (name, encoding, data))

    def add_channel(self, body) -> None:
        """Register a channel; the first definition wins (chunked ones are CRC-checked, the
        summary's copies are not)."""
        channel_id, schema_id, topic, encoding, metadata = _parse_channel(body)
        if channel_id in self.channels:
            return
        name, schema_encoding, data = self.schemas.get(schema_id, ("", "", b""))
        self.channels[channel_id] = Channel(channel_id, topic, encoding, name, schema_encoding, data, metadata)


def _check_tiling(data: bytes) -> bytes:
    """``data`` if its records tile it exactly (opcodes known, lengths in range), else DamagedRecord."""
    pos, size, head, valid = 0, len(data), _RECORD_HEAD.unpack_from, _VALID_OPS
    while pos < size:
        if pos + 9 > size:
            raise DamagedRecord("record header beyond chunk")
        opcode, length = head(data, pos)
        pos += 9 + length
        if opcode not in valid or pos > size:
            raise DamagedRecord("record beyond chunk")
    return data


def _chunk_payload(body) -> bytes:
    """Decompressed, CRC-checked records of a chunk body."""
    if len(body) < _CHUNK_HEAD.size:
        raise DamagedRecord("chunk header short")
    _start, _end, size, crc, comp_len = _CHUNK_HEAD.unpack_from(body, 0)
    pos = _CHUNK_HEAD.size
    if comp_len > 8 or pos + comp_len + 8 > len(body):
        raise DamagedRecord("chunk compression field damaged")
    compression = bytes(body[pos:pos + comp_len])
    pos += comp_len
    (data_len,) = _U64.unpack_from(body, pos)
    pos += 8
    if pos + data_len != len(body):
        raise DamagedRecord("chunk data length does not match record")
    raw = body[pos:]
    if size > MAX_CHUNK_BYTES:
        raise DamagedRecord(f"chunk size field damaged ({size} bytes)")
    try:
        if compression == b"zstd":
            data = zstandard.ZstdDecompressor().decompress(raw, max_output_size=size)
        elif compression == b"lz4":
            import lz4.frame
            data = lz4.frame.decompress(bytes(raw))
        elif compression == b"":
            data = bytes(raw)
        else:
            raise DamagedRecord(f"unknown chunk compression {compression!r}")
    except (zstandard.ZstdError, RuntimeError, ValueError, OverflowError, MemoryError) as exc:
        raise DamagedRecord(f"chunk does not decompress: {exc}") from None
    if len(data) != size or (crc != 0 and zlib.crc32(data) != crc):
        raise DamagedRecord("chunk CRC mismatch")
    return data


class _Scanner:
    """Finds and validates chunk records; remembers the last one so no chunk is decompressed twice."""

    def __init__(self, buf):
        self.buf = buf
        self.size = len(buf)
        self._cached: tuple[int, bytes | None] = (-1, None)
        self._nothing_from: int | None = None
        self._found: dict[bytes, tuple[int, int]] = {}

    def _find(self, mark: bytes, start: int) -> int:
        """``buf.find(mark, start)``, reusing the previous search (files are walked forwards)."""
        searched_from, at = self._found.get(mark, (None, -1))
        if searched_from is not None and searched_from <= start and (at == -1 or at >= start):
            return at
        at = self.buf.find(mark, start)
        self._found[mark] = (start, at)
        return at

    def records(self, pos: int) -> bytes | None:
        """Decompressed records of the chunk record at ``pos`` if it validates (CRC, sizes), else None.

        The opcode byte is not asked: a chunk whose opcode was flipped (into a message, a footer...)
        is still the chunk its CRC proves, not a record to believe."""
        if self._cached[0] == pos:
            return self._cached[1]
        result = None
        buf = self.buf
        if 0 <= pos and pos + 9 <= self.size:
            (length,) = _U64.unpack_from(buf, pos + 1)
            if pos + 9 + length <= self.size:
                try:
                    result = _check_tiling(_chunk_payload(buf[pos + 9:pos + 9 + length]))
                except (DamagedRecord, struct.error, MemoryError):
                    result = None
        self._cached = (pos, result)
        return result

    def next_chunk(self, start: int) -> int:
        """Offset of the first compressed chunk at or after ``start`` that validates, or the size."""
        if self._nothing_from is not None and start >= self._nothing_from:
            return self.size
        best = self.size
        for mark in (_ZSTD_MARK, _LZ4_MARK):
            at = self._find(mark, start + 37)
            while 0 <= at and at - 37 < best:
                if self.records(at - 37) is not None:
                    best = at - 37
                    break
                at = self._find(mark, at + 1)
        if best == self.size:
            self._nothing_from = start
        return best


def read_file(path: str | Path, report: ReadReport | None = None) -> Iterator[RawMessage]:
    """Yield every recoverable message of one MCAP file in file order; fill ``report``."""
    for batch in read_file_batches(path, report):
        yield from batch


def read_file_batches(path: str | Path, report: ReadReport | None = None) -> Iterator[list[RawMessage]]:
    """The messages of `read_file`, one list per chunk (fewer Python steps per message)."""
    path = Path(path)
    report = report if report is not None else ReadReport(str(path))
    report.path = str(path)
    with open(path, "rb") as handle:
        report.file_bytes = size = handle.seek(0, 2)
        if size == 0:
            report.header_ok = False
            report.problems.append("empty file")
            return
        with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as buf:
            yield from _walk(buf, report)


def read_buffer(buf, report: ReadReport | None = None) -> Iterator[RawMessage]:
    """Like `read_file` for bytes already in memory."""
    report = report if report is not None else ReadReport("<buffer>")
    report.file_bytes = len(buf)
    for batch in _walk(buf, report):
        yield from batch


def _summary_crc_ok(buf) -> bool:
    """True if the file ends in an intact footer whose summary CRC matches the summary section.

    Records outside chunks carry no CRC of their own; the summary's copies of the schema and
    channel records are trusted only through this one (MCAP spec: Footer.summary_crc)."""
    footer = len(buf) - len(MAGIC) - 9 - 20
    if footer < len(MAGIC) or buf[len(buf) - len(MAGIC):] != MAGIC:
        return False
    opcode, length = _RECORD_HEAD.unpack_from(buf, footer)
    if opcode != OP_FOOTER or length != 20:
        return False
    summary_start, _, crc = struct.unpack_from("<QQI", buf, footer + 9)
    return crc != 0 and len(MAGIC) < summary_start <= footer and \
        zlib.crc32(buf[summary_start:footer + 9 + 16]) == crc


def _walk(buf, report: ReadReport) -> Iterator[list[RawMessage]]:
    """Record by record; a record that would step over the next valid chunk is not trusted, nor a
    summary schema or channel record unless the footer's summary CRC holds."""
    size = len(buf)
    channels = _Channels()
    summary_unchecked = False
    scanner = _Scanner(buf)
    pos = len(MAGIC)
    if buf[:len(MAGIC)] != MAGIC:
        report.header_ok = False
        report.problems.append("no MCAP magic at the start")
        pos = 0
    guard = scanner.next_chunk(pos)
    chunked = guard < size  # then messages live in chunks: one outside is a damaged record
    while pos + 9 <= size:
        if pos > guard:
            guard = scanner.next_chunk(pos)
        opcode, length = _RECORD_HEAD.unpack_from(buf, pos)
        end = pos + 9 + length
        if opcode == OP_CHUNK or pos == guard:
            if end > size and guard == size:
                break  # the chunk the power cut interrupted
            report.chunks += 1
            records = scanner.records(pos)
            messages = None
            if records is not None:
                try:
                    messages = _messages(records, channels, report)
                except (DamagedRecord, struct.error, UnicodeDecodeError):
                    messages = None
            if messages is None:
                report.bad_chunks += 1
                guard = scanner.next_chunk(pos + 1)
                report.read_bytes = max(report.read_bytes, min(end, guard, size))
                report.skipped_bytes += max(0, guard - end) if guard < size else 0
                pos = guard
                continue
            if messages:
                yield messages
        elif opcode not in _VALID_OPS or end > size or end > guard or (
                opcode == OP_FOOTER and (length != 20 or buf[end:end + len(MAGIC)] != MAGIC)):
            if guard >= size:
                break
            report.skipped_bytes += guard - pos
            pos = guard
            continue
        elif opcode in (OP_SCHEMA, OP_CHANNEL) and summary_unchecked:
            pass  # copies of in-chunk records; messages left without their channel are counted
        elif opcode == OP_MESSAGE and chunked:
            report.skipped_bytes += end - pos
        elif opcode in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
            try:
                messages = _messages(buf[pos:end], channels, report)
            except (DamagedRecord, struct.error, UnicodeDecodeError):
                messages = []
                report.skipped_bytes += end - pos
            if messages:
                yield messages
        elif opcode == OP_HEADER:
            try:
                report.profile, _ = _string(buf[pos + 9:end], 0)
            except (DamagedRecord, struct.error, UnicodeDecodeError):
                pass
        elif opcode == OP_DATA_END:
            summary_unchecked = not _summary_crc_ok(buf)
        elif opcode == OP_FOOTER:
            report.complete = True
            report.read_bytes = min(size, end + len(MAGIC))
            break
        report.read_bytes = end
        pos = end
    for waiting in channels.pending.values():
        report.unattributed_messages += len(waiting)
    channels.pending.clear()


def _messages(data: bytes, channels: _Channels, report: ReadReport) -> list[RawMessage]:
    """Messages of a run of records (a chunk's content, or one top-level record).

    The whole run is parsed before any message is handed out, so a damaged record inside a
    CRC-valid chunk cannot stop the loop half-way through a chunk."""
    out = []
    append = out.append
    pos, size = 0, len(data)
    head, message_head = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
    known = channels.channels
    last_id, last_channel = -1, None
    while pos < size:
        opcode, length = head(data, pos)
        start, end = pos + 9, pos + 9 + length
        pos = end
        if opcode == OP_MESSAGE:
            channel_id, sequence, log_time, publish_time = message_head(data, start)
            if channel_id != last_id:
                last_id, last_channel = channel_id, known.get(channel_id)
            payload = data[start + 22:end]
            if last_channel is None:
                channels.pending.setdefault(channel_id, []).append((sequence, log_time, publish_time, payload))
                last_id = -1
                continue
            append(RawMessage(last_channel, sequence, log_time, publish_time, payload))
        elif opcode == OP_SCHEMA:
            channels.add_schema(data[start:end])
        elif opcode == OP_CHANNEL:
            body = data[start:end]
            channels.add_channel(body)
            channel = known[struct.unpack_from("<H", body, 0)[0]]
            last_id = -1
            for sequence, log_time, publish_time, payload in channels.pending.pop(channel.id, []):
                append(RawMessage(channel, sequence, log_time, publish_time, payload))
    report.messages += len(out)
    return out
