"""Reading the logger's own files back without the analysis extra: a linear MCAP read.

A linear read (`mcap.stream_reader.StreamReader`) needs no summary section, so it reads the file
being written and files cut short by a power loss up to their last complete chunk.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Iterator

from haulprofile import contract


def iter_records(path: str | Path, topics: set[str] | None = None) -> Iterator[tuple[str, int, bytes]]:
    """``(topic, publish time = monotonic [ns], payload)`` of every message, in file order; stops
    quietly at a cut (an open chunk, a file truncated by a power loss)."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader
    channels: dict[int, str] = {}
    with open(path, "rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                if isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message):
                    topic = channels.get(record.channel_id)
                    if topics is None or topic in topics:
                        yield topic, record.publish_time, record.data
        except (McapError, EOFError, ValueError, KeyError, struct.error):  # a cut inside a length field
            return


def can_frames(path: str | Path) -> Iterator:
    """The `/can/frames` records of a log (`contract.CAN_FRAME_DTYPE` arrays, one per message)."""
    for _, _, data in iter_records(path, {contract.CAN_FRAMES.name}):
        yield contract.unpack(contract.CAN_FRAMES, data)


def last_diagnostics(path: str | Path) -> dict | None:
    """The newest complete `/diagnostics` record of a log, or None."""
    last = None
    for _, _, data in iter_records(path, {contract.DIAGNOSTICS.name}):
        last = data
    return None if last is None else json.loads(last)


MCAP_MAGIC = b"\x89MCAP0\r\n"


def is_complete(path: str | Path) -> bool:
    """True if the log ends with the MCAP footer's magic (closed cleanly: summary and indexes)."""
    path = Path(path)
    size = path.stat().st_size
    if size < 2 * len(MCAP_MAGIC):
        return False
    with open(path, "rb") as stream:
        stream.seek(size - len(MCAP_MAGIC))
        return stream.read() == MCAP_MAGIC


def repair(path: str | Path) -> int:
    """Replace a cut log with an indexed copy of everything a linear read recovers (every message of
    every complete chunk, schemas, channels and metadata as they were), as ``analyze recover``
    does on the workstation; returns the messages kept. Written beside it, fsynced, then renamed."""
    import os

    from mcap.exceptions import McapError
    from mcap.records import Channel, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType, Writer

    from haulprofile.private_files import open_new

    path = Path(path)
    repaired = path.with_name(path.name + ".repaired")
    schemas: dict[int, Schema] = {}
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    messages = 0
    with open(path, "rb") as source, open_new(repaired, exclusive=False) as sink:
        writer = Writer(sink, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        started = False
        try:
            for record in StreamReader(source, validate_crcs=True).records:
                if isinstance(record, Header) and not started:
                    writer.start(profile=record.profile, library=record.library)
                    started = True
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel) and record.id not in channel_ids:
                    if record.schema_id and record.schema_id not in schema_ids:
                        s = schemas[record.schema_id]
                        schema_ids[record.schema_id] = writer.register_schema(s.name, s.encoding, s.data)
                    channel_ids[record.id] = writer.register_channel(
                        record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0),
                        dict(record.metadata))
                elif isinstance(record, Message) and record.channel_id in channel_ids:
                    writer.add_message(channel_ids[record.channel_id], log_time=record.log_time, data=record.data,
                                       publish_time=record.publish_time, sequence=record.sequence)
                    messages += 1
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, dict(record.metadata))
        except (McapError, EOFError, ValueError, KeyError, struct.error):
            pass  # the cut: everything before it is kept
        if not started:
            writer.start(profile=contract.PROFILE, library="haulprofile-repair")
        writer.finish()
        sink.flush()
        os.fsync(sink.fileno())
    os.replace(repaired, path)
    return messages
