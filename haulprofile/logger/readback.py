"""Reading the logger's own files back without the analysis extra: a linear MCAP read.

A linear read (`mcap.stream_reader.StreamReader`) needs no summary section, so it reads the file
being written and files cut short by a power loss up to their last complete chunk.
"""

from __future__ import annotations

import json
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
        except (McapError, EOFError, ValueError, KeyError):
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
