"""MCAP writer bound to the data contract: one channel per topic, registered on first use.

Crash safety: chunks are closed by size *and* by the age of their data (``chunk_interval_s``),
then the file is flushed and fsync'ed, so a power cut loses at most the open chunk. A file cut
short is still readable with a linear read (``mcap.stream_reader.StreamReader``) up to its last
complete chunk.
"""

from __future__ import annotations

import os
from typing import BinaryIO

from mcap.writer import CompressionType, Writer

from haulprofile import contract


class LogWriter:
    """Writes contract topics into one MCAP stream.

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
        self._stream = stream
        self._log_time = log_time
        self._writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType[compression.upper()])
        self._writer.start(profile=contract.PROFILE, library=f"haulprofile-contract-{contract.CONTRACT_VERSION}")
        self._channels: dict[str, int] = {}
        self._channel_metadata = channel_metadata or {}
        self._sequence: dict[str, int] = {}
        self._chunk_interval_ns = None if chunk_interval_s is None else int(chunk_interval_s * 1e9)
        self._fsync = fsync
        self._chunk_first_mono_ns: int | None = None
        self.message_count = 0
        self.chunk_flushes = 0
        self.closed = False

    def channel_id(self, topic: contract.Topic) -> int:
        if topic.name not in self._channels:
            schema_id = self._writer.register_schema(
                name=topic.schema_name, encoding=topic.schema_encoding, data=topic.schema_data())
            self._channels[topic.name] = self._writer.register_channel(
                topic=topic.name, message_encoding=topic.encoding, schema_id=schema_id,
                metadata=self._channel_metadata.get(topic.name, {}))
            self._sequence[topic.name] = 0
        return self._channels[topic.name]

    def write(self, topic: contract.Topic, payload: bytes, t_mono_ns: int, t_realtime_ns: int) -> None:
        """Add one message; ``publish_time`` is monotonic, ``log_time`` wall-clock (contract)."""
        channel = self.channel_id(topic)
        self._sequence[topic.name] += 1
        if self._log_time is not None:
            t_realtime_ns = self._log_time(t_realtime_ns, t_mono_ns)
        self._writer.add_message(channel_id=channel, log_time=int(t_realtime_ns), data=payload,
                                 publish_time=int(t_mono_ns), sequence=self._sequence[topic.name])
        self.message_count += 1
        if self._chunk_first_mono_ns is None:
            self._chunk_first_mono_ns = int(t_mono_ns)
        self.flush_if_due(int(t_mono_ns))

    def write_json(self, topic: contract.Topic, record: dict, t_mono_ns: int, t_realtime_ns: int) -> None:
        self.write(topic, contract.encode_json(record), t_mono_ns, t_realtime_ns)

    def write_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name=name, data=data)

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
        self._sync()

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
        self._writer.finish()
        self.closed = True
        if self._fsync:
            try:
                self._stream.flush()
            except (AttributeError, OSError, ValueError):
                return
            self._sync()
