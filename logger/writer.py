"""MCAP writer bound to the data contract: one channel per topic, registered on first use."""

from __future__ import annotations

from typing import BinaryIO

from mcap.writer import CompressionType, Writer

from . import contract


class LogWriter:
    """Writes contract topics into one MCAP stream.

    ``chunk_size`` bounds what is held in memory before a chunk is written; the logger uses a
    small one and closes chunks by time as well, so a power cut loses at most a second or two.
    """

    def __init__(self, stream: BinaryIO, chunk_size: int = 256 * 1024, compression: str = "zstd",
                 channel_metadata: dict[str, dict[str, str]] | None = None):
        self._stream = stream
        self._writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType[compression.upper()])
        self._writer.start(profile=contract.PROFILE, library=f"haulprofile-contract-{contract.CONTRACT_VERSION}")
        self._channels: dict[str, int] = {}
        self._channel_metadata = channel_metadata or {}
        self._sequence: dict[str, int] = {}

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
        self._writer.add_message(channel_id=channel, log_time=int(t_realtime_ns), data=payload,
                                 publish_time=int(t_mono_ns), sequence=self._sequence[topic.name])

    def write_json(self, topic: contract.Topic, record: dict, t_mono_ns: int, t_realtime_ns: int) -> None:
        self.write(topic, contract.encode_json(record), t_mono_ns, t_realtime_ns)

    def write_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name=name, data=data)

    def close(self) -> None:
        self._writer.finish()
