"""A virtual drive's sensor streams as an MCAP log in the data contract (`haulprofile.contract`).

What the logger would have written in the truck: raw J1939 frames (EEC1, EEC2, EEC3, ETC2, CCVS1,
LFE, CVW broadcasts; EC1 as a BAM transport session every 5 s) batched into ``/can/frames``, raw IMU
counts batched per 0.1 s, LPS25HB and HTS221 readings with their raw counts, GPS fixes as
``foxglove.LocationFix`` and ``/time/sync`` once per second. Monotonic time is the simulated time
plus a boot offset; wall-clock time is the scenario's start plus the simulated time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from haulprofile import contract
from haulprofile.contract import j1939
from haulprofile.contract.writer import TopicWriter

from . import sensors as sensor_models

BOOT_OFFSET_NS = 4_217_503_000_000
"""Monotonic clock at the start of the drive [ns] (the Pi booted ~70 minutes earlier)."""
GPS_LATENCY_NS = 80_000_000
"""A fix reaches the logger this long after its epoch [ns]."""
EC1_PERIOD_S = 5.0
BAM_PACKET_GAP_S = 0.05
MAX_FRAMES_PER_MESSAGE = 512
MAX_BATCH_S = 0.2
IMU_BATCH_S = 0.1
BAROMETER_BATCH_S = 0.32
"""The logger reads the LPS25HB's FIFO every 8 samples at 25 Hz: one message per read."""
HUMIDITY_BATCH_S = 1.0
IMU_TEMPERATURE_BATCH_S = 10.0
"""The logger's `/imu/temperature` messages hold ten readings."""
IMU_TEMPERATURE_STEP_S = 1.0
"""The logger reads the IMU's OUT_TEMP once a second (the LSM9DS1 driver's ``TEMP_INTERVAL_S``)."""

ENGINE_ADDRESS = 0x00
TRANSMISSION_ADDRESS = 0x03
BRAKES_ADDRESS = 0x0B

_CAN_BROADCASTS = (
    # stream, pgn, source, priority, {spn name: column}
    ("engine", j1939.PGN_EEC1, ENGINE_ADDRESS, 3,
     {"driver_demand_torque_pct": "driver_demand_torque_pct", "actual_engine_torque_pct": "actual_engine_torque_pct",
      "engine_speed_rpm": "engine_speed_rpm"}),
    ("pedals", j1939.PGN_EEC2, ENGINE_ADDRESS, 3, {"accelerator_pedal_pct": "accelerator_pedal_pct"}),
    ("engine_losses", j1939.PGN_EEC3, ENGINE_ADDRESS, 6,
     {"nominal_friction_torque_pct": "nominal_friction_torque_pct",
      "parasitic_loss_torque_pct": "parasitic_loss_torque_pct"}),
    ("transmission", j1939.PGN_ETC2, TRANSMISSION_ADDRESS, 6,
     {"current_gear": "current_gear", "selected_gear": "current_gear"}),
    ("wheel_speed", j1939.PGN_CCVS1, ENGINE_ADDRESS, 6,
     {"wheel_speed_kmh": "wheel_speed_kmh", "brake_switch": "brake_switch"}),
    ("fuel", j1939.PGN_LFE, ENGINE_ADDRESS, 6, {"fuel_rate_lph": "fuel_rate_lph"}),
    ("weight", j1939.PGN_CVW, BRAKES_ADDRESS, 6, {"gross_combination_weight_kg": "gross_combination_weight_kg"}),
)


def _ns(time_s) -> np.ndarray:
    return np.round(np.asarray(time_s, dtype=float) * 1e9).astype(np.int64)


def can_frames(drive) -> np.ndarray:
    """All broadcast frames of the drive, in time order (`contract.CAN_FRAME_DTYPE`)."""
    times, ids, payloads = [], [], []
    for stream, pgn, source, priority, spns in _CAN_BROADCASTS:
        frame = drive.sensors[stream]
        columns = [frame[c].to_numpy() for c in spns.values()]
        cache: dict[tuple, bytes] = {}
        data = []
        for values in zip(*columns):
            key = tuple(None if v != v else float(v) for v in values)  # NaN: not available, and a key that matches
            if key not in cache:
                cache[key] = j1939.encode_pgn(pgn, dict(zip(spns, key)))
            data.append(cache[key])
        times.append(frame["time_s"].to_numpy())
        ids.append(np.full(len(frame), j1939.make_id(pgn, source, priority)))
        payloads.extend(data)
    ec1 = j1939.encode_pgn(j1939.PGN_EC1, {"engine_reference_torque_nm": drive.sensors["engine_reference_torque_nm"]})
    session = j1939.bam_frames(j1939.PGN_EC1, ec1)
    session_ids = [j1939.make_id(j1939.PGN_TP_CM, ENGINE_ADDRESS, 7)] + \
                  [j1939.make_id(j1939.PGN_TP_DT, ENGINE_ADDRESS, 7)] * (len(session) - 1)
    for start in np.arange(0.3, drive.duration_s - 1.0, EC1_PERIOD_S):
        times.append(start + BAM_PACKET_GAP_S * np.arange(len(session)))
        ids.append(np.array(session_ids))
        payloads.extend(session)
    time = np.concatenate(times)
    records = np.zeros(len(time), dtype=contract.CAN_FRAME_DTYPE)
    records["t_mono_ns"] = BOOT_OFFSET_NS + _ns(time)
    records["arbitration_id"] = np.concatenate(ids)
    records["flags"] = contract.CAN_FLAG_EXTENDED | contract.CAN_FLAG_HW_TIMESTAMP
    records["dlc"] = [len(p) for p in payloads]
    records["data"] = np.frombuffer(b"".join(p.ljust(8, b"\0") for p in payloads), np.uint8).reshape(-1, 8)
    return records[np.argsort(records["t_mono_ns"], kind="stable")]


def _batches(t_ns: np.ndarray, max_count: int, max_span_ns: int):
    """(start, stop) index pairs of consecutive batches."""
    start = 0
    while start < len(t_ns):
        stop = min(start + max_count, int(np.searchsorted(t_ns, t_ns[start] + max_span_ns, side="left")))
        stop = max(stop, start + 1)
        yield start, stop
        start = stop


def _packed_sensor(table, topic: contract.Topic, order: int, batch_s: float, fields: tuple[str, ...]):
    """(t_mono_ns, order, topic, payload) of a sensor's samples packed as the logger packs them
    (contract 2): one message per ``batch_s`` of samples, stamped with its first sample."""
    records = np.zeros(len(table), dtype=topic.dtype)
    records["t_mono_ns"] = BOOT_OFFSET_NS + np.round(table["time_s"].to_numpy() * 1e9).astype(np.int64)
    for name in fields:
        records[name] = table[name].to_numpy()
    window = np.floor(table["time_s"].to_numpy() / batch_s).astype(np.int64)
    for part in np.split(records, np.flatnonzero(np.diff(window)) + 1):
        if len(part):
            yield int(part["t_mono_ns"][0]), order, topic, contract.pack(topic, part)


def _imu_temperature(imu) -> pd.DataFrame:
    """The IMU's die temperature as the logger reads it: once a second, OUT_TEMP's 1/16 K steps."""
    time_s = imu["time_s"].to_numpy()
    first = np.flatnonzero(np.diff(np.floor(time_s / IMU_TEMPERATURE_STEP_S), prepend=-1.0) > 0)
    raw = contract.imu_temperature_counts(imu["imu_temperature_c"].to_numpy()[first])
    return pd.DataFrame({"time_s": time_s[first], "temperature_c": contract.imu_temperature_c(raw),
                         "temperature_raw": raw})


def _messages(drive, contract_version: int = contract.CONTRACT_VERSION):
    """(t_mono_ns, order, topic, payload) of every message in the log."""
    start_ns = drive.scenario.start_epoch_ns
    frames = can_frames(drive)
    for a, b in _batches(frames["t_mono_ns"], MAX_FRAMES_PER_MESSAGE, int(MAX_BATCH_S * 1e9)):
        yield int(frames["t_mono_ns"][b - 1]), 0, contract.CAN_FRAMES, contract.pack(contract.CAN_FRAMES, frames[a:b])

    imu = drive.sensors["imu"]
    samples = np.zeros(len(imu), dtype=contract.IMU_SAMPLE_DTYPE)
    samples["t_mono_ns"] = BOOT_OFFSET_NS + _ns(imu["time_s"])
    samples["accel_raw"] = imu[["accel_x_raw", "accel_y_raw", "accel_z_raw"]].to_numpy()
    samples["gyro_raw"] = imu[["gyro_x_raw", "gyro_y_raw", "gyro_z_raw"]].to_numpy()
    window = np.floor(imu["time_s"].to_numpy() / IMU_BATCH_S).astype(np.int64)
    edges = np.flatnonzero(np.diff(window)) + 1
    for part in np.split(samples, edges):
        yield int(part["t_mono_ns"][-1]), 1, contract.IMU, contract.pack(contract.IMU, part)

    if contract_version >= 2 and "imu_temperature_c" in imu:
        yield from _packed_sensor(_imu_temperature(imu), contract.IMU_TEMPERATURE, 6, IMU_TEMPERATURE_BATCH_S,
                                  ("temperature_c", "temperature_raw"))

    if contract_version >= 2:
        yield from _packed_sensor(drive.sensors["barometer"], contract.BAROMETER, 2, BAROMETER_BATCH_S,
                                  ("pressure_pa", "temperature_c", "pressure_raw", "temperature_raw"))
        yield from _packed_sensor(drive.sensors["humidity"], contract.HUMIDITY, 3, HUMIDITY_BATCH_S,
                                  ("relative_humidity_pct", "temperature_c", "humidity_raw", "temperature_raw"))
    else:
        for row in drive.sensors["barometer"].itertuples(index=False):
            t = BOOT_OFFSET_NS + int(round(row.time_s * 1e9))
            yield t, 2, contract.BAROMETER_V1, contract.encode_json({
                "t_mono_ns": t, "pressure_pa": float(row.pressure_pa), "temperature_c": float(row.temperature_c),
                "pressure_raw": int(row.pressure_raw), "temperature_raw": int(row.temperature_raw)})
        for row in drive.sensors["humidity"].itertuples(index=False):
            t = BOOT_OFFSET_NS + int(round(row.time_s * 1e9))
            yield t, 3, contract.HUMIDITY_V1, contract.encode_json({
                "t_mono_ns": t, "relative_humidity_pct": float(row.relative_humidity_pct),
                "temperature_c": float(row.temperature_c), "humidity_raw": int(row.humidity_raw),
                "temperature_raw": int(row.temperature_raw)})

    gps = drive.sensors["gps"]
    for row in gps[gps["fix_quality"] > 0].itertuples(index=False):
        epoch_ns = int(round(row.time_s * 1e9))
        t = BOOT_OFFSET_NS + epoch_ns + GPS_LATENCY_NS
        yield t, 4, contract.GPS_FIX, contract.encode_json(contract.location_fix(
            t, start_ns + epoch_ns, float(row.latitude_deg), float(row.longitude_deg), float(row.altitude_m),
            float(row.h_acc_m), float(row.v_acc_m), gps_time_utc_ns=start_ns + epoch_ns,
            speed_mps=float(row.speed_mps), course_deg=None, fix_quality=int(row.fix_quality),
            satellites=int(row.satellites), hdop=None))

    fix_times = gps.loc[gps["fix_quality"] > 0, "time_s"].to_numpy()
    end_ns = int(round(float(drive.states["time_s"].iloc[-1]) * 1e9))
    for elapsed_ns in range(500_000_000, end_ns + 1, 1_000_000_000):
        recent = fix_times.size and np.any(np.abs(fix_times - elapsed_ns / 1e9) <= 1.0)
        t = BOOT_OFFSET_NS + elapsed_ns
        yield t, 5, contract.TIME_SYNC, contract.encode_json({
            "t_mono_ns": t, "t_realtime_ns": start_ns + elapsed_ns,
            "gps_time_utc_ns": start_ns + elapsed_ns if recent else None})


def write_mcap(drive, path: str | Path, contract_version: int = contract.CONTRACT_VERSION) -> Path:
    """Write the drive's sensor streams as one MCAP log (deterministic bytes for a drive);
    ``contract_version`` 1 writes barometer and humidity as contract 1's JSON messages."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    metadata = {
        contract.IMU.name: {
            "accel_scale_mps2_per_lsb": repr(sensor_models.ACCEL_SCALE_MPS2_PER_LSB),
            "gyro_scale_radps_per_lsb": repr(sensor_models.GYRO_SCALE_RADPS_PER_LSB),
            "accel_full_scale_g": str(sensor_models.ACCEL_FULL_SCALE_G),
            "gyro_full_scale_dps": str(sensor_models.GYRO_FULL_SCALE_DPS),
            "rate_hz": repr(float(drive.scenario.sensors.imu_rate_hz))},
        contract.CAN_FRAMES.name: {"channel_0": "can0", "bitrate": "250000", "protocol": "j1939"},
    }
    start_ns = drive.scenario.start_epoch_ns
    messages = sorted(_messages(drive, contract_version), key=lambda m: (m[0], m[1]))
    with open(path, "wb") as stream:
        writer = TopicWriter(stream, channel_metadata=metadata, contract_version=contract_version)
        writer.write_metadata("haulprofile.source", {
            "generator": "haulprofile.analysis.virtual_truck", "scenario": drive.scenario.name, "seed": str(drive.seed),
            "vehicle": drive.vehicle.name})
        for t_mono, _, topic, payload in messages:
            writer.write(topic, payload, t_mono, start_ns + (t_mono - BOOT_OFFSET_NS))
        writer.close()
    return path
