"""The data contract between the truck and the workstation: every MCAP topic, once.

Both the logger and the analysis import this module; nobody re-types a topic name.
`docs/data-format.md` explains the choices. Summary:

* Time base. Every record carries ``t_mono_ns``: CLOCK_MONOTONIC of the logger in integer
  nanoseconds, which never jumps. MCAP ``publish_time`` is the same monotonic clock at the moment
  the message was handed to the writer; MCAP ``log_time`` is CLOCK_REALTIME (so Foxglove shows
  dates). ``/time/sync`` pairs both clocks (and GPS UTC once the receiver has a fix) once per
  second, so analysis maps monotonic time to wall-clock and GPS time, across clock jumps.
* High-rate topics (CAN frames, IMU, and since contract version 2 barometer, humidity and
  magnetometer) are *packed*: a message is a little-endian array of
  fixed-size records described by a NumPy dtype (``encoding = "haulprofile.packed"``), a few
  hundred records per message, each starting with its ``t_mono_ns``. This module is their only
  codec: `Topic.record_struct` packs one record (the logger), `unpack` and `shift_times` read
  and shift them (everyone else); `haulprofile.contract.reader` reads whole logs into them.
* Low-rate topics are JSON with a JSON Schema (``jsonschema``), readable in Foxglove as is.
  GPS fixes use the field names of ``foxglove.LocationFix`` and open on Foxglove's map.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from functools import cache

import numpy as np

PACKED_ENCODING = "haulprofile.packed"
"""Message and schema encoding of packed topics; the schema data is the JSON of the dtype."""

JSON_ENCODING = "json"
JSON_SCHEMA_ENCODING = "jsonschema"

CONTRACT_VERSION = 2
"""1: barometer, humidity and magnetometer as one JSON message per sample; 2: packed like CAN and
IMU (`SENSOR_TOPICS`). Readers read both; the logger writes the current one."""

# CAN record flags (bit field in ``flags``).
CAN_FLAG_EXTENDED = 0x01
CAN_FLAG_REMOTE = 0x02
CAN_FLAG_ERROR = 0x04
CAN_FLAG_TX = 0x08
"""Set on frames the logger transmitted itself (OBD-II and J1939 requests, CTS answers)."""
CAN_FLAG_HW_TIMESTAMP = 0x10
"""``t_mono_ns`` came from the kernel/hardware receive timestamp, not from user space."""
CAN_FLAG_FD = 0x20
"""A CAN FD frame: ``dlc`` is its data length (up to 64), of which the record keeps the first 8
bytes; the flag says so, so no decoder takes the frame for a complete classic one."""

CAN_FRAME_DTYPE = np.dtype(
    [
        ("t_mono_ns", "<u8"),
        ("arbitration_id", "<u4"),
        ("flags", "u1"),
        ("dlc", "u1"),
        ("channel", "u1"),
        ("reserved", "u1"),
        ("data", "u1", (8,)),
    ]
)
"""One classic CAN frame, 24 bytes. ``data`` beyond ``dlc`` is zero."""

IMU_SAMPLE_DTYPE = np.dtype(
    [
        ("t_mono_ns", "<u8"),
        ("accel_raw", "<i2", (3,)),
        ("gyro_raw", "<i2", (3,)),
    ]
)
"""One LSM9DS1 accelerometer+gyroscope FIFO sample, raw two's-complement counts (x, y, z).

Physical values: ``accel_raw * accel_scale_mps2_per_lsb`` and ``gyro_raw *
gyro_scale_radps_per_lsb`` from the channel metadata (set by the configured full scale).
"""


BAROMETER_SAMPLE_DTYPE = np.dtype(
    [
        ("t_mono_ns", "<u8"),
        ("pressure_pa", "<f8"),
        ("temperature_c", "<f8"),
        ("pressure_raw", "<i4"),
        ("temperature_raw", "<i2"),
        ("reserved", "<u2"),
    ]
)
"""One LPS25HB sample, 32 bytes: the driver's SI values (float64, as contract 1's JSON held them)
beside the raw registers (PRESS_OUT 24-bit signed, 4096 LSB/hPa; TEMP_OUT, 42.5 + raw/480 degC)."""

HUMIDITY_SAMPLE_DTYPE = np.dtype(
    [
        ("t_mono_ns", "<u8"),
        ("relative_humidity_pct", "<f8"),
        ("temperature_c", "<f8"),
        ("humidity_raw", "<i2"),
        ("temperature_raw", "<i2"),
        ("reserved", "<u4"),
    ]
)
"""One HTS221 sample, 32 bytes: factory calibration applied (float64), raw counts beside."""

MAGNETOMETER_SAMPLE_DTYPE = np.dtype(
    [
        ("t_mono_ns", "<u8"),
        ("magnetic_field_t", "<f8", (3,)),
        ("magnetic_raw", "<i2", (3,)),
        ("reserved", "<u2"),
    ]
)
"""One LSM9DS1 magnetometer sample, 40 bytes: field [T] (x, y, z) and raw counts."""

IMU_TEMPERATURE_SAMPLE_DTYPE = np.dtype(
    [
        ("t_mono_ns", "<u8"),
        ("temperature_c", "<f8"),
        ("temperature_raw", "<i2"),
        ("reserved", "<u2", (3,)),
    ]
)
"""One reading of the LSM9DS1's temperature sensor, 24 bytes: OUT_TEMP (0x15-0x16, two's complement,
16 LSB/degC, 0 at 25 degC) and its value. The die's temperature is what the accelerometer's bias
follows as the cab warms up (`IMU_TEMPERATURE`)."""
IMU_TEMPERATURE_LSB_PER_C = 16.0
IMU_TEMPERATURE_ZERO_C = 25.0
"""OUT_TEMP's scale and the temperature its 0 reads (LSM9DS1 datasheet, table 4: TSen, TODR)."""


def imu_temperature_counts(celsius):
    """OUT_TEMP's two's-complement count for a die temperature [degC]: rounded, within int16."""
    counts = np.round((np.asarray(celsius, dtype=float) - IMU_TEMPERATURE_ZERO_C) * IMU_TEMPERATURE_LSB_PER_C)
    return np.clip(counts, -32768, 32767).astype(np.int16)


def imu_temperature_c(counts):
    """The die temperature [degC] an OUT_TEMP count reads."""
    return IMU_TEMPERATURE_ZERO_C + np.asarray(counts) / IMU_TEMPERATURE_LSB_PER_C


@dataclass(frozen=True)
class Topic:
    """One MCAP channel: name, schema and what a reader needs to know about it."""

    name: str
    schema_name: str
    encoding: str
    rate_hz: float
    description: str
    dtype: np.dtype | None = None
    json_schema: dict = field(default_factory=dict)
    units: dict = field(default_factory=dict)

    @property
    def schema_encoding(self) -> str:
        return PACKED_ENCODING if self.encoding == PACKED_ENCODING else JSON_SCHEMA_ENCODING

    def schema_data(self) -> bytes:
        """The bytes stored in the MCAP schema record."""
        if self.encoding == PACKED_ENCODING:
            return json.dumps({"numpy_dtype": dtype_to_json(self.dtype), "units": self.units}).encode()
        return json.dumps(self.json_schema).encode()


def dtype_to_json(dtype: np.dtype) -> list:
    """A dtype as JSON-able ``[[name, format, shape], ...]`` (round-trips through `dtype_from_json`)."""
    return [[name, dtype.fields[name][0].base.str, list(dtype.fields[name][0].shape)] for name in dtype.names]


def dtype_from_json(spec: list) -> np.dtype:
    return np.dtype([(name, fmt, tuple(shape)) if shape else (name, fmt) for name, fmt, shape in spec])


def _obj(properties: dict, required: list[str] | None = None, title: str = "") -> dict:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "type": "object",
        "properties": properties,
        "required": required if required is not None else list(properties),
    }


_NUM = {"type": "number"}
_INT = {"type": "integer"}
_NULLABLE_NUM = {"type": ["number", "null"]}
_T_MONO = {"t_mono_ns": {"type": "integer", "description": "CLOCK_MONOTONIC of the logger [ns]"}}
_FOXGLOVE_TIME = {
    "type": "object",
    "properties": {"sec": _INT, "nsec": _INT},
    "required": ["sec", "nsec"],
}

CAN_FRAMES = Topic(
    name="/can/frames",
    schema_name="haulprofile.CanFrames",
    encoding=PACKED_ENCODING,
    rate_hz=1500.0,
    description="Every CAN frame received or sent, raw, batched (one message per ~0.2 s or 512 frames).",
    dtype=CAN_FRAME_DTYPE,
    units={"t_mono_ns": "ns"},
)

IMU = Topic(
    name="/imu",
    schema_name="haulprofile.ImuSamples",
    encoding=PACKED_ENCODING,
    rate_hz=952.0,
    description="LSM9DS1 accelerometer and gyroscope FIFO samples, raw counts, batched per FIFO read.",
    dtype=IMU_SAMPLE_DTYPE,
    units={"t_mono_ns": "ns", "accel_raw": "LSB", "gyro_raw": "LSB"},
)

BAROMETER_V1 = Topic(
    name="/barometer",
    schema_name="haulprofile.Barometer",
    encoding=JSON_ENCODING,
    rate_hz=25.0,
    description="LPS25HB pressure and temperature; raw register counts kept beside SI values.",
    json_schema=_obj(
        {
            **_T_MONO,
            "pressure_pa": _NUM,
            "temperature_c": _NUM,
            "pressure_raw": {"type": "integer", "description": "PRESS_OUT 24-bit, 4096 LSB/hPa"},
            "temperature_raw": {"type": "integer", "description": "TEMP_OUT 16-bit, 42.5 + raw/480 degC"},
        },
        title="haulprofile.Barometer",
    ),
    units={"pressure_pa": "Pa", "temperature_c": "degC"},
)

HUMIDITY_V1 = Topic(
    name="/humidity",
    schema_name="haulprofile.Humidity",
    encoding=JSON_ENCODING,
    rate_hz=12.5,
    description="HTS221 relative humidity and temperature (factory calibration applied), raw counts kept.",
    json_schema=_obj(
        {
            **_T_MONO,
            "relative_humidity_pct": _NUM,
            "temperature_c": _NUM,
            "humidity_raw": _INT,
            "temperature_raw": _INT,
        },
        title="haulprofile.Humidity",
    ),
    units={"relative_humidity_pct": "%", "temperature_c": "degC"},
)

MAGNETOMETER_V1 = Topic(
    name="/magnetometer",
    schema_name="haulprofile.Magnetometer",
    encoding=JSON_ENCODING,
    rate_hz=10.0,
    description="LSM9DS1 magnetometer, raw counts and tesla.",
    json_schema=_obj(
        {
            **_T_MONO,
            "magnetic_field_t": {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3},
            "magnetic_raw": {"type": "array", "items": _INT, "minItems": 3, "maxItems": 3},
        },
        title="haulprofile.Magnetometer",
    ),
    units={"magnetic_field_t": "T"},
)

"""`BAROMETER_V1`, `HUMIDITY_V1`, `MAGNETOMETER_V1`: contract version 1's JSON form of these topics
(one message per sample), read in old logs, written only by tests that make such logs."""

def _packed_sensor(name: str, schema_name: str, rate_hz: float, description: str, dtype: np.dtype) -> Topic:
    """A sensor topic packed since contract 2; units: those of its contract-1 JSON form, LSB for raw counts."""
    units = {"t_mono_ns": "ns", **{field: "LSB" for field in dtype.names if field.endswith("_raw")}}
    return Topic(name=name, schema_name=schema_name, encoding=PACKED_ENCODING, rate_hz=rate_hz,
                 description=description, dtype=dtype, units=units | _V1_UNITS[name])


_V1_UNITS = {t.name: t.units for t in (BAROMETER_V1, HUMIDITY_V1, MAGNETOMETER_V1)}

BAROMETER = _packed_sensor("/barometer", "haulprofile.BarometerSamples", 25.0,
                           "LPS25HB pressure and temperature, SI values and raw registers, batched per FIFO read.",
                           BAROMETER_SAMPLE_DTYPE)
HUMIDITY = _packed_sensor("/humidity", "haulprofile.HumiditySamples", 12.5,
                          "HTS221 relative humidity and temperature (factory calibration applied) and raw counts, "
                          "batched.", HUMIDITY_SAMPLE_DTYPE)
MAGNETOMETER = _packed_sensor("/magnetometer", "haulprofile.MagnetometerSamples", 10.0,
                              "LSM9DS1 magnetometer, tesla and raw counts, batched.", MAGNETOMETER_SAMPLE_DTYPE)

IMU_TEMPERATURE = Topic(
    name="/imu/temperature",
    schema_name="haulprofile.ImuTemperatureSamples",
    encoding=PACKED_ENCODING,
    rate_hz=1.0,
    description="LSM9DS1 die temperature (OUT_TEMP), degC and raw counts, once a second, batched.",
    dtype=IMU_TEMPERATURE_SAMPLE_DTYPE,
    json_schema=_obj({**_T_MONO, "temperature_c": _NUM, "temperature_raw": _INT}, title="haulprofile.ImuTemperature"),
    units={"t_mono_ns": "ns", "temperature_c": "degC", "temperature_raw": "LSB"},
)
"""Written since December 2026 (packed only; ``json_schema`` is its records' form in a viewer copy;
older logs have no such channel). An
accelerometer's bias moves with its temperature (a MEMS part: about 0.5 mg/K), so the warm-up of a
cab that the estimator could only follow as a rate in time is logged as what drives it."""

SENSOR_TOPICS: dict[str, Topic] = {t.name: t for t in (BAROMETER, HUMIDITY, MAGNETOMETER, IMU_TEMPERATURE)}
"""Topics packed since contract version 2 (the IMU's temperature since it was added); a channel of
theirs is packed only if its message encoding says so (else it is contract 1's JSON)."""

GPS_FIX = Topic(
    name="/gps/fix",
    schema_name="foxglove.LocationFix",
    encoding=JSON_ENCODING,
    rate_hz=10.0,
    description=(
        "Position fix. Fields of foxglove.LocationFix (timestamp, frame_id, latitude, longitude, "
        "altitude, position_covariance, position_covariance_type) plus haulprofile extras."
    ),
    json_schema=_obj(
        {
            "timestamp": _FOXGLOVE_TIME,
            "frame_id": {"type": "string"},
            "latitude": _NUM,
            "longitude": _NUM,
            "altitude": _NUM,
            "position_covariance": {"type": "array", "items": _NUM, "minItems": 9, "maxItems": 9},
            "position_covariance_type": {"type": "integer", "enum": [0, 1, 2, 3]},
            **_T_MONO,
            "gps_time_utc_ns": {"type": ["integer", "null"], "description": "receiver UTC time of the fix [ns since epoch]"},
            "speed_mps": _NULLABLE_NUM,
            "course_deg": _NULLABLE_NUM,
            "h_acc_m": _NULLABLE_NUM,
            "v_acc_m": _NULLABLE_NUM,
            "fix_quality": _INT,
            "satellites": _INT,
            "hdop": _NULLABLE_NUM,
            "vdop": _NULLABLE_NUM,
        },
        required=["timestamp", "frame_id", "latitude", "longitude", "altitude", "position_covariance",
                  "position_covariance_type", "t_mono_ns"],
        title="foxglove.LocationFix",
    ),
    units={"latitude": "deg", "longitude": "deg", "altitude": "m", "h_acc_m": "m", "v_acc_m": "m",
           "speed_mps": "m/s"},
)
"""``timestamp`` is the wall-clock (GPS UTC when known) of the fix; covariance diagonal is
(σ_east², σ_north², v_acc²) in m² (GST's sigmas; h_acc² on both axes where only h_acc is known)
with type 2 (diagonal known) when accuracies are known."""

GPS_NMEA = Topic(
    name="/gps/nmea",
    schema_name="haulprofile.NmeaSentences",
    encoding=JSON_ENCODING,
    rate_hz=1.0,
    description="Raw NMEA sentences as received (checksum-valid or not), batched once per second.",
    json_schema=_obj(
        {**_T_MONO, "sentences": {"type": "array", "items": {"type": "string"}},
         "t_mono_ns_each": {"type": "array", "items": _INT}},
        title="haulprofile.NmeaSentences",
    ),
)

TIME_SYNC = Topic(
    name="/time/sync",
    schema_name="haulprofile.TimeSync",
    encoding=JSON_ENCODING,
    rate_hz=1.0,
    description="Pairs of the logger's clocks: monotonic, realtime and (with a GPS fix) GPS UTC.",
    json_schema=_obj(
        {**_T_MONO, "t_realtime_ns": _INT, "gps_time_utc_ns": {"type": ["integer", "null"]}},
        title="haulprofile.TimeSync",
    ),
)

DIAGNOSTICS = Topic(
    name="/diagnostics",
    schema_name="haulprofile.Diagnostics",
    encoding=JSON_ENCODING,
    rate_hz=1.0,
    description="Per-source health once per second: rates, drops, errors, queue depth, disk.",
    json_schema=_obj(
        {
            **_T_MONO,
            "sources": {"type": "object", "additionalProperties": {"type": "object"}},
            "queue_depth": _INT,
            "disk_free_bytes": _INT,
            "messages": {"type": "array", "items": {"type": "string"}},
        },
        required=["t_mono_ns", "sources"],
        title="haulprofile.Diagnostics",
    ),
)

PRIVACY_ZONE = Topic(
    name="/privacy/zone",
    schema_name="haulprofile.PrivacyZone",
    encoding=JSON_ENCODING,
    rate_hz=0.0,
    description=("Written instead of /gps/fix where a privacy zone begins or ends: no position, no NMEA "
                 "and no GPS time between an 'entered' and the next 'left'."),
    json_schema=_obj(
        {**_T_MONO,
         "event": {"type": "string", "enum": ["entered", "left"]},
         "source": {"type": "string", "enum": ["logger", "redact"],
                    "description": "cut by the logger before writing, or later by analyze redact"}},
        title="haulprofile.PrivacyZone",
    ),
)
"""``t_mono_ns`` is the first epoch inside (``entered``) or the first fix outside again (``left``).
The zone is not named: its name ("home") would say what the stop was."""

PRIVACY_EVENTS = ("entered", "left")

TOPICS: dict[str, Topic] = {
    t.name: t
    for t in (CAN_FRAMES, IMU, BAROMETER, HUMIDITY, MAGNETOMETER, IMU_TEMPERATURE, GPS_FIX, GPS_NMEA, TIME_SYNC,
              DIAGNOSTICS, PRIVACY_ZONE)
}

PROFILE = "haulprofile"
"""MCAP header profile of files written by haulprofile."""


TIME_STRUCT = struct.Struct("<Q")
"""The ``t_mono_ns`` that opens every packed record (a prefix packer for records whose rest is raw
little-endian sensor words, and the reader of a payload's first time)."""


def _struct_format(dtype: np.dtype) -> str:
    """`struct` format of a packed dtype (byte arrays as ``Ns``, other sub-arrays repeated)."""
    codes = {"u1": "B", "i1": "b", "u2": "H", "i2": "h", "u4": "I", "i4": "i", "u8": "Q", "i8": "q",
             "f4": "f", "f8": "d"}
    out = "<"
    for name in dtype.names:
        base, shape = dtype.fields[name][0].base, dtype.fields[name][0].shape
        count = int(np.prod(shape)) if shape else 1
        code = codes[base.str.lstrip("<>|=")]
        out += f"{count}s" if shape and code == "B" else f"{count if count > 1 else ''}{code}"
    return out


@cache
def _record_struct(dtype: np.dtype) -> struct.Struct:
    packer = struct.Struct(_struct_format(dtype))
    if packer.size != dtype.itemsize:
        raise ValueError(f"dtype {dtype} has padding; a packed record must not")
    return packer


def _check_packed(topic: Topic) -> None:
    if topic.dtype.names[0] != "t_mono_ns" or topic.dtype.fields["t_mono_ns"][0] != np.dtype("<u8") or \
            topic.dtype.fields["t_mono_ns"][1] != 0:
        raise ValueError(f"{topic.name}: a packed record starts with its t_mono_ns (<u8)")
    _record_struct(topic.dtype)


for _topic in TOPICS.values():
    if _topic.encoding == PACKED_ENCODING:
        _check_packed(_topic)


def record_struct(topic: Topic) -> struct.Struct:
    """`struct.Struct` of one record of a packed topic, derived from its dtype (the one layout):
    ``record_struct(CAN_FRAMES).pack(t_mono_ns, arbitration_id, flags, dlc, channel, 0, data)``."""
    return _record_struct(topic.dtype)


def pack(topic: Topic, records: np.ndarray) -> bytes:
    """Serialise a record array for a packed topic."""
    if records.dtype != topic.dtype:
        records = records.astype(topic.dtype)
    return np.ascontiguousarray(records).tobytes()


def first_time_ns(payload) -> int:
    """``t_mono_ns`` of the first record of a packed payload."""
    return TIME_STRUCT.unpack_from(payload, 0)[0]


def unpack(topic: Topic, payload, shift_ns: int = 0, whole_only: bool = False) -> np.ndarray:
    """Record array of a packed message, times shifted by ``shift_ns`` (then a copy; else a
    read-only view on ``payload``). A payload that is not a whole number of records is an error,
    or with ``whole_only`` (a damaged message) keeps its whole records."""
    size = topic.dtype.itemsize
    if len(payload) % size and not whole_only:
        raise ValueError(f"{topic.name}: message of {len(payload)} bytes is not a whole number of "
                         f"{size}-byte records")
    records = np.frombuffer(payload, dtype=topic.dtype, count=len(payload) // size)
    if shift_ns:
        records = records.copy()
        shift_times(records, shift_ns)
    return records


def shift_times(records: np.ndarray, shift_ns: int) -> np.ndarray:
    """Move the ``t_mono_ns`` of packed records (writable array, in place) by ``shift_ns`` [ns];
    the one place a packed topic's time shift (onto a continuous time line) happens."""
    if shift_ns and len(records):
        records["t_mono_ns"] += np.uint64(shift_ns % (1 << 64))
    return records


def join_records(parts: list[np.ndarray], dtype: np.dtype) -> np.ndarray:
    """Packed records of several arrays in one, copied as bytes (NumPy copies a structured dtype
    field by field, some twenty times slower)."""
    if not parts:
        return np.zeros(0, dtype)
    if len(parts) == 1:
        return parts[0]
    return np.concatenate([np.ascontiguousarray(p, dtype).view(np.uint8) for p in parts]).view(dtype)


def encode_json(record: dict) -> bytes:
    return json.dumps(record, separators=(",", ":"), allow_nan=False).encode()


def location_fix(
    t_mono_ns: int,
    wall_time_ns: int,
    latitude_deg: float,
    longitude_deg: float,
    altitude_m: float,
    h_acc_m: float | None,
    v_acc_m: float | None,
    east_north_sigma_m: tuple[float, float] | None = None,
    **extras,
) -> dict:
    """A ``foxglove.LocationFix``-compatible record with the accuracy as covariance diagonal (ENU).

    ``east_north_sigma_m`` (a receiver's per-axis standard deviations, NMEA GST) sets the east and
    north variances; without it both get ``h_acc_m``².
    """
    if east_north_sigma_m is not None and v_acc_m is not None:
        east, north = east_north_sigma_m
        cov = [east**2, 0.0, 0.0, 0.0, north**2, 0.0, 0.0, 0.0, v_acc_m**2]
        cov_type = 2
    elif h_acc_m is not None and v_acc_m is not None:
        cov = [h_acc_m**2, 0.0, 0.0, 0.0, h_acc_m**2, 0.0, 0.0, 0.0, v_acc_m**2]
        cov_type = 2
    else:
        cov, cov_type = [0.0] * 9, 0
    return {
        "timestamp": {"sec": wall_time_ns // 1_000_000_000, "nsec": wall_time_ns % 1_000_000_000},
        "frame_id": "gps",
        "latitude": latitude_deg,
        "longitude": longitude_deg,
        "altitude": altitude_m,
        "position_covariance": cov,
        "position_covariance_type": cov_type,
        "t_mono_ns": int(t_mono_ns),
        "h_acc_m": h_acc_m,
        "v_acc_m": v_acc_m,
        **extras,
    }
