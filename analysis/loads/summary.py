"""Collectives of one drive on shared bins, and how well a generated cycle represents the
measured drive for the powertrain (as numbers)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .collectives import (EQUIVALENT_FREQUENCY_HZ, QUANTITIES, damage_equivalent_range, level_crossings,
                          level_edges, rainflow_cycles, rainflow_matrix, residence_matrix, time_at_level)

N_LEVEL_BINS = 40
N_MATRIX_BINS = 20
TIME_SHARES = (0.05, 0.5, 0.95)


@dataclass
class Collectives:
    """Every collective of one drive [s, counts, Nm]."""

    name: str
    duration_s: float
    distance_km: float
    edges: dict
    time_at_level: dict
    residence_s: np.ndarray
    rainflow: pd.DataFrame
    rainflow_counts: np.ndarray
    crossing_levels_nm: np.ndarray
    crossings: np.ndarray
    damage_equivalent_torque_nm: dict
    positive_wheel_energy_kwh: float
    time_quantiles: dict


def shared_edges(*drives: pd.DataFrame) -> dict:
    """Bins spanning all drives: level bins per quantity, speed x torque bins, rainflow range x mean bins."""
    edges = {q: level_edges(*[d[q] for d in drives], n_bins=N_LEVEL_BINS) for q in QUANTITIES}
    edges["residence_speed_rpm"] = level_edges(*[d["wheel_speed_rpm"] for d in drives], n_bins=N_MATRIX_BINS)
    edges["residence_torque_nm"] = level_edges(*[d["wheel_torque_nm"] for d in drives], n_bins=N_MATRIX_BINS)
    span = edges["residence_torque_nm"][-1] - edges["residence_torque_nm"][0]
    edges["rainflow_range_nm"] = np.linspace(0.0, span, N_MATRIX_BINS + 1)
    edges["rainflow_mean_nm"] = edges["residence_torque_nm"]
    return edges


def compute(loads: pd.DataFrame, name: str, edges: dict) -> Collectives:
    """All collectives of one drive (``analysis.loads.collectives.wheel_loads`` output)."""
    durations = loads["duration_s"].to_numpy()
    duration_s = float(durations.sum())
    torque = loads["wheel_torque_nm"].to_numpy()
    cycles = rainflow_cycles(torque)
    levels = np.asarray(edges["wheel_torque_nm"], float)
    dets = damage_equivalent_range(cycles, duration_s * EQUIVALENT_FREQUENCY_HZ)
    distance_km = float(np.sum(loads["speed_mps"].to_numpy() * durations)) / 1000.0
    power = loads["wheel_power_w"].to_numpy()
    return Collectives(
        name=name, duration_s=duration_s, distance_km=distance_km, edges=edges,
        time_at_level={q: time_at_level(loads[q], durations, edges[q]) for q in QUANTITIES},
        residence_s=residence_matrix(loads["wheel_speed_rpm"], torque, durations,
                                     edges["residence_speed_rpm"], edges["residence_torque_nm"]),
        rainflow=cycles,
        rainflow_counts=rainflow_matrix(cycles, edges["rainflow_range_nm"], edges["rainflow_mean_nm"]),
        crossing_levels_nm=levels, crossings=level_crossings(torque, levels),
        damage_equivalent_torque_nm=dets,
        positive_wheel_energy_kwh=float(np.sum(np.clip(power, 0, None) * durations)) / 3.6e6,
        time_quantiles={q: {share: time_quantile(loads[q].to_numpy(), durations, share) for share in TIME_SHARES}
                        for q in QUANTITIES})


def summary(c: Collectives) -> dict:
    """JSON-able headline numbers of one drive."""
    return {
        "duration_s": c.duration_s,
        "distance_km": c.distance_km,
        "rainflow_cycles": float(c.rainflow["count"].sum()),
        "damage_equivalent_torque_range_nm": {str(k): v for k, v in c.damage_equivalent_torque_nm.items()},
        "positive_wheel_energy_kwh_per_km": c.positive_wheel_energy_kwh / c.distance_km if c.distance_km else None,
    }


def _share(matrix: np.ndarray) -> np.ndarray:
    total = matrix.sum()
    return matrix / total if total > 0 else matrix


def time_quantile(values: np.ndarray, durations_s: np.ndarray, share: float) -> float:
    """Level below which a drive spends the time ``share`` (time-weighted quantile)."""
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(durations_s[order])
    if len(cumulative) == 0 or cumulative[-1] <= 0:
        return float("nan")
    return float(values[order][min(np.searchsorted(cumulative, share * cumulative[-1]), len(values) - 1)])


def compare(measured: Collectives, generated: Collectives) -> pd.DataFrame:
    """How representative the generated cycle is for the powertrain: per criterion the measured
    and generated value and the relative deviation (generated / measured - 1)."""
    rows = []
    for k, value in measured.damage_equivalent_torque_nm.items():
        rows.append((f"damage-equivalent torque range k={k} [Nm]", value, generated.damage_equivalent_torque_nm[k]))
    for quantity, label in QUANTITIES.items():
        for share in TIME_SHARES:
            rows.append((f"{label} exceeded {1 - share:.0%} of the time", measured.time_quantiles[quantity][share],
                         generated.time_quantiles[quantity][share]))
    rows.append(("positive wheel energy [kWh/km]",
                 measured.positive_wheel_energy_kwh / measured.distance_km if measured.distance_km else np.nan,
                 generated.positive_wheel_energy_kwh / generated.distance_km if generated.distance_km else np.nan))
    rows.append(("rainflow cycles per hour", measured.rainflow["count"].sum() / measured.duration_s * 3600,
                 generated.rainflow["count"].sum() / generated.duration_s * 3600))
    frame = pd.DataFrame(rows, columns=["criterion", "measured", "generated"])
    with np.errstate(divide="ignore", invalid="ignore"):
        frame["relative_deviation"] = frame["generated"] / frame["measured"] - 1.0
    p, q = _share(measured.residence_s), _share(generated.residence_s)
    distance = 0.5 * float(np.abs(p - q).sum())
    uncovered = float(p[q == 0].sum())
    extra = pd.DataFrame([("speed x torque residence: total variation distance [-]", 0.0, distance, distance),
                          ("speed x torque residence: measured time in cells the cycle never visits [-]",
                           0.0, uncovered, uncovered)], columns=frame.columns)
    return pd.concat([frame, extra], ignore_index=True)
