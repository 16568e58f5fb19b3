"""An imperfect world around a virtual-truck drive, for the estimation tests: a DEM that is not
the road (spatially correlated error plus a bridge over a valley), barometric weather drift, an IMU
with a mounting pitch and a bias, an engine torque report with a gain error, and a vehicle file
whose rolling resistance is off. Every injected error is returned beside the data."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


G = 9.81


@dataclass(frozen=True)
class Imperfections:
    dem_error_rms_m: float = 5.0
    dem_correlation_m: float = 300.0
    bridge_at_m: float = 6000.0
    """Driven distance [m] of the bridge's middle."""
    bridge_length_m: float = 300.0
    bridge_depth_m: float = 20.0
    baro_drift_pa: float = 150.0
    """Sea-level pressure change over the drive [Pa] (1.5 hPa)."""
    imu_pitch_deg: float = 1.5
    imu_bias_mps2: float = 0.05
    torque_gain: float = 1.03
    rolling_resistance_factor: float = 1.15
    seed: int = 7


class ErroneousDem:
    """A DEM reader's ``height_m`` with a Gaussian random field (RMS, Gaussian correlation) and a
    valley under the bridge added to the true terrain."""

    def __init__(self, dem, truth, imperfections: Imperfections, n_waves: int = 300):
        self.dem = dem
        rng = np.random.default_rng(imperfections.seed)
        self.k = rng.normal(0, 1 / imperfections.dem_correlation_m, (n_waves, 2))
        self.phase = rng.uniform(0, 2 * np.pi, n_waves)
        self.amplitude = imperfections.dem_error_rms_m * np.sqrt(2 / n_waves)
        self.lat0 = float(truth["latitude_deg"].iloc[0])
        self.lon0 = float(truth["longitude_deg"].iloc[0])
        distance = truth["distance_m"].to_numpy()
        self.bridge_east, self.bridge_north = self._local(
            np.interp(imperfections.bridge_at_m, distance, truth["latitude_deg"].to_numpy()),
            np.interp(imperfections.bridge_at_m, distance, truth["longitude_deg"].to_numpy()))
        self.imperfections = imperfections

    def _local(self, lat, lon):
        north = np.radians(np.asarray(lat) - self.lat0) * 6_371_000.0
        east = np.radians(np.asarray(lon) - self.lon0) * 6_371_000.0 * np.cos(np.radians(self.lat0))
        return east, north

    def error_m(self, lat, lon):
        east, north = self._local(lat, lon)
        field = self.amplitude * np.cos(np.outer(east, self.k[:, 0]) + np.outer(north, self.k[:, 1])
                                        + self.phase).sum(axis=1)
        half = self.imperfections.bridge_length_m / 2
        radius = np.hypot(east - self.bridge_east, north - self.bridge_north)
        valley = np.where(radius < half, self.imperfections.bridge_depth_m * np.cos(np.pi * radius / (2 * half)) ** 2, 0)
        return field.reshape(np.shape(lat)) - valley.reshape(np.shape(lat))

    def height_m(self, lat, lon):
        return self.dem.height_m(lat, lon) + self.error_m(lat, lon)


def imperfect_signals(signals, imperfections: Imperfections = Imperfections()):
    """The signals table with barometric drift, IMU mounting pitch and bias, and torque gain error."""
    out = signals.copy()
    time_s = out["time_s"].to_numpy()
    out["pressure_pa"] = out["pressure_pa"] + imperfections.baro_drift_pa * (time_s - time_s[0]) / np.ptp(time_s)
    out["accel_x_mps2"] = (out["accel_x_mps2"] + G * np.sin(np.radians(imperfections.imu_pitch_deg))
                           + imperfections.imu_bias_mps2)
    out["engine_torque_nm"] = out["engine_torque_nm"] * imperfections.torque_gain
    return out


def mismatched_vehicle(vehicle, imperfections: Imperfections = Imperfections()):
    """The vehicle file as a datasheet gives it: rolling resistance off by the factor."""
    return replace(vehicle, rolling_resistance_coefficient=vehicle.rolling_resistance_coefficient
                   * imperfections.rolling_resistance_factor)


def on_grid(grid, truth, column):
    """A truth column [unit] at the grid's distances."""
    distance = truth["distance_m"].to_numpy()
    order = np.argsort(distance, kind="stable")
    return np.interp(grid["distance_m"].to_numpy(), distance[order], truth[column].to_numpy(dtype=float)[order])
