"""The additive statistics of a log, and of any number of logs by summing them (`FleetStatistics`).

Per log, from its signals after the mass stage: the Markov transition counts
(`analysis.markov.count_transitions`, each log closed on itself), wheel-load histograms on fixed
bins (`LoadBins`), Palmgren–Miner damage sums Σ nᵢ Sᵢᵏ of the wheel-torque rainflow cycles,
totals (time, distance, wheel energy, fuel), and the mass estimated per segment.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd

from ..loads import NEEDED as LOAD_COLUMNS
from ..loads import loads_of, resample_mean
from ..loads.bins import WIDTHS
from ..loads.collectives import (EQUIVALENT_FREQUENCY_HZ, QUANTITIES, WOEHLER_EXPONENTS, level_crossings,
                                 rainflow_cycles, sample_durations_s)
from ..markov import ClassWidths, TransitionCounts, count_transitions
from ..markov.counting import CountingError
from ..jsonable import jsonable
from ..stop_mass import with_mass_at_stops
from ..vehicle import Vehicle
from .histograms import SparseHistogram
from .road_load import SegmentMoments

STANDING_MPS = 0.1
TOTALS = ("duration_s", "valid_s", "driving_s", "distance_km", "mass_known_s", "loads_s", "loads_distance_km",
          "positive_wheel_energy_kwh", "negative_wheel_energy_kwh", "fuel_l", "fuel_logged_s", "rainflow_cycles")


@dataclass(frozen=True)
class LoadBins:
    """Fixed bin widths of the wheel-load histograms (those of a single drive's collectives,
    `loads.bins.WIDTHS`, so a truck's sum and a drive compare bin by bin), and the averaging period
    the loads are counted on **[choice: 1 s, the generated cycle's rate; rainflow counts depend on the rate]**."""

    wheel_force_n: float = WIDTHS["wheel_force_n"]
    wheel_torque_nm: float = WIDTHS["wheel_torque_nm"]
    wheel_speed_rpm: float = WIDTHS["wheel_speed_rpm"]
    wheel_power_w: float = WIDTHS["wheel_power_w"]
    residence_speed_rpm: float = WIDTHS["residence_speed_rpm"]
    residence_torque_nm: float = WIDTHS["residence_torque_nm"]
    rainflow_nm: float = WIDTHS["rainflow_range_nm"]
    period_s: float = 1.0
    power_level_w: float = 100.0
    """Bins of the fine wheel power histogram the cycle selection's power levels come from
    (`cycle_target`) **[choice: 100 W, a thousandth of a truck's power range]**."""

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class FleetStatistics:
    """Additive statistics of the logs named in ``logs`` (sorted paths); ``a + b`` is both."""

    logs: list[str]
    counts: TransitionCounts | None
    histograms: dict[str, SparseHistogram]
    damage_sums: np.ndarray
    totals: dict[str, float]
    mass_segments: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    road_load_moments: list[SegmentMoments] = field(default_factory=list)
    """Each mass segment's additive moments for the truck's shared road-load fit (`fleet.road_load`)."""
    road_load_logs: list[dict] = field(default_factory=list)
    """Each log's own c_r and c_d·A (its joint fit alone), beside the truck's shared ones."""

    def __add__(self, other: "FleetStatistics") -> "FleetStatistics":
        if not isinstance(other, FleetStatistics):
            return NotImplemented
        counts = (self.counts if other.counts is None else other.counts if self.counts is None
                  else self.counts + other.counts)
        histograms = {name: self.histograms[name] + other.histograms[name] for name in self.histograms}
        return FleetStatistics(self.logs + other.logs, counts, histograms, self.damage_sums + other.damage_sums,
                               {key: self.totals[key] + other.totals[key] for key in TOTALS},
                               self.mass_segments + other.mass_segments, self.notes + other.notes,
                               self.road_load_moments + other.road_load_moments,
                               self.road_load_logs + other.road_load_logs)

    def damage_equivalent_torque_nm(self) -> dict[int, float]:
        """S_eq(k) = (Σ nᵢ Sᵢᵏ / N_eq)^(1/k) [Nm], N_eq = 1 cycle per second of loads (`analysis.loads`)."""
        n_eq = self.totals["loads_s"] * EQUIVALENT_FREQUENCY_HZ
        return {k: float((d / n_eq) ** (1.0 / k)) if n_eq > 0 else 0.0
                for k, d in zip(WOEHLER_EXPONENTS, self.damage_sums)}

    def same_as(self, other: "FleetStatistics") -> bool:
        """Bit-identical counts, histograms, damage sums, totals and mass segments."""
        if self.logs != other.logs or (self.counts is None) != (other.counts is None):
            return False
        if self.counts is not None and not _counts_equal(self.counts, other.counts):
            return False
        return (self.histograms.keys() == other.histograms.keys()
                and all(h.equals(other.histograms[n]) for n, h in self.histograms.items())
                and np.array_equal(self.damage_sums, other.damage_sums) and self.totals == other.totals
                and _as_json(self.mass_segments) == _as_json(other.mass_segments)
                and _as_json(self.road_load_logs) == _as_json(other.road_load_logs)
                and len(self.road_load_moments) == len(other.road_load_moments)
                and all(np.array_equal(a.blocks, b.blocks) for a, b in zip(self.road_load_moments,
                                                                           other.road_load_moments)))


def _as_json(value) -> str:
    return json.dumps(value, sort_keys=True, default=jsonable)


def _counts_equal(a: TransitionCounts, b: TransitionCounts) -> bool:
    arrays = ("from_key", "to_key", "count", "moments", "start_key", "start_count")
    return (a.widths == b.widths and all(np.array_equal(getattr(a, n), getattr(b, n)) for n in arrays)
            and (a.n_samples, a.n_dropped, a.n_closed) == (b.n_samples, b.n_dropped, b.n_closed))


def sum_statistics(parts: list[FleetStatistics]) -> FleetStatistics:
    """Sum in the order given (the caller sorts by path, so floating-point sums never depend on
    which worker finished first)."""
    if not parts:
        raise ValueError("nothing to sum")
    total = parts[0]
    for part in parts[1:]:
        total = total + part
    return total


def load_histograms(signals: pd.DataFrame, vehicle: Vehicle, bins: LoadBins) -> tuple[dict, np.ndarray, dict]:
    """Wheel-load histograms [s or cycles], damage sums per Wöhler exponent and load totals of one
    log, on ``bins.period_s`` means (rows without mass or other inputs are left out; the mass
    missing at stops is filled as the chain counts it, `with_mass_at_stops`, so the group's cycle
    target stands at the stops its walks stand at)."""
    frame = signals[[c for c in (*LOAD_COLUMNS, "valid") if c in signals.columns]]
    if set(LOAD_COLUMNS) - set(frame.columns):
        frame = frame.iloc[:0].reindex(columns=[*LOAD_COLUMNS, "valid"])
    frame = with_mass_at_stops(frame)
    loads = loads_of(resample_mean(frame, bins.period_s) if len(frame) else frame, vehicle)
    durations = loads["duration_s"].to_numpy()
    histograms = {f"time_at_level_{q}": SparseHistogram.of({q: loads[q]}, {q: getattr(bins, q)}, durations)
                  for q in QUANTITIES}
    histograms["residence_speed_torque_s"] = SparseHistogram.of(
        {"wheel_speed_rpm": loads["wheel_speed_rpm"], "wheel_torque_nm": loads["wheel_torque_nm"]},
        {"wheel_speed_rpm": bins.residence_speed_rpm, "wheel_torque_nm": bins.residence_torque_nm}, durations)
    torque = loads["wheel_torque_nm"].to_numpy()
    cycles = rainflow_cycles(torque)
    histograms["rainflow_range_mean_counts"] = SparseHistogram.of(
        {"range_nm": cycles["range"], "mean_nm": cycles["mean"]},
        {"range_nm": bins.rainflow_nm, "mean_nm": bins.rainflow_nm}, cycles["count"])
    histograms["level_crossings_torque"] = crossing_histogram(torque, bins.wheel_torque_nm)
    histograms["wheel_power_levels_s"] = SparseHistogram.of({"wheel_power_w": loads["wheel_power_w"]},
                                                            {"wheel_power_w": bins.power_level_w}, durations)
    ranges, counts = cycles["range"].to_numpy(float), cycles["count"].to_numpy(float)
    damage = np.array([float(np.sum(counts * ranges ** k)) for k in WOEHLER_EXPONENTS])
    power = loads["wheel_power_w"].to_numpy()
    totals = {"loads_s": float(durations.sum()), "rainflow_cycles": float(counts.sum()),
              "loads_distance_km": float(np.sum(loads["speed_mps"].to_numpy(float) * durations)) / 1000.0,
              "positive_wheel_energy_kwh": float(np.sum(np.clip(power, 0, None) * durations)) / 3.6e6,
              "negative_wheel_energy_kwh": float(np.sum(np.clip(power, None, 0) * durations)) / 3.6e6}
    return histograms, damage, totals


def crossing_histogram(torque: np.ndarray, width: float) -> SparseHistogram:
    """Upward crossings of the torque levels k·width spanned by the data (key k)."""
    finite = torque[np.isfinite(torque)]
    if finite.size < 2:
        return SparseHistogram.empty(("level_nm",), (width,))
    k = np.arange(np.ceil(finite.min() / width), np.floor(finite.max() / width) + 1).astype(np.int64)
    counts = level_crossings(torque, k * width).astype(float)
    keep = counts > 0
    return SparseHistogram(("level_nm",), (float(width),), k[keep].reshape(-1, 1), counts[keep])


def _time_totals(signals: pd.DataFrame) -> dict:
    time = signals["time_s"].to_numpy(float)
    valid = signals["valid"].fillna(False).to_numpy(bool) if "valid" in signals.columns else np.ones(len(time), bool)
    durations = sample_durations_s(time, valid)
    speed = signals["speed_mps"].to_numpy(float)
    moving = np.nan_to_num(speed, nan=0.0) > STANDING_MPS
    mass = signals["mass_kg"].to_numpy(float) if "mass_kg" in signals.columns else np.full(len(time), np.nan)
    totals = {"duration_s": float(time[-1] - time[0]) if len(time) else 0.0, "valid_s": float(durations.sum()),
              "driving_s": float(durations[moving].sum()),
              "distance_km": float(np.nansum(speed * durations)) / 1000.0,
              "mass_known_s": float(durations[np.isfinite(mass)].sum()), "fuel_l": 0.0, "fuel_logged_s": 0.0}
    if "fuel_rate_lph" in signals.columns:
        fuel = signals["fuel_rate_lph"].to_numpy(float)
        logged = np.isfinite(fuel)
        totals["fuel_l"] = float(np.sum(fuel[logged] * durations[logged])) / 3600.0
        totals["fuel_logged_s"] = float(durations[logged].sum())
    return totals


def log_statistics(name: str, signals: pd.DataFrame, summary: dict, vehicle: Vehicle,
                   widths: ClassWidths | None = None, bins: LoadBins | None = None) -> FleetStatistics:
    """The additive statistics of one log's signals (after the mass stage) and its run summary."""
    bins = bins or LoadBins()
    notes = []
    try:
        counts = count_transitions(signals, widths or ClassWidths())
    except CountingError as exc:
        counts = None
        notes.append(f"{name}: no transition counts ({exc})")
    histograms, damage, load_totals = load_histograms(signals, vehicle, bins)
    if load_totals["loads_s"] == 0:
        notes.append(f"{name}: no wheel loads (no sample with speed, acceleration, gradient and mass together)")
    segments = [{"log": name, **segment} for segment in summary.get("mass", {}).get("segments", [])]
    totals = {**_time_totals(signals), **load_totals}
    road_load = summary.get("mass", {}).get("road_load", {})
    own = [{"log": name, **{key: road_load[key] for key in ("rolling_resistance_coefficient", "drag_area_m2",
                                                            "torque_gain") if key in road_load}}] if road_load else []
    return FleetStatistics([name], counts, histograms, damage, {key: totals[key] for key in TOTALS}, segments, notes,
                           road_load_logs=own)
