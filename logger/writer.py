"""The logger's MCAP writer: the contract's `TopicWriter` (one channel per topic, registered on
first use) with the daemon's durability policy.

Crash safety: chunks are closed by size *and* by the age of their data (``chunk_interval_s``),
then the file is flushed and fsync'ed, so a power cut loses at most the open chunk. A file cut
short is still readable with a linear read (``mcap.stream_reader.StreamReader``) up to its last
complete chunk.
"""

from __future__ import annotations

import os
from typing import BinaryIO

from haulprofile import contract
from haulprofile.contract.writer import TopicWriter


class LogWriter(TopicWriter):
    """Writes contract topics into one MCAP stream (`TopicWriter`), durably.

    ``chunk_size`` [bytes] bounds what is held in memory before a chunk is written;
    ``chunk_interval_s`` [s] closes a chunk once its first message is that old (monotonic time of
    the data), and ``fsync`` makes every closed chunk durable: ``True`` calls ``os.fsync`` at once,
    a callable ``fsync(fd)`` is called instead (the daemon hands the fsync to a thread so the event
    loop never waits for the disk).
    """

    def __init__(self, stream: BinaryIO, chunk_size: int = 256 * 1024, compression: str = "zstd",
                 channel_metadata: dict[str, dict[str, str]] | None = None,
                 chunk_interval_s: float | None = None, fsync=False, log_time=None):
        """``log_time(t_realtime_ns, t_mono_ns)``: the MCAP ``log_time`` to write (privacy
        coarsening of wall-clock time); default the realtime stamp as it is."""
        super().__init__(stream, chunk_size=chunk_size, compression=compression, channel_metadata=channel_metadata)
        self._log_time = log_time
        self._chunk_interval_ns = None if chunk_interval_s is None else int(chunk_interval_s * 1e9)
        self._fsync = fsync
        self._chunk_first_mono_ns: int | None = None
        self.chunk_flushes = 0
        self.complete_bytes = 0
        """Bytes of the stream that end at a record boundary and were handed to the file system
        (after the header, or the last `flush`): where a file cut by a failed write is truncated."""

    def write(self, topic: contract.Topic, payload: bytes, t_mono_ns: int, t_realtime_ns: int) -> None:
        """Add one message; ``publish_time`` is monotonic, ``log_time`` wall-clock (contract)."""
        if self._log_time is not None:
            t_realtime_ns = self._log_time(t_realtime_ns, t_mono_ns)
        super().write(topic, payload, t_mono_ns, t_realtime_ns)
        if self._chunk_first_mono_ns is None:
            self._chunk_first_mono_ns = int(t_mono_ns)
        self.flush_if_due(int(t_mono_ns))

    def flush_if_due(self, now_mono_ns: int) -> bool:
        """Close the open chunk if its first message is ``chunk_interval_s`` old; True if closed."""
        if (self._chunk_interval_ns is not None and self._chunk_first_mono_ns is not None
                and now_mono_ns - self._chunk_first_mono_ns >= self._chunk_interval_ns):
            self.flush()
            return True
        return False

    def flush(self) -> None:
        """Write the open chunk, flush the stream and (if enabled) fsync it."""
        self._writer.flush()
        self._chunk_first_mono_ns = None
        self.chunk_flushes += 1
        self.complete_bytes = self._stream_offset()
        self._sync()

    def _stream_offset(self) -> int:
        try:
            return self._stream.tell()
        except (AttributeError, OSError, ValueError):
            return 0

    def _sync(self) -> None:
        if not self._fsync:
            return
        try:
            fd = self._stream.fileno()
        except (AttributeError, OSError, ValueError):
            return
        if callable(self._fsync):
            self._fsync(fd)
        else:
            os.fsync(fd)

    def close(self) -> None:
        """Write the last chunk and the summary section (indexes, statistics)."""
        if self.closed:
            return
        super().close()
        if self._fsync:
            try:
                self._stream.flush()
            except (AttributeError, OSError, ValueError):
                return
            self._sync()
