"""A viewer-ready MCAP copy: every channel JSON with a JSON Schema (message encoding ``json``,
schema encoding ``jsonschema``), so Foxglove, the ``mcap`` tools and any JSON reader decode it
without haulprofile.

* ``/signals``: one message per row of the decoded signals table, a number per column (null where
  missing), each column's unit in its schema (``unit``, and in ``description``): plottable by name
  (``/signals.engine_speed_rpm``).
* ``/imu``: one message per sample, ``linear_acceleration`` [m/s²] and ``angular_velocity`` [rad/s]
  (sensor axes; the field names of ROS ``sensor_msgs/Imu``).
* ``/gps/fix``: ``foxglove.LocationFix`` as logged (only fixes with a position): the route on the map.
* ``/can/frames``: one message per frame (``id``, ``extended``, ``remote``, ``tx``, ``dlc``,
  ``channel``, ``data`` as byte values), so ``/can/frames{id==217056256}.data[3]`` plots a byte.
* the other JSON topics (barometer, humidity, …) as logged, with their contract schemas.

Message ``log_time`` and ``publish_time`` are the exported time (`source.LogContent.times_ns`).
"""

from __future__ import annotations

import json

import msgspec
import numpy as np

from haulprofile import contract
from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE, CAN_FLAG_TX

from ..units import unit_of
from .source import NS_PER_S, LogContent

PROFILE = ""
LIBRARY = "haulprofile-export"
SCHEMA_DRAFT = "https://json-schema.org/draft/2020-12/schema"
_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
         "required": ["sec", "nsec"]}
_VECTOR = {"type": "object", "properties": {a: {"type": ["number", "null"]} for a in "xyz"}, "required": list("xyz")}
IMU_SCHEMA = {
    "$schema": SCHEMA_DRAFT, "title": "haulprofile.Imu", "type": "object",
    "properties": {
        "timestamp": _TIME, "frame_id": {"type": "string"},
        "linear_acceleration": {**_VECTOR, "description": "acceleration, sensor axes [m/s²]", "unit": "m/s²"},
        "angular_velocity": {**_VECTOR, "description": "angular rate, sensor axes [rad/s]", "unit": "rad/s"},
    },
    "required": ["timestamp", "frame_id", "linear_acceleration", "angular_velocity"],
}
CAN_SCHEMA = {
    "$schema": SCHEMA_DRAFT, "title": "haulprofile.CanFrame", "type": "object",
    "properties": {
        "timestamp": _TIME, "id": {"type": "integer", "description": "11- or 29-bit identifier"},
        "extended": {"type": "boolean"}, "remote": {"type": "boolean"}, "error": {"type": "boolean"},
        "tx": {"type": "boolean", "description": "sent by the logger"},
        "dlc": {"type": "integer", "minimum": 0, "maximum": 8}, "channel": {"type": "integer"},
        "data": {"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 255}, "maxItems": 8},
    },
    "required": ["timestamp", "id", "extended", "remote", "error", "tx", "dlc", "channel", "data"],
}
SKIPPED_COLUMNS = ("time_s", "wall_time_ns")
"""Columns the message times already carry."""


def signals_schema(table) -> dict:
    """JSON Schema of a ``/signals`` message of ``table``: a nullable number per column, with its unit."""
    known = table.attrs.get("units", {})
    properties = {"timestamp": _TIME}
    for column in table.columns:
        if column in SKIPPED_COLUMNS:
            continue
        unit = unit_of(str(column), known)
        properties[str(column)] = {"type": ["number", "null"], "unit": unit,
                                   "description": f"{column} [{unit}]" if unit else str(column)}
    return {"$schema": SCHEMA_DRAFT, "title": "haulprofile.Signals", "type": "object", "properties": properties,
            "required": ["timestamp"]}


def _stamp(time_ns: int) -> dict:
    return {"sec": time_ns // NS_PER_S, "nsec": time_ns % NS_PER_S}


class _Out:
    """An mcap writer with one JSON channel per topic."""

    def __init__(self, stream):
        from mcap.writer import CompressionType, Writer

        self.writer = Writer(stream, compression=CompressionType.ZSTD)
        self.writer.start(profile=PROFILE, library=LIBRARY)
        self.channels: dict[str, int] = {}
        self.encode = msgspec.json.Encoder().encode

    def channel(self, topic: str, schema: dict) -> int:
        if topic not in self.channels:
            schema_id = self.writer.register_schema(schema.get("title") or topic.strip("/"), "jsonschema",
                                                    json.dumps(schema).encode())
            self.channels[topic] = self.writer.register_channel(topic, "json", schema_id)
        return self.channels[topic]

    def add(self, channel_id: int, time_ns: int, record) -> None:
        self.writer.add_message(channel_id, log_time=time_ns, data=self.encode(record), publish_time=time_ns)

    def finish(self) -> None:
        self.writer.finish()


def _events(content: LogContent, table, row_mono_ns):
    """(exported time [ns], topic, schema, record) of everything, each topic in time order."""
    if table is not None and len(table):
        schema = signals_schema(table)
        columns = [c for c in schema["properties"] if c != "timestamp"]
        values = table[columns].astype(float).to_numpy()
        for t, row in zip(content.times_ns(row_mono_ns).tolist(), values.tolist()):
            yield t, "/signals", schema, {"timestamp": _stamp(t), **dict(zip(columns, row))}
    for t, accel, gyro in zip(content.times_ns(content.imu_time_ns).tolist(), content.accel_mps2.tolist(),
                              content.gyro_radps.tolist()):
        yield t, contract.IMU.name, IMU_SCHEMA, {
            "timestamp": _stamp(t), "frame_id": "imu",
            "linear_acceleration": dict(zip("xyz", accel)), "angular_velocity": dict(zip("xyz", gyro))}
    frames = content.frames
    for t, ident, flag, dlc, channel, data in zip(
            content.times_ns(frames["t_mono_ns"]).tolist(), frames["arbitration_id"].tolist(),
            frames["flags"].tolist(), frames["dlc"].tolist(), frames["channel"].tolist(), frames["data"].tolist()):
        remote = bool(flag & CAN_FLAG_REMOTE)
        yield t, contract.CAN_FRAMES.name, CAN_SCHEMA, {
            "timestamp": _stamp(t), "id": ident, "extended": bool(flag & CAN_FLAG_EXTENDED), "remote": remote,
            "error": bool(flag & CAN_FLAG_ERROR), "tx": bool(flag & CAN_FLAG_TX), "dlc": dlc, "channel": channel,
            "data": [] if remote else data[:dlc]}
    json_forms = {t.name: t for t in (contract.BAROMETER_V1, contract.HUMIDITY_V1, contract.MAGNETOMETER_V1)}
    for topic, records in content.json.items():
        spec = json_forms.get(topic, contract.TOPICS.get(topic))
        if spec is None or not spec.json_schema:
            continue
        for record in records:
            if not isinstance(record.get("t_mono_ns"), int):
                continue
            if topic == contract.GPS_FIX.name and not _has_position(record):
                continue
            yield int(content.times_ns([record["t_mono_ns"]])[0]), topic, spec.json_schema, record


def _has_position(record: dict) -> bool:
    return all(isinstance(record.get(k), (int, float)) and np.isfinite(record[k]) for k in ("latitude", "longitude"))


def write(content: LogContent, stream, table=None, row_mono_ns=None) -> dict[str, int]:
    """Write the viewer copy of ``content`` (and ``table``, rows at ``row_mono_ns`` [ns]) to a binary
    stream; returns the messages written per topic."""
    out = _Out(stream)
    counts: dict[str, int] = {}
    for t, topic, schema, record in _events(content, table, row_mono_ns):
        out.add(out.channel(topic, schema), t, record)
        counts[topic] = counts.get(topic, 0) + 1
    out.finish()
    return counts
