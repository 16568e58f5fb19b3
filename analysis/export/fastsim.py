"""A driving cycle as a FASTSim 3 cycle file (``fastsim.Cycle.from_file`` reads it).

FASTSim 3's cycle CSV has ``time_seconds``, ``speed_meters_per_second``, ``grade`` (rise over run,
a fraction, not %), ``pwr_max_charge_watts``, ``temp_amb_air_kelvin`` and ``pwr_solar_load_watts``.
It takes no distance or elevation column: FASTSim integrates them itself, distance as Σ v_i·Δt_i
(each step at the speed reached at its end) and elevation as Σ Δs_i·sin(atan(grade_i)) from
``init_elev_meters`` (which only its YAML/JSON form carries; a generated cycle has no absolute
height, so the CSV leaves FASTSim's default). So the grade of each step is what puts the cycle's
hills into FASTSim.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

COLUMNS = ("time_seconds", "speed_meters_per_second", "grade", "pwr_max_charge_watts", "temp_amb_air_kelvin",
           "pwr_solar_load_watts")
STANDARD_AIR_K = 295.15
"""FASTSim's own default ambient temperature (22 °C), used where the cycle has none [K]."""
KELVIN_AT_0C = 273.15


def fastsim_cycle(cycle: pd.DataFrame) -> pd.DataFrame:
    """FASTSim 3 cycle columns of a cycle with ``time_s`` [s], ``speed_mps`` [m/s] and (optional)
    ``gradient_pct`` [%] and ``air_temperature_c`` [°C]; missing values as 0 grade / 22 °C."""
    n = len(cycle)
    grade = (cycle["gradient_pct"].to_numpy(float) / 100.0 if "gradient_pct" in cycle.columns else np.zeros(n))
    air = (cycle["air_temperature_c"].to_numpy(float) + KELVIN_AT_0C if "air_temperature_c" in cycle.columns
           else np.full(n, STANDARD_AIR_K))
    return pd.DataFrame({
        "time_seconds": cycle["time_s"].to_numpy(float) - float(cycle["time_s"].iloc[0]),
        "speed_meters_per_second": np.nan_to_num(cycle["speed_mps"].to_numpy(float)),
        "grade": np.nan_to_num(grade),
        "pwr_max_charge_watts": np.zeros(n),
        "temp_amb_air_kelvin": np.where(np.isfinite(air), air, STANDARD_AIR_K),
        "pwr_solar_load_watts": np.zeros(n),
    }, columns=list(COLUMNS))


def write_fastsim_cycle(cycle: pd.DataFrame, path: str | Path) -> Path:
    path = Path(path)
    fastsim_cycle(cycle).to_csv(path, index=False, float_format="%.9g")
    return path
