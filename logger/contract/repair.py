"""A repaired, indexed copy of a cut or damaged log, read by the one reader (`reader`).

Every message the reader recovers is written again with its schema, channel (metadata included),
times and sequence number unchanged, beside the file's metadata records, into a new file with
chunk indexes and a summary, so the seeking reader and Foxglove open it. The logger repairs a
file a power cut left open before it encrypts it (`repair`, in place: numpy and mcap only, no
numba or pandas needed on the Pi); ``analyze recover`` writes a copy beside the original
(`write_recovered`).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import BinaryIO

from mcap.writer import CompressionType, Writer

from . import PROFILE
from .mcap_records import MAGIC, OP_HEADER, DamagedRecord, ReadReport, parse_header
from .reader import read_windows


def is_complete(path: str | Path) -> bool:
    """True if the log ends with the MCAP footer's magic (closed cleanly: summary and indexes)."""
    path = Path(path)
    size = path.stat().st_size
    if size < 2 * len(MAGIC):
        return False
    with open(path, "rb") as stream:
        stream.seek(size - len(MAGIC))
        return stream.read() == MAGIC


def write_recovered(source: str | Path, sink: BinaryIO, report: ReadReport | None = None,
                    chunk_size: int = 1024 * 1024, library: str | None = None, **options) -> ReadReport:
    """Write everything the reader recovers of ``source`` to ``sink`` as a complete MCAP file;
    ``library`` None keeps the original header's. Returns the read report (``messages``: how
    many were written)."""
    report = report if report is not None else ReadReport(str(source))
    writer = Writer(sink, chunk_size=chunk_size, compression=CompressionType.ZSTD)
    profile, original_library = _header(source)
    writer.start(profile=profile or PROFILE,
                 library=library if library is not None else original_library or "haulprofile-repair")
    schema_ids: dict[tuple, int] = {}
    channel_ids: dict[int, int] = {}
    metadata_written = 0

    def flush_metadata() -> None:
        nonlocal metadata_written
        for name, data in report.metadata[metadata_written:]:
            writer.add_metadata(name, dict(data))
        metadata_written = len(report.metadata)

    for window in read_windows(source, report, **options):
        flush_metadata()
        for channel_id in sorted(set(window.channels) - set(channel_ids)):
            channel = window.channels[channel_id]
            key = (channel.schema_name, channel.schema_encoding, channel.schema_data)
            if key not in schema_ids:
                schema_ids[key] = 0 if key == ("", "", b"") else writer.register_schema(
                    name=channel.schema_name, encoding=channel.schema_encoding, data=channel.schema_data)
            channel_ids[channel_id] = writer.register_channel(
                topic=channel.topic, message_encoding=channel.message_encoding, schema_id=schema_ids[key],
                metadata=dict(channel.metadata))
        for message in window.messages():
            writer.add_message(channel_id=channel_ids[message.channel.id], log_time=message.log_time_ns,
                               data=message.data, publish_time=message.publish_time_ns, sequence=message.sequence)
    flush_metadata()
    writer.finish()
    return report


def repair(path: str | Path) -> int:
    """Replace a cut log with its repaired copy (`write_recovered`): written beside it (mode 0640),
    fsynced, then renamed over it. Returns the messages kept."""
    from haulprofile.contract.private_files import open_new

    path = Path(path)
    repaired = path.with_name(path.name + ".repaired")
    with open_new(repaired, exclusive=False) as sink:
        report = write_recovered(path, sink, chunk_size=256 * 1024)
        sink.flush()
        os.fsync(sink.fileno())
    os.replace(repaired, path)
    return report.messages


def _header(path: str | Path) -> tuple[str, str]:
    """(profile, library) of a file's header record; empty strings when it is damaged."""
    with open(path, "rb") as handle:
        head = handle.read(4096)
    if head[:len(MAGIC)] != MAGIC or len(head) < len(MAGIC) + 9 or head[len(MAGIC)] != OP_HEADER:
        return "", ""
    try:
        return parse_header(head[len(MAGIC) + 9:])
    except (DamagedRecord, UnicodeDecodeError, struct.error):
        return "", ""
