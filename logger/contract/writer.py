"""How contract topics go into an MCAP stream: one channel per topic, registered on first use with
its schema, a sequence number per channel, ``publish_time`` monotonic and ``log_time`` wall clock.

The logger's `haulprofile.logger.writer.LogWriter` adds its durability policy (chunks closed by
age, fsync) on top; test data and the virtual truck write with this class alone, so the analysis
side never imports the daemon to produce a log.
"""

from __future__ import annotations

from typing import BinaryIO

from mcap.writer import CompressionType, Writer

from . import CONTRACT_VERSION, PROFILE, Topic, encode_json


class TopicWriter:
    """Writes contract topics into one MCAP stream.

    Parameters
    ----------
    stream : binary file
        Where the MCAP bytes go.
    chunk_size : int
        Bytes held in memory before a chunk is written [bytes].
    compression : str
        Chunk compression: ``"zstd"``, ``"lz4"`` or ``"none"``.
    channel_metadata : dict, optional
        Per topic name, the channel's metadata (e.g. the IMU's scale factors).
    contract_version : int
        The version the header names (an older one only for test logs of that version's topics).
    """

    def __init__(self, stream: BinaryIO, chunk_size: int = 256 * 1024, compression: str = "zstd",
                 channel_metadata: dict[str, dict[str, str]] | None = None, contract_version: int = CONTRACT_VERSION):
        self._stream = stream
        self._writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType[compression.upper()])
        self._writer.start(profile=PROFILE, library=f"haulprofile-contract-{contract_version}")
        self._channels: dict[str, int] = {}
        self._channel_metadata = channel_metadata or {}
        self._sequence: dict[str, int] = {}
        self.message_count = 0
        self.closed = False

    def channel_id(self, topic: Topic) -> int:
        if topic.name not in self._channels:
            schema_id = self._writer.register_schema(
                name=topic.schema_name, encoding=topic.schema_encoding, data=topic.schema_data())
            self._channels[topic.name] = self._writer.register_channel(
                topic=topic.name, message_encoding=topic.encoding, schema_id=schema_id,
                metadata=self._channel_metadata.get(topic.name, {}))
            self._sequence[topic.name] = 0
        return self._channels[topic.name]

    def write(self, topic: Topic, payload: bytes, t_mono_ns: int, t_realtime_ns: int) -> None:
        """Add one message; ``publish_time`` is monotonic, ``log_time`` wall-clock [ns] (contract)."""
        channel = self.channel_id(topic)
        self._sequence[topic.name] += 1
        self._writer.add_message(channel_id=channel, log_time=int(t_realtime_ns), data=payload,
                                 publish_time=int(t_mono_ns), sequence=self._sequence[topic.name])
        self.message_count += 1

    def write_json(self, topic: Topic, record: dict, t_mono_ns: int, t_realtime_ns: int) -> None:
        self.write(topic, encode_json(record), t_mono_ns, t_realtime_ns)

    def write_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name=name, data=data)

    def close(self) -> None:
        """Write the last chunk and the summary section (indexes, statistics)."""
        if self.closed:
            return
        self._writer.finish()
        self.closed = True
