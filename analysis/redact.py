"""``analyze redact``: new, complete logs without what was recorded inside privacy zones.

For logs written before zones were configured (the logger's own zones act before writing). Per
input log, in two passes of the contract's reader (`haulprofile.contract.reader`; a cut or
damaged log is refused: ``analyze recover`` first):

1. the ``/gps/fix`` positions give the stretches spent in a zone: from the first fix inside to the
   first fix outside again, on the monotonic clock (to the start of the file when its first fix
   is inside, or the file before ended inside; to the end when its last one is). A loaded
   logger stamps the epochs it reads from the port in one go with one time: a time held by any
   fix inside is inside;
2. a new file is written with the ``mcap`` library's writer: fixes inside are dropped (each fix
   by its own position), NMEA sentences received inside are cut out of their ``/gps/nmea``
   batches (a batch left empty is dropped), J1939 Vehicle Position (PGN 65267) and Time/Date
   (65254) frames inside leave ``/can/frames`` (as do Vehicle Position frames whose own position
   is in a zone), ``/time/sync`` inside loses its GPS time, and ``/privacy/zone`` records
   (``source = "redact"``) mark each stretch. Every other message, schema, channel, metadata and attachment
   is copied as it was (data byte for byte, times, sequence numbers); chunk indexes, statistics
   and the summary are those of the new file.

Inputs are never opened for writing; an output that would replace an input, or a file that
`analyze redact` did not write itself (`manifest.Manifest`), is refused, and so is a symbolic link.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from haulprofile import contract
from haulprofile.contract.privacy import (POSITION_PGNS, VEHICLE_POSITION_PGN, Zone, frame_pgns, in_any,
                                          vehicle_positions, zones_from_tables)
from haulprofile.contract.reader import Channel, RawMessage, ReadReport, read_messages, read_windows
from haulprofile.contract.private_files import FILE_MODE, make_dirs

from haulprofile.contract.input_files import read_small

from .errors import UserError
from .manifest import Manifest, refuse_link

INF = float("inf")


def load_zones(path: str | Path) -> list[Zone]:
    """Zones from a TOML file: ``[[zones]]`` tables, or a logger configuration's ``[[privacy.zones]]``."""
    import tomllib
    path = Path(path)
    raw = read_small(path, "zones file", UserError)
    try:
        data = tomllib.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise UserError(f"--zones {path}: not UTF-8 text (invalid byte at offset {exc.start}); TOML is UTF-8") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"--zones {path}: not valid TOML: {exc}") from None
    tables, where = data.get("zones"), "zones"
    if tables is None and isinstance(data.get("privacy"), dict):
        tables, where = data["privacy"].get("zones"), "privacy.zones"
    if not tables or not isinstance(tables, list):
        raise UserError(f"--zones {path}: no [[zones]] (or [[privacy.zones]]) tables")
    try:
        return zones_from_tables(tables, where)
    except ValueError as exc:
        raise UserError(f"--zones {path}: {exc}") from None


@dataclass
class RedactReport:
    source: Path
    target: Path
    messages_in: int = 0
    messages_out: int = 0
    fixes_removed: int = 0
    sentences_removed: int = 0
    gps_times_removed: int = 0
    frames_removed: int = 0
    stretches: list[tuple[float, float]] = field(default_factory=list)
    ends_inside: bool = False

    def line(self) -> str:
        return (f"{self.source.name} -> {self.target}: {len(self.stretches)} stretch(es) in zones; removed "
                f"{self.fixes_removed} fixes, {self.sentences_removed} NMEA sentences, "
                f"{self.gps_times_removed} GPS times, {self.frames_removed} J1939 position/time frames; "
                f"{self.messages_out} of {self.messages_in} messages kept")


def _stretches(fixes: list[tuple[int, bool]], inside_at_start: bool) -> list[tuple[float, float]]:
    """[start, end) monotonic intervals [ns] spent in a zone, from (t_mono_ns, inside) of each fix;
    fixes that share a time are one instant, inside if any of them is."""
    inside_at: dict[int, bool] = {}
    for t, inside in fixes:
        inside_at[t] = inside_at.get(t, False) or inside
    times = sorted(inside_at)
    stretches, start = [], -INF if inside_at_start or (times and inside_at[times[0]]) else None
    for t in times:
        if inside_at[t] and start is None:
            start = t
        elif not inside_at[t] and start is not None:
            stretches.append((start, t))
            start = None
    if start is not None:
        stretches.append((start, INF))
    return stretches


def _in(stretches, t: int) -> bool:
    return any(a <= t < b for a, b in stretches)


def _read_fixes(data: bytes, zones: list[Zone], source: Path) -> tuple[list[tuple[int, bool]], ReadReport]:
    """(t_mono_ns, inside) of every ``/gps/fix``; a log that is cut or damaged is refused."""
    read = ReadReport(str(source))
    fixes = []
    for message in read_messages(data, read):
        if message.channel.topic == contract.GPS_FIX.name:
            fix = json.loads(message.data)
            fixes.append((int(fix["t_mono_ns"]), in_any(zones, fix["latitude"], fix["longitude"])))
    if not read.header_ok:
        raise UserError(f"{source}: not an MCAP log (no header)")
    if read.warning():
        raise UserError(f"{read.warning()}; run 'analyze recover' on it first")
    return fixes, read


def _without_position_frames(payload: bytes, zones: list[Zone], stretches, report: RedactReport) -> bytes | None:
    """A ``/can/frames`` batch without the J1939 Vehicle Position and Time/Date frames received in a
    zone's stretch, nor Vehicle Position frames whose own position lies in a zone (a log without
    GPS has no stretches); the batch as it was if none is dropped, None if all are."""
    import numpy as np

    frames = contract.unpack(contract.CAN_FRAMES, payload)
    pgns = frame_pgns(frames["arbitration_id"], frames["flags"] & contract.CAN_FLAG_EXTENDED)
    candidates = np.flatnonzero(np.isin(pgns, POSITION_PGNS))
    if not len(candidates):
        return payload
    drop = np.zeros(len(frames), bool)
    lat, lon = vehicle_positions(frames["data"][candidates])
    for i, index in enumerate(candidates):
        t = int(frames["t_mono_ns"][index])
        positioned = pgns[index] == VEHICLE_POSITION_PGN and np.isfinite(lat[i]) and np.isfinite(lon[i])
        drop[index] = _in(stretches, t) or bool(positioned and in_any(zones, float(lat[i]), float(lon[i])))
    if not drop.any():
        return payload
    report.frames_removed += int(drop.sum())
    kept = frames[~drop]
    return contract.pack(contract.CAN_FRAMES, kept) if len(kept) else None


def redact_bytes(data: bytes, zones: list[Zone], target_stream, inside_at_start: bool = False,
                 report: RedactReport | None = None) -> RedactReport:
    """Write the redacted copy of the MCAP log ``data`` into ``target_stream``."""
    report = report or RedactReport(Path("-"), Path("-"))
    fixes, first_read = _read_fixes(data, zones, report.source)
    stretches = _stretches(fixes, inside_at_start)
    report.stretches = stretches
    report.ends_inside = bool(stretches) and stretches[-1][1] == INF
    starts = {a for a, _ in stretches if a != -INF}
    ends = {b for _, b in stretches if b != INF}

    writer = Writer(target_stream, chunk_size=1024 * 1024, compression=CompressionType.ZSTD)
    writer.start(profile=first_read.profile, library=first_read.library)
    schema_ids: dict[tuple, int] = {}
    channel_ids: dict[int, int] = {}
    marker_channel = None
    seen_metadata: set[tuple] = set()
    seen_attachments: set[tuple] = set()
    read = ReadReport(str(report.source))
    channels: dict[int, Channel] = {}

    def out_channel(channel: Channel) -> int:
        if channel.id not in channel_ids:
            key = (channel.schema_name, channel.schema_encoding, channel.schema_data)
            if key not in schema_ids:
                schema_ids[key] = 0 if key == ("", "", b"") else writer.register_schema(*key)
            channel_ids[channel.id] = writer.register_channel(
                channel.topic, channel.message_encoding, schema_ids[key], dict(channel.metadata))
        return channel_ids[channel.id]

    def marker(event: str, message: RawMessage, t_mono: int) -> None:
        nonlocal marker_channel
        if marker_channel is None:
            existing = [c for c in channels.values() if c.topic == contract.PRIVACY_ZONE.name]
            if existing:
                marker_channel = out_channel(existing[0])
            else:
                topic = contract.PRIVACY_ZONE
                schema_id = writer.register_schema(topic.schema_name, topic.schema_encoding, topic.schema_data())
                marker_channel = writer.register_channel(topic.name, topic.encoding, schema_id)
        payload = contract.encode_json({"t_mono_ns": t_mono, "event": event, "source": "redact"})
        writer.add_message(marker_channel, log_time=message.log_time_ns, data=payload,
                           publish_time=message.publish_time_ns)
        report.messages_out += 1

    def copy_metadata_and_attachments() -> None:
        for name, entries in read.metadata:
            key = (name, tuple(sorted(entries.items())))
            if key not in seen_metadata:
                seen_metadata.add(key)
                writer.add_metadata(name, dict(entries))
        for attachment in read.attachments:
            key = (attachment.name, attachment.log_time_ns, attachment.data)
            if key not in seen_attachments:
                seen_attachments.add(key)
                writer.add_attachment(attachment.create_time_ns, attachment.log_time_ns, attachment.name,
                                      attachment.media_type, attachment.data)

    for window in read_windows(data, read):
        copy_metadata_and_attachments()
        channels.update(window.channels)
        for message in window.messages():
            report.messages_in += 1
            topic = message.channel.topic
            payload = message.data
            if topic == contract.GPS_FIX.name:
                fix = json.loads(payload)
                t = int(fix["t_mono_ns"])
                if t in starts:
                    marker("entered", message, t)
                    starts.discard(t)
                if t in ends:
                    marker("left", message, t)
                    ends.discard(t)
                if in_any(zones, fix["latitude"], fix["longitude"]):
                    report.fixes_removed += 1
                    continue
            elif topic == contract.GPS_NMEA.name and stretches:
                batch = json.loads(payload)
                keep = [(s, t) for s, t in zip(batch["sentences"], batch["t_mono_ns_each"]) if not _in(stretches, t)]
                if len(keep) != len(batch["sentences"]):
                    report.sentences_removed += len(batch["sentences"]) - len(keep)
                    if not keep:
                        continue
                    payload = contract.encode_json({"t_mono_ns": keep[0][1], "sentences": [s for s, _ in keep],
                                                    "t_mono_ns_each": [t for _, t in keep]})
            elif topic == contract.CAN_FRAMES.name:
                payload = _without_position_frames(payload, zones, stretches, report)
                if payload is None:
                    continue
            elif topic == contract.TIME_SYNC.name and stretches:
                sync = json.loads(payload)
                if sync.get("gps_time_utc_ns") is not None and _in(stretches, int(sync["t_mono_ns"])):
                    sync["gps_time_utc_ns"] = None
                    payload = contract.encode_json(sync)
                    report.gps_times_removed += 1
            writer.add_message(out_channel(message.channel), log_time=message.log_time_ns, data=payload,
                               publish_time=message.publish_time_ns, sequence=message.sequence)
            report.messages_out += 1
    copy_metadata_and_attachments()
    writer.finish()
    return report


def redact_files(inputs: list[Path], zones: list[Zone], out_dir: Path, read=None) -> list[RedactReport]:
    """Redact each log into ``out_dir`` under its own name (``.age`` dropped: the copy is plain);
    ``read(path) -> bytes`` opens a log (decrypting it where needed). A stretch that reaches the
    end of one file is carried into the next (inputs in the order given)."""
    read = read or (lambda p: Path(p).read_bytes())
    refuse_link(out_dir, "--out")
    make_dirs(out_dir)
    manifest = Manifest(out_dir)
    resolved_inputs = {p.resolve() for p in inputs}
    targets: dict[Path, Path] = {}
    for path in inputs:
        name = path.name[:-len(".age")] if path.name.endswith(".age") else path.name
        target = out_dir / name
        if target.resolve() in resolved_inputs or (target.exists() and os.path.samefile(target, path)):
            raise UserError(f"--out {out_dir}: {target} would replace an input log; choose another directory")
        if target in targets:
            raise UserError(f"{path} and {targets[target]} would both be written to {target}; redact them apart")
        manifest.check_target(target)
        targets[target] = path
    reports, inside = [], False
    for target, path in targets.items():
        report = RedactReport(path, target)
        fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".partial", dir=out_dir)
        partial = Path(name)
        try:
            os.fchmod(fd, FILE_MODE)
            with os.fdopen(fd, "wb") as stream:
                redact_bytes(read(path), zones, stream, inside, report)
                stream.flush()
                os.fsync(stream.fileno())
            manifest.install(target, partial)
        finally:
            partial.unlink(missing_ok=True)
        inside = report.ends_inside
        reports.append(report)
    return reports
