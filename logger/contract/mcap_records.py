"""MCAP records of haulprofile logs, parsed and checked: what the reader believes of a file.

Opcodes and layouts of the MCAP spec (https://mcap.dev/spec), the chunk check (decompressed size,
CRC-32 of the records, records tiling the chunk), the footer's summary CRC, and the read report.
"""

from __future__ import annotations

import struct
import threading
from dataclasses import dataclass, field
from typing import NamedTuple

try:  # ISA-L's CRC-32 (same polynomial as zlib's) runs at tens of GB/s, zlib's at about 2
    from isal.isal_zlib import crc32
except ImportError:
    from zlib import crc32

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_CHUNK_INDEX, OP_ATTACHMENT, OP_METADATA, OP_DATA_END = 0x08, 0x09, 0x0C, 0x0F
_VALID_OPS = set(range(0x01, 0x10))
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_RECORD_HEAD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQII")
_ZSTD_MARK = b"\x04\x00\x00\x00zstd"
_LZ4_MARK = b"\x03\x00\x00\x00lz4"
_MARK_AT = 9 + _CHUNK_HEAD.size - 4
"""Offset of a chunk's compression string (its length first) from the chunk record's start."""
MAX_CHUNK_BYTES = 1 << 28
"""Largest uncompressed chunk believed, 256 MiB (writers use 1 MiB by default, ROS 2 4 MiB, the
logger 256 KiB); a larger size field is a damaged one, not a reason to allocate that much. No
chunk decompresses to more than its size field says: the decompressors are bounded by it."""


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


class Attachment(NamedTuple):
    log_time_ns: int
    create_time_ns: int
    name: str
    media_type: str
    data: bytes


@dataclass
class ReadReport:
    """What a read found in one file [bytes, counts]."""

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
    library: str = ""
    metadata: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    """The metadata records read (name, map), in file order."""
    attachments: list[Attachment] = field(default_factory=list)
    """The attachments whose CRC holds, in file order."""
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


def _string_map(body, pos: int) -> tuple[dict[str, str], int]:
    (map_len,) = _U32.unpack_from(body, pos)
    pos += 4
    end = pos + map_len
    if end > len(body):
        raise DamagedRecord("map beyond record")
    entries = {}
    while pos < end:
        key, pos = _string(body, pos)
        value, pos = _string(body, pos)
        entries[key] = value
    return entries, end


def parse_metadata(body) -> tuple[str, dict[str, str]]:
    name, pos = _string(body, 0)
    return name, _string_map(body, pos)[0]


def parse_attachment(body) -> Attachment:
    """An attachment record's fields; `DamagedRecord` when its CRC (if set) does not hold."""
    log_time, create_time = struct.unpack_from("<QQ", body, 0)
    name, pos = _string(body, 16)
    media_type, pos = _string(body, pos)
    (n,) = _U64.unpack_from(body, pos)
    end = pos + 8 + n
    if end + 4 > len(body):
        raise DamagedRecord("attachment data beyond record")
    (crc,) = _U32.unpack_from(body, end)
    if crc and crc32(bytes(body[:end])) != crc:
        raise DamagedRecord("attachment CRC")
    return Attachment(log_time, create_time, name, media_type, bytes(body[pos + 8:end]))


def parse_header(body) -> tuple[str, str]:
    """(profile, library) of a header record's body."""
    profile, pos = _string(body, 0)
    return profile, _string(body, pos)[0]


def _parse_channel(body) -> tuple[int, int, str, str, dict]:
    channel_id, schema_id = struct.unpack_from("<HH", body, 0)
    topic, pos = _string(body, 4)
    encoding, pos = _string(body, pos)
    metadata, _ = _string_map(body, pos)
    return channel_id, schema_id, topic, encoding, metadata


def header_profile(head) -> str:
    """The profile of a file's header record ("" when the magic or header is damaged)."""
    if head[:len(MAGIC)] != MAGIC or len(head) < len(MAGIC) + 9 or head[len(MAGIC)] != OP_HEADER:
        return ""
    try:
        return _string(head, len(MAGIC) + 9)[0]
    except (DamagedRecord, UnicodeDecodeError, struct.error):
        return ""


_per_thread = threading.local()


def _zstd_decompressor():
    """This thread's zstd decompressor (a context is worth keeping: some 7 % of the time of a chunk)."""
    decompressor = getattr(_per_thread, "zstd", None)
    if decompressor is None:
        import zstandard

        decompressor = _per_thread.zstd = zstandard.ZstdDecompressor()
    return decompressor


def _decompress(body) -> bytes:
    """Decompressed, CRC-checked records of a chunk body (DamagedRecord if not)."""
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
    import zstandard
    try:
        if compression == b"zstd":
            declared = zstandard.frame_content_size(raw)
            if declared == size:  # the frame says what the chunk says: one call, bounded by both
                data = _zstd_decompressor().decompress(raw, max_output_size=size)
            else:  # a frame that declares more, or nothing: read at most one byte past the size
                data = _zstd_decompressor().stream_reader(bytes(raw)).read(size + 1)
        elif compression == b"lz4":
            import lz4.frame
            data = lz4.frame.LZ4FrameDecompressor().decompress(raw, max_length=size + 1)
        elif compression == b"":
            data = bytes(raw)
        else:
            raise DamagedRecord(f"unknown chunk compression {compression!r}")
    except (zstandard.ZstdError, RuntimeError, ValueError, OverflowError, MemoryError) as exc:
        _per_thread.__dict__.pop("zstd", None)  # start the next chunk with a fresh context
        raise DamagedRecord(f"chunk does not decompress: {exc}") from None
    if len(data) != size or (crc != 0 and crc32(data) != crc):
        raise DamagedRecord("chunk CRC mismatch")
    return data


def _tiles(data: bytes) -> bool:
    """True if ``data``'s records tile it exactly (opcodes known, lengths in range)."""
    pos, size, head, valid = 0, len(data), _RECORD_HEAD.unpack_from, _VALID_OPS
    while pos < size:
        if pos + 9 > size:
            return False
        opcode, length = head(data, pos)
        pos += 9 + length
        if opcode not in valid or pos > size:
            return False
    return True


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
        crc32(buf[summary_start:footer + 9 + 16]) == crc
