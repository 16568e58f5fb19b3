"""Name the aligned streams: the signals table columns and the ingest summary.

Where two sources give the same quantity, J1939 wins over OBD-II and, within J1939, the source
address that sent the most frames wins (the others are listed in the summary, never mixed).
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from .. import checks
from ..signal_columns import COLUMNS
from ..units import UNITS_KEY
from . import align
from .logs import LogError

KMH = 1.0 / 3.6
IMU_TEMPERATURE_HOLD_S = 2.5
"""The IMU's temperature comes once a second: held over a reading that arrived late or was lost, not
over a sensor that stopped."""


def _sources(acc: align.BinAccumulator, spn_name: str) -> list[tuple[str, int]]:
    """Stream keys of one J1939 SPN, one per source address, most samples first."""
    keys = [(k, s.n) for k, s in acc.streams.items() if k.startswith(spn_name + "@") and s.n > 0]
    return sorted(keys, key=lambda kn: -kn[1])


class _Columns:
    def __init__(self, ingest):
        self.ingest = ingest
        self.acc = ingest.acc
        grid = self.acc.grid()
        if grid is None:
            raise LogError("the logs hold no data (no CAN frames, sensor samples or GPS fixes)")
        checks.rows(grid.n, f"the signals table at {ingest.rate_hz:g} Hz", "give a lower ingest.rate_hz or fewer logs")
        self.grid, self.n = grid, grid.n
        self.first_bin = int(grid.run_bins[0])
        self.recorded = self.acc.recorded(grid)
        self.rate_hz = ingest.rate_hz
        self.chosen: dict[str, dict] = {}

    def held(self, key: str, max_hold_s: float = align.MAX_HOLD_S) -> np.ndarray:
        values = self.acc.series(key, self.grid)
        limit = align.hold_bins(self.acc.sample_period_s(key), self.rate_hz, max_hold_s)
        return align.hold(values, self.recorded, limit)

    def pick(self, column: str, spn_name: str | None, obd_name: str | None = None, scale: float = 1.0,
             max_hold_s: float = align.MAX_HOLD_S) -> np.ndarray | None:
        """J1939 SPN from its busiest source address, else the OBD-II PID, else another key."""
        candidates = _sources(self.acc, spn_name) if spn_name else []
        if candidates:
            key = candidates[0][0]
            self.chosen[column] = {"source": "j1939", "key": key,
                                   "other_sources": [k for k, _ in candidates[1:]]}
            return self.held(key, max_hold_s) * scale
        for key in ([obd_name] if obd_name else []):
            if key in self.acc.streams and self.acc.streams[key].n:
                self.chosen[column] = {"source": key.split(":")[0], "key": key}
                return self.held(key, max_hold_s) * scale
        return None

    def constant(self, spn_name: str, obd_name: str) -> float | None:
        """A configuration value (reference torque): the median of what was sent."""
        for key in [k for k, _ in _sources(self.acc, spn_name)] + [obd_name]:
            if key in self.acc.streams and self.acc.streams[key].n:
                values = self.acc.series(key, self.grid)
                self.chosen[spn_name] = {"key": key}
                return float(np.nanmedian(values))
        return None

    def axle_sum(self) -> np.ndarray | None:
        """Sum of the VW axle weights of the busiest source [kg]; NaN unless every axle is known."""
        pattern = re.compile(r"axle_weight_kg#(\d+)@(\d+)$")
        by_source: dict[str, list[str]] = {}
        for key, stream in self.acc.streams.items():
            match = pattern.match(key)
            if match and stream.n:
                by_source.setdefault(match.group(2), []).append(key)
        if not by_source:
            return None
        source = max(by_source, key=lambda s: sum(self.acc.streams[k].n for k in by_source[s]))
        keys = sorted(by_source[source])
        self.chosen["reported_mass_kg"] = {"source": "j1939 VW axle sum", "key": keys}
        stack = np.vstack([self.held(k, align.QUASI_STATIC_HOLD_S) for k in keys])
        return np.where(np.all(np.isfinite(stack), axis=0), stack.sum(axis=0), np.nan)


def build_table(ingest) -> tuple[pd.DataFrame, dict]:
    """The signals table of an `Ingest` after `finish_streams`, and the coverage summary."""
    c = _Columns(ingest)
    acc = ingest.acc
    grid_mono = c.grid.bins() * acc.period_ns
    table: dict[str, np.ndarray] = {"time_s": np.arange(c.n, dtype=np.int64) * acc.period_ns / 1e9}
    wall = align.wall_clock_ns(grid_mono, ingest.clock_pairs())
    if wall is not None:
        table["wall_time_ns"] = wall
    speed = c.pick("speed_mps", "wheel_speed_kmh", "obd:vehicle_speed_kmh", KMH)
    if speed is None and "gps:speed_mps" in acc.streams and acc.streams["gps:speed_mps"].n:
        # no CAN speed: the receiver's speed over ground (RMC/VTG, NAV-PVT), linear between fixes
        c.chosen["speed_mps"] = {"source": "gps", "key": "gps:speed_mps"}
        speed = align.interpolate(acc.series("gps:speed_mps", c.first_bin, c.n), c.recorded,
                                  align.hold_bins(acc.sample_period_s("gps:speed_mps"), c.rate_hz))
    columns = {
        "engine_speed_rpm": c.pick("engine_speed_rpm", "engine_speed_rpm", "obd:engine_speed_rpm"),
        "driver_demand_torque_pct": c.pick("driver_demand_torque_pct", "driver_demand_torque_pct",
                                           "obd:driver_demand_torque_pct"),
        "accelerator_pedal_pct": c.pick("accelerator_pedal_pct", "accelerator_pedal_pct"),
        "current_gear": c.pick("current_gear", "current_gear"),
        "brake_switch": c.pick("brake_switch", "brake_switch"),
        "fuel_rate_lph": c.pick("fuel_rate_lph", "fuel_rate_lph"),
    }
    torque_pct = c.pick("actual_engine_torque_pct", "actual_engine_torque_pct", "obd:actual_engine_torque_pct")
    reference = c.constant("engine_reference_torque_nm", "obd:engine_reference_torque_nm")
    if reference is not None:
        columns["engine_reference_torque_nm"] = np.where(c.recorded, reference, np.nan)
        if torque_pct is not None:
            columns["engine_torque_nm"] = torque_pct / 100.0 * reference
        for column, spn_name in (("engine_friction_torque_nm", "nominal_friction_torque_pct"),
                                 ("engine_parasitic_torque_nm", "parasitic_loss_torque_pct")):
            pct = c.pick(column, spn_name)
            if pct is not None:
                columns[column] = pct / 100.0 * reference
    mass = c.pick("reported_mass_kg", "gross_combination_weight_kg", max_hold_s=align.QUASI_STATIC_HOLD_S)
    columns["reported_mass_kg"] = mass if mass is not None else c.axle_sum()
    for column, key in (("latitude_deg", "gps:latitude"), ("longitude_deg", "gps:longitude"),
                        ("gps_altitude_m", "gps:altitude"), ("gps_h_acc_m", "gps:h_acc_m"),
                        ("gps_v_acc_m", "gps:v_acc_m"), ("gps_hdop", "gps:hdop"), ("gps_vdop", "gps:vdop"),
                        ("relative_humidity_pct", "hum:relative_humidity_pct"),
                        ("accel_x_mps2", "accel_x_mps2"), ("accel_y_mps2", "accel_y_mps2"),
                        ("accel_z_mps2", "accel_z_mps2")):
        columns[column] = c.pick(column, None, key)
    columns["imu_temperature_c"] = c.pick("imu_temperature_c", None, "imut:temperature_c",
                                          max_hold_s=IMU_TEMPERATURE_HOLD_S)
    columns["pressure_pa"] = c.pick("pressure_pa", None, "baro:pressure_pa")
    if columns["pressure_pa"] is None:
        columns["pressure_pa"] = c.pick("pressure_pa", None, "obd:barometric_pressure_kpa", 1000.0)
    for key in ("hum:temperature_c", "baro:temperature_c", "obd:ambient_air_temperature_c"):
        columns["air_temperature_c"] = c.pick("air_temperature_c", None, key)
        if columns["air_temperature_c"] is not None:
            break
    dbc_units = ({s.name: s.unit or "" for m in ingest.database.messages for s in m.signals}
                 if ingest.database is not None else {})
    units = {}
    for key in sorted(k for k in acc.streams if k.startswith("dbc:")):
        name = key[4:]
        ours = name in COLUMNS or name in table or name in columns  # a DBC never replaces one of our columns
        column = f"dbc_{name}" if ours else name
        columns[column] = c.pick(column, None, key)
        units[column] = dbc_units.get(name, "")
    if speed is not None:
        table["valid"] = c.recorded & np.isfinite(speed)
        table["speed_mps"] = speed
    else:
        table["valid"] = c.recorded
    table.update({k: v for k, v in columns.items() if v is not None})
    frame = pd.DataFrame(table)
    frame.attrs[UNITS_KEY] = {k: v for k, v in units.items() if k in frame.columns}
    return frame, _summary(ingest, c, frame)


def _summary(ingest, c: _Columns, frame: pd.DataFrame) -> dict:
    valid = frame["valid"].to_numpy()
    gaps = np.flatnonzero(np.diff(np.concatenate([[1], c.recorded.astype(np.int8), [1]])) == -1)
    coverage = {col: float(np.isfinite(frame[col].to_numpy(dtype=float))[valid].mean()) if valid.any() else 0.0
                for col in frame.columns if col not in ("time_s", "valid", "wall_time_ns")}
    return {
        "rate_hz": ingest.rate_hz,
        "t0_mono_ns": int(c.first_bin * ingest.acc.period_ns),
        "rows": int(len(frame)),
        "duration_s": float(frame["time_s"].iloc[-1]) + 1.0 / ingest.rate_hz,
        "valid_fraction": float(valid.mean()),
        "gaps": int(len(gaps)),
        "gap_s": float((~c.recorded).sum() / ingest.rate_hz),
        "span_s": float((c.grid.run_bins[-1] + c.grid.lengths[-1] - c.first_bin) * ingest.acc.period_ns / 1e9),
        "gaps_shortened": c.grid.shortened(ingest.acc.period_ns),
        "can_frames": int(ingest.can_frames),
        "imu_samples": int(ingest.imu_samples),
        "topics": dict(ingest.topic_counts),
        "sources": c.chosen,
        "coverage": coverage,
        "transport_protocol": vars(ingest.tp_stats),
        "obd": vars(ingest.obd_stats),
        "notes": list(ingest.notes),
    }
