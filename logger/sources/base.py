"""What every source shares: the queue it feeds, the clock, and its health counters."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

from haulprofile import contract
from ..clock import Clock


@dataclass
class SourceStats:
    """Counters a source keeps; `/diagnostics` turns them into rates once per second."""

    records: int = 0
    messages: int = 0
    drops: int = 0
    errors: int = 0
    state: str = "starting"
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"records": self.records, "messages": self.messages, "drops": self.drops,
                "errors": self.errors, "state": self.state, **self.extra}


@dataclass
class LogItem:
    topic: contract.Topic
    payload: bytes
    t_mono_ns: int
    t_realtime_ns: int
    records: int = 1


class Source:
    """Base of the sources; ``run()`` is the task, ``emit()`` hands a message to the writer."""

    name = "source"

    def __init__(self, queue: asyncio.Queue, clock: Clock, say=None):
        self.queue = queue
        self.clock = clock
        self.stats = SourceStats()
        self._say = say or (lambda message: None)

    def say(self, message: str) -> None:
        """A line for the next `/diagnostics` message (and the journal)."""
        self._say(f"{self.name}: {message}")

    def emit(self, topic: contract.Topic, payload: bytes, t_mono_ns: int, records: int = 1) -> None:
        offset = self.clock.mono_offset_ns()
        try:
            self.queue.put_nowait(LogItem(topic, payload, t_mono_ns, t_mono_ns + offset, records))
        except asyncio.QueueFull:
            self.stats.drops += records
            return
        self.stats.records += records
        self.stats.messages += 1

    def emit_json(self, topic: contract.Topic, record: dict, t_mono_ns: int) -> None:
        self.emit(topic, contract.encode_json(record), t_mono_ns)

    async def run(self) -> None:
        raise NotImplementedError

    async def close(self) -> None:
        """Release the device; called once on shutdown."""
