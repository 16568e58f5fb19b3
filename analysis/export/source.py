"""One input log as what every export writes: its raw CAN frames, IMU samples in SI units, JSON
records, and the one clock offset that puts its times on the wall clock.

Exported times are ``t_mono_ns + wall_offset_ns``: a single offset per log (the median of GPS UTC,
else realtime, else MCAP ``log_time``, minus the monotonic time), floored to whole seconds, so
intervals stay exact and every bin of a rate that divides 1 Hz holds the same frames after a
re-import. Private exports (`private`) tell no time of day: an MCAP log keeps the logger's
monotonic time (since its boot), another logger's log with wall-clock times counts from the whole
second it began; they drop the J1939 PGNs that carry position and date (as the logger does under
privacy) and every position topic.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from haulprofile import contract
from haulprofile.contract import CAN_FLAG_EXTENDED

from ..ingest import foreign
from ..ingest.logs import decode_json, is_mcap, iter_log_windows

PRIVATE_PGNS = (65267, 65254)
"""J1939 Vehicle Position and Time/Date: what a telematics unit broadcasts about where and when
(`logger.config.PrivacySection.drop_can_pgns`)."""
POSITION_TOPICS = (contract.GPS_FIX.name, contract.GPS_NMEA.name, contract.TIME_SYNC.name)
"""JSON topics that tell where or when; left out of private exports."""
NS_PER_S = 1_000_000_000


@dataclass
class LogContent:
    """What one log holds for an export (times on the log's own monotonic clock [ns])."""

    path: Path
    frames: np.ndarray
    """CAN records, `contract.CAN_FRAME_DTYPE`."""
    wall_offset_ns: int
    """Added to ``t_mono_ns`` for exported times [ns]; a whole number of seconds."""
    imu_time_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    accel_mps2: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """IMU acceleration, sensor axes [m/s²]."""
    gyro_radps: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """IMU angular rate, sensor axes [rad/s]."""
    json: dict[str, list[dict]] = field(default_factory=dict)
    """JSON records per topic, as logged."""
    ingest_shift_ns: int = 0
    """What the ingest adds to these times (a foreign log goes on its own wall clock) [ns]."""

    def times_ns(self, t_mono_ns) -> np.ndarray:
        """Exported times of monotonic times [ns]."""
        return np.asarray(t_mono_ns, np.int64) + np.int64(self.wall_offset_ns)


def pgn_of(frames: np.ndarray) -> np.ndarray:
    """J1939 PGN of extended-id frames (PDU1 without the destination), -1 for standard ids."""
    ident = frames["arbitration_id"].astype(np.int64)
    pf = (ident >> 16) & 0xFF
    pgn = (ident >> 8) & 0x3FF00
    pgn = np.where(pf >= 240, pgn | ((ident >> 8) & 0xFF), pgn)
    return np.where(frames["flags"] & CAN_FLAG_EXTENDED != 0, pgn, -1)


def without_private_frames(frames: np.ndarray) -> np.ndarray:
    """The frames but those of `PRIVATE_PGNS`."""
    return frames[~np.isin(pgn_of(frames), PRIVATE_PGNS)]


def clock_offset_ns(mono_ns, wall_ns) -> int:
    """Median of wall − monotonic over the pairs, floored to whole seconds [ns] (0 without pairs)."""
    mono, wall = np.asarray(mono_ns, np.int64), np.asarray(wall_ns, np.int64)
    if len(mono) == 0:
        return 0
    median = int(np.median(wall - mono))
    return median - median % NS_PER_S


def _mcap_offset(json_records: dict[str, list[dict]], clock_pairs) -> int:
    sync = json_records.get(contract.TIME_SYNC.name, [])
    for key in ("gps_time_utc_ns", "t_realtime_ns"):
        pairs = [(r["t_mono_ns"], r[key]) for r in sync
                 if isinstance(r.get(key), int) and isinstance(r.get("t_mono_ns"), int)]
        if pairs:
            return clock_offset_ns(*zip(*pairs))
    return clock_offset_ns(*clock_pairs)


def json_records(window, topics) -> dict[str, list[dict]]:
    """The JSON records of a window's channels of ``topics`` (None: every JSON topic), per topic."""
    wanted = {cid: c.topic for cid, c in window.channels.items() if c.message_encoding == contract.JSON_ENCODING
              and (topics is None or c.topic in topics)}
    records: dict[str, list[dict]] = {}
    rows = np.flatnonzero(np.isin(window.channel_ids, list(wanted)))
    for cid, data in zip(window.channel_ids[rows].tolist(), window.payloads(rows)):
        record = decode_json(data)
        if record is not None:
            records.setdefault(wanted[cid], []).append(record)
    return records


def sensor_records(window) -> dict[str, list[dict]]:
    """The packed sensor samples of a window (contract 2) as the records of their contract-1 JSON
    form, so a viewer copy shows the barometer, humidity and magnetometer of either version."""
    records: dict[str, list[dict]] = {}
    for topic in contract.SENSOR_TOPICS:
        rows = window.topic_records(topic)
        if len(rows):
            fields = [f for f in rows.dtype.names if f != "reserved"]
            records[topic] = [{f: row[f].tolist() for f in fields} for row in rows]
    return records


class Clock:
    """What a log's clock offset is taken from, gathered a window at a time: its time-sync records
    and the (publish time, log time) of its messages."""

    def __init__(self):
        self.sync: list[dict] = []
        self.mono: list[int] = []
        self.wall: list[int] = []

    def add(self, window) -> None:
        self.mono.extend(window.publish_times_ns[window.batch_starts].astype(np.int64).tolist())
        self.wall.extend(window.log_times_ns[window.batch_starts].astype(np.int64).tolist())
        self.sync.extend(json_records(window, {contract.TIME_SYNC.name}).get(contract.TIME_SYNC.name, []))

    def offset_ns(self) -> int:
        return _mcap_offset({contract.TIME_SYNC.name: self.sync},
                            (np.array(self.mono, np.int64), np.array(self.wall, np.int64)))


def _read_mcap(path: Path, everything: bool):
    """CAN records, IMU records and JSON records (with ``everything``), IMU channel metadata and the
    clock offset [ns] of one MCAP log."""
    can_parts, imu_parts, records, imu_meta, clock = [], [], {}, {}, Clock()
    for _, _, window in iter_log_windows([path]):
        clock.add(window)
        can_parts.append(window.topic_records(contract.CAN_FRAMES.name))
        if everything:
            imu_parts.append(window.topic_records(contract.IMU.name))
            for topic, found in (json_records(window, None) | sensor_records(window)).items():
                records.setdefault(topic, []).extend(found)
        for channel in window.channels.values():
            if channel.topic == contract.IMU.name and not imu_meta:
                imu_meta = dict(channel.metadata)
    can = contract.join_records([p for p in can_parts if len(p)], contract.CAN_FRAME_DTYPE)
    imu = contract.join_records([p for p in imu_parts if len(p)], contract.IMU_SAMPLE_DTYPE)
    return can, imu, records, imu_meta, clock.offset_ns()


def load(path: Path, private: bool = False, everything: bool = True) -> LogContent:
    """The content of one MCAP log or foreign CAN log for export (without ``everything``: the CAN
    frames only, what the bus-log formats hold)."""
    path = Path(path)
    if is_mcap(path):
        can, imu, records, meta, offset = _read_mcap(path, everything)
        offset = 0 if private else offset
        content = LogContent(path, can, offset, json=records if everything else {})
        if len(imu) and "accel_scale_mps2_per_lsb" in meta:
            content.imu_time_ns = imu["t_mono_ns"].astype(np.int64)
            content.accel_mps2 = imu["accel_raw"] * float(meta["accel_scale_mps2_per_lsb"])
            if "gyro_scale_radps_per_lsb" in meta:
                content.gyro_radps = imu["gyro_raw"] * float(meta["gyro_scale_radps_per_lsb"])
            else:
                content.gyro_radps = np.full((len(imu), 3), np.nan)
    else:
        frames, (mono, wall) = foreign.read_can_log(path)
        offset = clock_offset_ns(mono, wall)
        if private and len(wall):  # times since the whole second the recording began
            offset = -clock_offset_ns([0], mono[:1] + offset)
        content = LogContent(path, frames, offset, ingest_shift_ns=int(wall[0] - mono[0]) if len(wall) else 0)
    if private:
        content.frames = without_private_frames(content.frames)
        content.json = {topic: records for topic, records in content.json.items() if topic not in POSITION_TOPICS}
    return content
