"""Logs in, messages out: MCAP files (whole or cut) and foreign CAN logs, in time order.

Inputs are files or directories of them. MCAP files are ordered by the wall clock of their
first message; the monotonic clock restarts at a reboot, so a file whose monotonic time runs
backwards is shifted onto one continuous time line using the wall-clock distance between files.
Every message's ``t_mono_ns`` below is on that continuous line.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, NamedTuple

import numpy as np

from haulprofile import contract
from haulprofile.contract.naming import log_name_parts

from haulprofile.contract.reader import Channel, ReadReport, Window, first_message, read_windows

from ..encrypted import decrypted, is_encrypted
from ..errors import UserError
from . import foreign

MCAP_SUFFIXES = {".mcap"}


class LogError(UserError):
    pass


def expand(paths) -> list[Path]:
    """Files of ``paths``; directories contribute their MCAP and foreign CAN logs (recursively)."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    files: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.is_file()
                           and (p.suffix.lower() in MCAP_SUFFIXES | foreign.SUFFIXES or is_encrypted(p)))
            if not found:
                raise LogError(f"{path}: directory holds no .mcap (or .log/.asc/.blf/.mf4/.nmea/.ubx) files")
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            raise LogError(f"input {path} not found")
    if not files:
        raise LogError("no input logs given")
    return [decrypted(p) for p in files]


def is_mcap(path: Path) -> bool:
    if path.suffix.lower() in MCAP_SUFFIXES:
        return True
    with open(path, "rb") as handle:
        return handle.read(8) == b"\x89MCAP0\r\n"


class LogMessage(NamedTuple):
    """One message: topic, continuous monotonic time [ns], wall clock [ns], payload, channel."""

    topic: str
    t_mono_ns: int
    log_time_ns: int
    data: bytes
    channel: Channel
    file_index: int


@dataclass
class Timeline:
    """Per-file shifts onto the continuous monotonic line [ns]."""

    offsets_ns: dict[str, int] = field(default_factory=dict)
    reports: list[ReadReport] = field(default_factory=list)


def _first_message(path: Path):
    try:
        return first_message(path)
    except OSError as exc:
        raise LogError(f"{path}: cannot read ({exc.strerror or exc})") from None


def order_mcap(files: list[Path]) -> list[tuple[Path, int, int]]:
    """(path, first wall clock [ns], first monotonic [ns]) in the order the files were written.

    Files of one logger (its names: one prefix, distinct sequence numbers, `logger.storage`) go by
    their sequence number: a Raspberry Pi has no real-time clock and may log for hours with its
    clock behind after a power cut, so a later file can carry an earlier wall clock. Other files
    go by the wall clock of their first message; empty files last.
    """
    entries = []
    for path in files:
        first = _first_message(path)
        if first is None:
            entries.append((path, np.iinfo(np.int64).max, 0))
        else:
            entries.append((path, first.log_time_ns, first.publish_time_ns))
    names = [log_name_parts(path) for path in files]
    if names and all(names) and len({n[0] for n in names}) == 1 and len({n[1] for n in names}) == len(names):
        sequence = {path: n[1] for path, n in zip(files, names)}
        return sorted(entries, key=lambda e: sequence[e[0]])
    return sorted(entries, key=lambda e: (e[1], str(e[0])))


def iter_log_windows(paths, timeline: Timeline | None = None) -> Iterator[tuple[int, int, Window]]:
    """(file index, time shift [ns], `Window` of decoded chunks) of the MCAP logs in ``paths``, in
    time order; a file's monotonic times plus its shift lie on the continuous line.

    ``timeline`` (optional) receives each file's ReadReport and time shift. Foreign CAN logs
    in ``paths`` are skipped here (see `read_frames`).
    """
    timeline = timeline if timeline is not None else Timeline()
    files = [p for p in expand(paths) if is_mcap(p)]
    offset = 0
    last_mono = last_wall = None
    for index, (path, first_wall, first_mono) in enumerate(order_mcap(files)):
        if last_mono is not None and first_mono + offset < last_mono and first_wall != np.iinfo(np.int64).max:
            offset = last_mono + max(first_wall - last_wall, 0) - first_mono
        timeline.offsets_ns[str(path)] = offset
        report = ReadReport(str(path))
        timeline.reports.append(report)
        for window in read_windows(path, report, threads=1, ahead=1):
            latest = int(np.argmax(window.publish_times_ns))  # the first message of the latest time
            if last_mono is None or int(window.publish_times_ns[latest]) + offset > last_mono:
                last_mono, last_wall = int(window.publish_times_ns[latest]) + offset, int(window.log_times_ns[latest])
            yield index, offset, window


def iter_log_messages(paths, timeline: Timeline | None = None) -> Iterator[LogMessage]:
    """Every recoverable message of the MCAP logs in ``paths``, file after file in time order,
    with ``t_mono_ns`` on the continuous time line (see `iter_log_windows`)."""
    for index, offset, window in iter_log_windows(paths, timeline):
        for raw in window.messages():
            yield LogMessage(raw.channel.topic, raw.publish_time_ns + offset, raw.log_time_ns, raw.data,
                             raw.channel, index)


@dataclass
class LogArrays:
    """A whole log in memory: raw CAN records, IMU records and decoded JSON records per topic."""

    can: np.ndarray
    imu: np.ndarray
    json: dict[str, list[dict]]
    channel_metadata: dict[str, dict]
    timeline: Timeline
    clock_pairs: tuple[np.ndarray, np.ndarray]
    sensors: dict[str, np.ndarray] = field(default_factory=dict)
    """Packed sensor records per topic (contract 2 on: barometer, humidity, magnetometer)."""

    def json_table(self, topic: str):
        """One JSON topic, or a packed sensor topic, as a DataFrame (a column per field, a
        sub-array field as arrays; ``t_mono_ns`` on the continuous line)."""
        import pandas as pd

        if topic in self.sensors:
            records = self.sensors[topic]
            return pd.DataFrame({name: records[name] if records[name].ndim == 1 else list(records[name])
                                 for name in records.dtype.names if name != "reserved"})
        return pd.DataFrame.from_records(self.json.get(topic, []))


def read_frames(paths) -> LogArrays:
    """Everything of ``paths`` as arrays (contract dtypes, times on the continuous line [ns]).

    For the report and the fleet stage; the signals table comes from `read_logs`, which streams.
    """
    timeline = Timeline()
    can_parts, imu_parts = [], []
    sensor_parts: dict[str, list[np.ndarray]] = {}
    json_records: dict[str, list[dict]] = {}
    metadata: dict[str, dict] = {}
    mono_pairs, wall_pairs = [], []
    for _, offset, window in iter_log_windows(paths, timeline):
        mono_pairs.extend((window.publish_times_ns[window.batch_starts].astype(np.int64) + offset).tolist())
        wall_pairs.extend(window.log_times_ns[window.batch_starts].astype(np.int64).tolist())
        for channel_id in _first_seen(window.channel_ids):
            metadata.setdefault(window.channels[channel_id].topic, dict(window.channels[channel_id].metadata))
        for topic, parts in ((contract.CAN_FRAMES.name, can_parts), (contract.IMU.name, imu_parts)):
            records = window.topic_records(topic)
            if len(records):
                parts.append(contract.shift_times(records, offset))
        for topic in contract.SENSOR_TOPICS:
            records = window.topic_records(topic)
            if len(records):
                sensor_parts.setdefault(topic, []).append(contract.shift_times(records, offset))
        json_ids = [cid for cid, c in window.channels.items()
                    if c.message_encoding == contract.JSON_ENCODING and c.topic not in (contract.CAN_FRAMES.name,
                                                                                        contract.IMU.name)]
        rows = np.flatnonzero(np.isin(window.channel_ids, json_ids))
        for channel_id, data in zip(window.channel_ids[rows].tolist(), window.payloads(rows)):
            record = decode_json(data)
            if record is not None:
                if isinstance(record.get("t_mono_ns"), int):
                    record["t_mono_ns"] += offset
                json_records.setdefault(window.channels[channel_id].topic, []).append(record)
    for path in expand(paths):
        if not is_mcap(path):
            frames, _ = foreign.read_can_log(path)
            can_parts.append(frames)
    can = contract.join_records(can_parts, contract.CAN_FRAME_DTYPE)
    imu = contract.join_records(imu_parts, contract.IMU_SAMPLE_DTYPE)
    sensors = {topic: contract.join_records(parts, contract.SENSOR_TOPICS[topic].dtype)
               for topic, parts in sensor_parts.items()}
    return LogArrays(can, imu, json_records, metadata, timeline,
                     (np.array(mono_pairs, dtype=np.int64), np.array(wall_pairs, dtype=np.int64)), sensors)


def _first_seen(values: np.ndarray) -> list:
    """Distinct ``values`` in the order they first occur."""
    unique, first = np.unique(values, return_index=True)
    return unique[np.argsort(first)].tolist()


def decode_json(data: bytes) -> dict | None:
    try:
        record = json.loads(data)
    except (ValueError, UnicodeDecodeError):
        return None
    return record if isinstance(record, dict) else None
