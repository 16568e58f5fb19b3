"""``analyze recover``: a repaired, indexed copy of a cut or damaged MCAP log.

Every message the reader (`haulprofile.contract.reader`) recovers is written again, with its schema, channel (metadata
included), times and sequence number unchanged, into a new file with chunk indexes and a summary,
so the seeking reader and Foxglove open it. The damaged original is never modified.
"""

from __future__ import annotations

from pathlib import Path

from mcap.writer import CompressionType, Writer

from haulprofile.contract.reader import ReadReport, header_profile, read_messages

from .logs import LogError


def recover(source: str | Path, target: str | Path, chunk_size: int = 1024 * 1024) -> ReadReport:
    """Write the recoverable messages of ``source`` to ``target``; return what the read found."""
    source, target = Path(source), Path(target)
    if not source.is_file():
        raise LogError(f"{source} not found")
    if target.resolve() == source.resolve():
        raise LogError(f"{target}: the repaired copy must not overwrite the original; choose another name")
    report = ReadReport(str(source))
    schema_ids: dict[tuple, int] = {}
    channel_ids: dict[int, int] = {}
    with open(target, "wb") as stream:
        writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        writer.start(profile=_profile(source), library="haulprofile-recover")
        for message in read_messages(source, report):
            channel = message.channel
            if channel.id not in channel_ids:
                key = (channel.schema_name, channel.schema_encoding, channel.schema_data)
                if key not in schema_ids:
                    schema_ids[key] = writer.register_schema(name=channel.schema_name or channel.topic,
                                                             encoding=channel.schema_encoding,
                                                             data=channel.schema_data)
                channel_ids[channel.id] = writer.register_channel(
                    topic=channel.topic, message_encoding=channel.message_encoding,
                    schema_id=schema_ids[key], metadata=dict(channel.metadata))
            writer.add_message(channel_id=channel_ids[channel.id], log_time=message.log_time_ns,
                               data=message.data, publish_time=message.publish_time_ns,
                               sequence=message.sequence)
        writer.finish()
    if report.messages == 0:
        target.unlink()
        raise LogError(f"{source}: no message could be recovered (not an MCAP log, or damaged from the start)")
    return report


def _profile(path: Path) -> str:
    """The header's profile of the original ("" when the header is damaged)."""
    with open(path, "rb") as handle:
        return header_profile(handle.read(4096))
