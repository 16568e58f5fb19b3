"""Contract-correct synthetic logs with a known truth, for ingest tests and the benchmark.

Not a vehicle model (that is `haulprofile.analysis.virtual_truck`): the truth here is a random but smooth
signal per quantity, constant within each 100 ms bin, so an aligned 10 Hz table can be compared
bin by bin. The frames are what a truck sends (J1939-71 layouts from `haulprofile.contract.j1939`, EC1 by
BAM every 5 s, a second CCVS1 sender that reports "not available"), at bus rates, batched and
written as the logger writes them (the contract's `TopicWriter`, packed topics, small zstd chunks).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from haulprofile import contract
from haulprofile.contract import j1939
from haulprofile.contract import CAN_FLAG_EXTENDED, CAN_FLAG_HW_TIMESTAMP
from haulprofile.contract.writer import TopicWriter

BIN_NS = 100_000_000
ACCEL_SCALE_MPS2_PER_LSB = 0.061e-3 * 9.80665
"""LSM9DS1 at ±2 g: 0.061 mg/LSB."""
T0_MONO_NS = 5_000_000_000_000
REALTIME_OFFSET_NS = 1_700_000_000_000_000_000 - T0_MONO_NS
GPS_MINUS_REALTIME_NS = 250_000_000
"""The Pi's clock runs 0.25 s off GPS: wall_time_ns must follow GPS."""
REFERENCE_TORQUE_NM = 2100.0

# (PGN, source address, rate [Hz], phase within the bin [ns])
PERIODIC = [
    (j1939.PGN_EEC1, 0x00, 100.0, 3_000_000),
    (j1939.PGN_EEC2, 0x00, 20.0, 11_000_000),
    (j1939.PGN_CCVS1, 0x00, 10.0, 13_000_000),
    (j1939.PGN_CCVS1, 0x17, 5.0, 17_000_000),
    (j1939.PGN_ETC2, 0x03, 10.0, 23_000_000),
    (j1939.PGN_LFE, 0x00, 10.0, 29_000_000),
    (j1939.PGN_CVW, 0x0B, 1.0, 31_000_000),
]
FILLER_PGNS = (65262, 65263, 65270, 65271, 65276, 65217, 65132, 61442, 64892, 65253)
"""Engine temperature, fluid levels, inlet/exhaust, electrical, dash display, … (not decoded)."""


@dataclass
class Truth:
    """Per-bin (100 ms) truth of a synthetic log; ``bin_start_mono_ns`` on the logger's clock."""

    bin_start_mono_ns: np.ndarray
    values: dict[str, np.ndarray]


def _smooth(rng, n: int, low: float, high: float, step: float) -> np.ndarray:
    walk = np.cumsum(rng.normal(0, step, n))
    walk = np.convolve(walk, np.ones(25) / 25, mode="same")
    span = walk.max() - walk.min() if n > 1 and walk.max() > walk.min() else 1.0
    return low + (walk - walk.min()) / span * (high - low)


def make_truth(n_bins: int, rng, t0_ns: int = T0_MONO_NS) -> Truth:
    speed = np.clip(_smooth(rng, n_bins, -3, 24, 0.3), 0, None)
    v = {
        "speed_mps": speed,
        "engine_speed_rpm": np.where(speed > 0, 900 + speed * 45, 650.0),
        "actual_engine_torque_pct": _smooth(rng, n_bins, -10, 95, 2.0),
        "driver_demand_torque_pct": _smooth(rng, n_bins, 0, 100, 2.0),
        "accelerator_pedal_pct": _smooth(rng, n_bins, 0, 100, 2.0),
        "current_gear": np.round(np.clip(speed / 2.2, 0, 12)),
        "brake_switch": (rng.random(n_bins) < 0.1).astype(float),
        "fuel_rate_lph": _smooth(rng, n_bins, 2, 80, 1.0),
        "reported_mass_kg": np.full(n_bins, 18_000.0),
        "latitude_deg": 50.77 + np.cumsum(speed) * 1e-6,
        "longitude_deg": 6.08 + np.cumsum(speed) * 0.5e-6,
        "gps_altitude_m": _smooth(rng, n_bins, 150, 300, 0.5),
        "gps_h_acc_m": np.full(n_bins, 1.5),
        "gps_v_acc_m": np.full(n_bins, 2.5),
        "pressure_pa": _smooth(rng, n_bins, 97_000, 99_000, 5.0),
        "air_temperature_c": _smooth(rng, n_bins, 5, 25, 0.05),
        "relative_humidity_pct": _smooth(rng, n_bins, 30, 70, 0.1),
        "accel_x_mps2": np.gradient(speed, 0.1),
        "accel_y_mps2": _smooth(rng, n_bins, -1, 1, 0.1),
        "accel_z_mps2": 9.80665 + _smooth(rng, n_bins, -0.3, 0.3, 0.05),
    }
    return Truth(t0_ns + np.arange(n_bins, dtype=np.int64) * BIN_NS, v)


def _spn_words(pgn: int, columns: dict[str, np.ndarray]) -> np.ndarray:
    """Data words (uint64, little-endian bytes) of ``pgn`` from physical SPN values, vectorised."""
    n = len(next(iter(columns.values())))
    word = np.full(n, np.uint64(0xFFFFFFFFFFFFFFFF))
    for spn in j1939.spns_of(pgn):
        if spn.name not in columns:
            continue
        value = columns[spn.name]
        raw = np.clip(np.round((value - spn.offset) / spn.resolution), 0, spn.max_valid_raw)
        raw = np.where(np.isnan(value), spn.not_available_raw, raw).astype(np.uint64)
        mask = np.uint64(((1 << spn.length_bits) - 1) << spn.bit_offset)
        word = (word & ~mask) | (raw << np.uint64(spn.bit_offset))
    return word


def can_frames(truth: Truth, filler_hz: float, rng) -> np.ndarray:
    """Every CAN frame of the truth's span, time-sorted (contract dtype)."""
    v, t0 = truth.values, truth.bin_start_mono_ns
    n_bins = len(t0)
    parts = []
    for pgn, source, rate, phase in PERIODIC:
        per_bin = rate * BIN_NS / 1e9
        step = max(1, int(round(1 / per_bin))) if per_bin < 1 else 1
        count = int(round(per_bin)) if per_bin >= 1 else 1
        bins = np.repeat(np.arange(0, n_bins, step), count)
        sub = np.tile(np.arange(count), len(bins) // count) if count else bins
        times = t0[bins] + phase + sub * (BIN_NS // max(count, 1))
        columns = {name: v[key][bins] for name, key in _SPN_SOURCES.items()
                   if j1939.SPNS[name].pgn == pgn and key in v}
        if pgn == j1939.PGN_CCVS1:
            columns = {"wheel_speed_kmh": v["speed_mps"][bins] * 3.6, "brake_switch": v["brake_switch"][bins]}
            if source != 0x00:
                columns = {"wheel_speed_kmh": np.full(len(bins), np.nan)}
        if pgn == j1939.PGN_CVW:
            columns = {"gross_combination_weight_kg": v["reported_mass_kg"][bins]}
        parts.append(_records(times, j1939.make_id(pgn, source, 3 if pgn == j1939.PGN_EEC1 else 6),
                              _spn_words(pgn, columns)))
    ec1 = j1939.encode_pgn(j1939.PGN_EC1, {"engine_reference_torque_nm": REFERENCE_TORQUE_NM})
    bam = j1939.bam_frames(j1939.PGN_EC1, ec1)
    for b in range(0, n_bins, 50):
        for k, data in enumerate(bam):
            pgn = j1939.PGN_TP_CM if k == 0 else j1939.PGN_TP_DT
            word = np.frombuffer(data.ljust(8, b"\xff"), "<u8")
            parts.append(_records(np.array([t0[b] + 41_000_000 + k * 5_000_000]), j1939.make_id(pgn, 0x00, 7), word))
    if filler_hz > 0:
        n = int(filler_hz * n_bins * BIN_NS / 1e9)
        times = t0[0] + np.sort(rng.integers(0, n_bins * BIN_NS, n))
        ids = np.array([j1939.make_id(p, s) for p in FILLER_PGNS for s in (0x00, 0x03)], dtype=np.uint32)
        chosen = ids[rng.integers(0, len(ids), n)]
        parts.append(_records(times, chosen, rng.integers(0, 2**63, n, dtype=np.int64).astype(np.uint64)))
    frames = np.concatenate(parts)
    return frames[np.argsort(frames["t_mono_ns"], kind="stable")]


_SPN_SOURCES = {"engine_speed_rpm": "engine_speed_rpm", "actual_engine_torque_pct": "actual_engine_torque_pct",
                "driver_demand_torque_pct": "driver_demand_torque_pct",
                "accelerator_pedal_pct": "accelerator_pedal_pct", "current_gear": "current_gear",
                "fuel_rate_lph": "fuel_rate_lph"}


def _records(times, arbitration_id, words) -> np.ndarray:
    out = np.zeros(len(times), contract.CAN_FRAME_DTYPE)
    out["t_mono_ns"] = times
    out["arbitration_id"] = arbitration_id
    out["flags"] = CAN_FLAG_EXTENDED | CAN_FLAG_HW_TIMESTAMP
    out["dlc"] = 8
    out["data"] = np.ascontiguousarray(words, dtype="<u8").view(np.uint8).reshape(-1, 8)
    return out


def imu_samples(truth: Truth, rate_hz: float = 952.0) -> np.ndarray:
    t0 = truth.bin_start_mono_ns
    n = int(len(t0) * BIN_NS / 1e9 * rate_hz)
    times = t0[0] + np.round(np.arange(n) * 1e9 / rate_hz).astype(np.int64) + 500_000
    bins = (times - t0[0]) // BIN_NS
    out = np.zeros(n, contract.IMU_SAMPLE_DTYPE)
    out["t_mono_ns"] = times
    for axis, key in enumerate(("accel_x_mps2", "accel_y_mps2", "accel_z_mps2")):
        out["accel_raw"][:, axis] = np.round(truth.values[key][bins] / ACCEL_SCALE_MPS2_PER_LSB)
    return out


def write_log(stream: BinaryIO, duration_s: float, seed: int = 0, filler_hz: float = 0.0,
              segment_s: float = 60.0, chunk_size: int = 256 * 1024, t0_mono_ns: int = T0_MONO_NS,
              realtime_offset_ns: int = REALTIME_OFFSET_NS, contract_version: int = contract.CONTRACT_VERSION) -> Truth:
    """Write a synthetic log of ``duration_s`` [s] into ``stream``; return its truth.

    ``t0_mono_ns`` (a multiple of 100 ms) is the logger's monotonic clock at the start;
    ``realtime_offset_ns`` its realtime minus monotonic clock (GPS UTC is 0.25 s ahead of it);
    ``contract_version`` 1 writes barometer, humidity and magnetometer as one JSON message per
    sample (the old logger), 2 packed as today's logger does (the same values either way).
    """
    rng = np.random.default_rng(seed)
    n_bins = int(round(duration_s * 1e9 / BIN_NS))
    truth = make_truth(n_bins, rng, t0_mono_ns)
    writer = TopicWriter(stream, chunk_size=chunk_size, channel_metadata={
        contract.IMU.name: {"accel_scale_mps2_per_lsb": repr(ACCEL_SCALE_MPS2_PER_LSB),
                            "gyro_scale_radps_per_lsb": repr(8.75e-3 * np.pi / 180)}},
                         contract_version=contract_version)
    per_segment = int(segment_s * 1e9 / BIN_NS)
    for start in range(0, n_bins, per_segment):
        part = Truth(truth.bin_start_mono_ns[start:start + per_segment],
                     {k: v[start:start + per_segment] for k, v in truth.values.items()})
        _write_segment(writer, part, filler_hz, rng, realtime_offset_ns, contract_version)
    writer.close()
    return truth


def _sensor_events(truth: Truth) -> list:
    """(t_mono_ns, topic, payload) of the barometer (3 samples a bin, 8 to a message as a FIFO read),
    humidity and magnetometer (one per second) as today's logger packs them."""
    v, t0 = truth.values, truth.bin_start_mono_ns
    events = []
    baro = np.zeros(3 * len(t0), contract.BAROMETER.dtype)  # 25 Hz: samples at 1, 41, 81 ms of every bin
    baro["t_mono_ns"] = (t0[:, None] + np.array([1_000_000, 41_000_000, 81_000_000])).ravel()
    baro["pressure_pa"] = np.repeat(v["pressure_pa"], 3)
    baro["temperature_c"] = np.repeat(v["air_temperature_c"], 3)
    humidity = np.zeros(len(t0), contract.HUMIDITY.dtype)
    humidity["t_mono_ns"] = t0 + 2_000_000
    humidity["relative_humidity_pct"] = v["relative_humidity_pct"]
    humidity["temperature_c"] = v["air_temperature_c"]
    magnetic = np.zeros(len(t0), contract.MAGNETOMETER.dtype)
    magnetic["t_mono_ns"] = t0 + 5_000_000
    magnetic["magnetic_field_t"] = [2e-5, 0.0, 4e-5]
    magnetic["magnetic_raw"] = [700, 0, 1400]
    for topic, records, per_message in ((contract.BAROMETER, baro, 8), (contract.HUMIDITY, humidity, 10),
                                        (contract.MAGNETOMETER, magnetic, 10)):
        for start in range(0, len(records), per_message):
            batch = records[start:start + per_message]
            events.append((int(batch["t_mono_ns"][0]), topic, contract.pack(topic, batch)))
    return events


def _write_segment(writer: TopicWriter, truth: Truth, filler_hz: float, rng, realtime_offset_ns: int,
                   contract_version: int) -> None:
    events = []
    frames = can_frames(truth, filler_hz, rng)
    for start in range(0, len(frames), 512):
        batch = frames[start:start + 512]
        events.append((int(batch["t_mono_ns"][-1]), contract.CAN_FRAMES, contract.pack(contract.CAN_FRAMES, batch)))
    imu = imu_samples(truth)
    for start in range(0, len(imu), 32):
        batch = imu[start:start + 32]
        events.append((int(batch["t_mono_ns"][-1]), contract.IMU, contract.pack(contract.IMU, batch)))
    v, t0 = truth.values, truth.bin_start_mono_ns
    packed = contract_version >= 2
    if packed:
        events += _sensor_events(truth)
    for k in range(len(t0)):
        t = int(t0[k])
        if not packed:
            for j in range(0, 10, 4):  # barometer 25 Hz: samples at 0, 40, 80 ms of every 100 ms
                events.append((t + j * 10_000_000 + 1_000_000, contract.BAROMETER_V1, contract.encode_json({
                    "t_mono_ns": t + j * 10_000_000 + 1_000_000, "pressure_pa": float(v["pressure_pa"][k]),
                    "temperature_c": float(v["air_temperature_c"][k]), "pressure_raw": 0, "temperature_raw": 0})))
            events.append((t + 2_000_000, contract.HUMIDITY_V1, contract.encode_json({
                "t_mono_ns": t + 2_000_000, "relative_humidity_pct": float(v["relative_humidity_pct"][k]),
                "temperature_c": float(v["air_temperature_c"][k]), "humidity_raw": 0, "temperature_raw": 0})))
        gps_ns = t + realtime_offset_ns + GPS_MINUS_REALTIME_NS
        events.append((t + 7_000_000, contract.GPS_FIX, contract.encode_json(contract.location_fix(
            t + 7_000_000, gps_ns + 7_000_000, float(v["latitude_deg"][k]), float(v["longitude_deg"][k]),
            float(v["gps_altitude_m"][k]), float(v["gps_h_acc_m"][k]), float(v["gps_v_acc_m"][k]),
            gps_time_utc_ns=gps_ns + 7_000_000, fix_quality=1, satellites=9))))
        if not packed:
            events.append((t + 5_000_000, contract.MAGNETOMETER_V1, contract.encode_json({
                "t_mono_ns": t + 5_000_000, "magnetic_field_t": [2e-5, 0.0, 4e-5], "magnetic_raw": [700, 0, 1400]})))
        if t % 1_000_000_000 == 0:
            events.append((t + 9_000_000, contract.TIME_SYNC, contract.encode_json({
                "t_mono_ns": t + 9_000_000, "t_realtime_ns": t + 9_000_000 + realtime_offset_ns,
                "gps_time_utc_ns": t + 9_000_000 + realtime_offset_ns + GPS_MINUS_REALTIME_NS})))
    events.sort(key=lambda e: e[0])
    for t, topic, payload in events:
        writer.write(topic, payload, t, t + realtime_offset_ns)
