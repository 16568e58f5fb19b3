"""Realism levels of the virtual truck: how far its world and sensors are from ideal.

``ideal`` is the original world (terrain built to lie ``cut_fill`` above the road, sensors with
white noise and constant biases) and reproduces its figures exactly. ``typical`` and ``harsh``
build the terrain first and engineer the road into it, write the DEM from the terrain with the
errors real DEMs have, and give every sensor the errors real ones have. The sizes and their
sources are in ``docs/virtual-truck.md``; every size can be overridden (``[realism]`` table of a
scenario file, or keyword arguments of `realism`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from ..errors import UserError

LEVELS = ("ideal", "typical", "harsh")


@dataclass(frozen=True)
class Realism:
    """Error sizes of one level (all >= 0; 0 switches the error off)."""

    level: str = "ideal"
    terrain_first: bool = False
    """Terrain is a fractal surface of its own and the road is engineered into it."""
    # DEM (vertical in metres, horizontal in cells)
    dem_correlated_m: float = 0.0
    dem_correlation_m: float = 0.0
    dem_noise_m: float = 0.0
    dem_canopy_m: float = 0.0
    dem_building_m: float = 0.0
    dem_shift_cells: float = 0.0
    dem_void_fraction: float = 0.0
    # IMU
    imu_mount_pitch_deg: float = 0.0
    imu_temp_drift_mps2_per_k: float = 0.0
    # barometer
    baro_front_pa: float = 0.0
    baro_cab_transient_pa: float = 0.0
    # wheel speed, GPS
    wheel_scale_pct: float = 0.0
    gps_urban_factor: float = 0.0
    gps_outages_per_h: float = 0.0
    # engine torque report, driveline, auxiliaries
    torque_gain_pct: float = 0.0
    torque_offset_pct: float = 0.0
    driveline_gear_spread: float = 0.0
    driveline_spin_loss_pct: float = 0.0
    aux_compressor_kw: float = 0.0
    aux_fan_kw: float = 0.0
    aux_pto_kw: float = 0.0
    parasitic_estimate_error_pct: float = 0.0
    """Per-drive error of the engine controller's estimate of what the compressor and the fan take
    (EEC3 SPN 2978), uniform within ± this, drawn for each of the two."""
    parasitic_report: str = "estimate"
    """What the engine sends as SPN 2978: ``estimate``, ``zero`` (a constant 0 %) or ``not available``."""
    torque_report: str = "net"
    """The form of the engine's torque report (SPN 513): ``net`` of its friction (negative in a fuel
    cut), or ``indicated`` as J1939-71 defines it (friction included, 0 % in a fuel cut)."""
    # environment and load
    wind_mps: float = 0.0
    wind_gust_mps: float = 0.0
    trailer_change: bool = False

    @property
    def is_ideal(self) -> bool:
        return self == IDEAL


IDEAL = Realism()

TYPICAL = Realism(
    level="typical", terrain_first=True,
    dem_correlated_m=3.0, dem_correlation_m=1500.0, dem_noise_m=1.5, dem_canopy_m=9.6, dem_building_m=4.0,
    dem_shift_cells=0.5, dem_void_fraction=0.002,
    imu_mount_pitch_deg=1.0, imu_temp_drift_mps2_per_k=0.5e-3 * 9.80665,
    baro_front_pa=120.0, baro_cab_transient_pa=30.0,
    wheel_scale_pct=1.5, gps_urban_factor=2.5, gps_outages_per_h=1.0,
    torque_gain_pct=3.0, torque_offset_pct=1.0, driveline_gear_spread=0.01, driveline_spin_loss_pct=0.5,
    aux_compressor_kw=6.0, aux_fan_kw=8.0, aux_pto_kw=10.0, parasitic_estimate_error_pct=15.0,
    wind_mps=4.0, wind_gust_mps=1.5, trailer_change=True)

HARSH = Realism(
    level="harsh", terrain_first=True,
    dem_correlated_m=6.0, dem_correlation_m=800.0, dem_noise_m=3.0, dem_canopy_m=15.0, dem_building_m=8.0,
    dem_shift_cells=1.0, dem_void_fraction=0.01,
    imu_mount_pitch_deg=3.0, imu_temp_drift_mps2_per_k=1.5e-3 * 9.80665,
    baro_front_pa=200.0, baro_cab_transient_pa=80.0,
    wheel_scale_pct=3.0, gps_urban_factor=5.0, gps_outages_per_h=3.0,
    torque_gain_pct=6.0, torque_offset_pct=3.0, driveline_gear_spread=0.02, driveline_spin_loss_pct=1.0,
    aux_compressor_kw=10.0, aux_fan_kw=20.0, aux_pto_kw=20.0, parasitic_estimate_error_pct=30.0,
    wind_mps=8.0, wind_gust_mps=3.0, trailer_change=True)

PRESETS = {"ideal": IDEAL, "typical": TYPICAL, "harsh": HARSH}
PARASITIC_REPORTS = ("estimate", "zero", "not available")
TORQUE_REPORTS = ("net", "indicated")
CHOICES = {"parasitic_report": PARASITIC_REPORTS, "torque_report": TORQUE_REPORTS}
"""The fields that name one of a few forms, with their choices."""

SIZE_FIELDS = tuple(f.name for f in fields(Realism) if f.type in ("float", float))
_UPPER = {"dem_shift_cells": 3.0, "dem_void_fraction": 0.5, "imu_mount_pitch_deg": 10.0,
          "wheel_scale_pct": 20.0, "torque_gain_pct": 30.0, "torque_offset_pct": 30.0,
          "driveline_gear_spread": 0.2, "driveline_spin_loss_pct": 10.0, "parasitic_estimate_error_pct": 100.0}


def realism_level(level: str | Realism = "ideal", **sizes) -> Realism:
    """The preset ``level`` with some error sizes replaced; a one-line `UserError` for an unknown
    level or size name, a negative size, or one beyond its sensible maximum."""
    if isinstance(level, Realism):
        base = level
    elif level in PRESETS:
        base = PRESETS[level]
    else:
        raise UserError(f"unknown realism level {level!r} (known: {', '.join(LEVELS)})")
    for name, value in sizes.items():
        if name not in SIZE_FIELDS and name not in ("terrain_first", "trailer_change") and name not in CHOICES:
            raise UserError(f"realism: unknown error size {name!r} (known: {', '.join(SIZE_FIELDS)})")
        if name in CHOICES:
            if value not in CHOICES[name]:
                raise UserError(f"realism.{name}: expected one of {', '.join(CHOICES[name])}, got {value!r}")
        elif name in SIZE_FIELDS:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
                raise UserError(f"realism.{name}: expected a number, got {value!r}")
            if value < 0:
                raise UserError(f"realism.{name}: error sizes cannot be negative, got {value:g}")
            if value > _UPPER.get(name, 10_000.0):
                raise UserError(f"realism.{name}: {value:g} is beyond the sensible maximum "
                                f"{_UPPER.get(name, 10_000.0):g}")
            sizes[name] = float(value)
        elif not isinstance(value, bool):
            raise UserError(f"realism.{name}: expected true or false, got {value!r}")
    return replace(base, **sizes) if sizes else base
