"""`/diagnostics` once per second, and the systemd notify protocol (READY, WATCHDOG, STATUS)."""

from __future__ import annotations

import logging
import os

from .clock import Clock

log = logging.getLogger("haulprofile.logger")

SAID_AT = (1, 100, 10000)
"""Which occurrence of a repeated event the logger says (journal and `/diagnostics`): the first,
then the 100th and the 10 000th; the others are counted in the source's stats. A link that comes
and goes, or a sensor that keeps failing, is then said a few times a drive, not every second."""


def worth_saying(count: int) -> bool:
    """True for the ``count``-th occurrence of a repeated event if it is one that is said (`SAID_AT`)."""
    return count in SAID_AT


def ordinal(count: int) -> str:
    """``1st``, ``2nd``, ``100th``: the occurrence in a message."""
    suffix = "th" if 10 <= count % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(count % 10, "th")
    return f"{count}{suffix}"


class Diagnostics:
    """Per-source rates, drops, errors and state; queue depth; disk; messages since the last one."""

    def __init__(self, clock: Clock):
        self.clock = clock
        self.messages: list[str] = []
        self.storage = None
        self.paused_drops = 0
        self._last: dict[str, tuple[int, int]] = {}

    def record(self, t_mono_ns: int, sources, queue_depth: int) -> dict:
        per_source = {}
        for source in sources:
            stats = source.stats.as_dict()
            last_t, last_records = self._last.get(source.name, (None, 0))
            if last_t is not None and t_mono_ns > last_t:
                stats["rate_hz"] = (source.stats.records - last_records) / ((t_mono_ns - last_t) * 1e-9)
            else:
                stats["rate_hz"] = None
            self._last[source.name] = (t_mono_ns, source.stats.records)
            per_source[source.name] = stats
        record = {"t_mono_ns": t_mono_ns, "sources": per_source, "queue_depth": queue_depth,
                  "disk_free_bytes": self.storage.free_bytes() if self.storage else 0,
                  "messages": self.messages[:], "paused_drops": self.paused_drops,
                  "file": self.storage.path.name if self.storage and self.storage.path else None}
        self.messages.clear()
        return record

    def status_line(self, sources) -> str:
        return "; ".join(f"{s.name} {s.stats.records} rec, {s.stats.drops} drops" for s in sources)


class SystemdNotifier:
    """sd_notify via the sdnotify package; a no-op when NOTIFY_SOCKET is unset (not under systemd)."""

    def __init__(self):
        self._notifier = None
        if os.environ.get("NOTIFY_SOCKET"):
            try:
                import sdnotify
                self._notifier = sdnotify.SystemdNotifier()
            except ImportError:
                log.warning("NOTIFY_SOCKET is set but sdnotify is not installed: no watchdog pings")
        self.sent: list[str] = []

    def _notify(self, state: str) -> None:
        if self._notifier is not None:
            self._notifier.notify(state)
            self.sent.append(state)

    def ready(self, status: str) -> None:
        self._notify(f"READY=1\nSTATUS={status}")

    def watchdog(self, status: str) -> None:
        self._notify(f"WATCHDOG=1\nSTATUS={status}")

    def stopping(self) -> None:
        self._notify("STOPPING=1")
