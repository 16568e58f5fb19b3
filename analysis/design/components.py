"""Component scaling: machine, inverter, gearbox or e-axle, battery, from a candidate's few numbers.

Scaling laws (docs/design.md, "Components"):
- machine: one reference map in per-unit speed (of base speed) and torque (of peak torque), scaled
  linearly in both axes (ADVISOR's and FASTSim's linear scaling: efficiency unchanged with size);
  base speed = maximum speed / constant-power speed ratio; peak torque = peak power / base speed;
  continuous rating a fixed share of the peak.
- inverter: its phase current caps the machine's torque and power in proportion,
  P_inv = sqrt(3) (U_dc / sqrt(2)) I cos(phi) (sine-triangle/SVPWM limit of the fundamental).
- gearbox: per-mesh efficiency; e-axle ratios are total ratios, central ratios sit before the axle.
- battery: energy is the variable; internal resistance inversely proportional to energy at a fixed
  voltage (more cells in parallel), peak power a C-rate of the energy.
Cost [EUR] and mass [kg] figures per kW, kVA and kWh are the cited ones of docs/design.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONSTANT_POWER_SPEED_RATIO = 3.0
"""Maximum / base speed of the reference permanent-magnet machine [-]."""
CONTINUOUS_SHARE = 0.6
"""Continuous / peak rating of torque and power [-] (eActros 600: 400/600 kW = 0.67; docs/design.md)."""
POWER_FACTOR = 0.85
"""cos(phi) of the machine at its inverter's current limit [-]."""
MESH_EFFICIENCY = 0.985
"""One spur/helical gear mesh [-]."""
AXLE_EFFICIENCY = 0.96
"""Hypoid final drive of a central driveline [-]."""
BATTERY_C_RATE = 1.5
"""Peak discharge power / nominal energy [1/h] of a truck pack (LFP, docs/design.md)."""
RESISTANCE_ENERGY_OHM_KWH = 16.0
"""Internal resistance x energy [ohm kWh] at the pack voltage, when the vehicle file gives none."""
SPEED_RANGE_RPM = {"central": (2_500.0, 6_000.0), "e-axle": (8_000.0, 14_000.0)}
"""Maximum machine speed the search may choose per topology [rpm]."""
SPEEDS = {"central": (2, 4), "e-axle": (1, 2)}
"""Number of gears per topology (fewest, most)."""
TOPOLOGIES = ("central", "e-axle")

# --- cost [EUR] and mass [kg] figures (sources in docs/design.md)
EUR_PER_MACHINE, KG_PER_MACHINE = 1_000.0, 25.0
"""Fixed share of each machine (housing, bearings, resolver, cooling, its inverter's case) [EUR, kg; choice]."""
EUR_PER_KW_MACHINE = 12.0
EUR_PER_KVA_INVERTER = 6.0
EUR_GEARBOX_BASE, EUR_PER_GEAR = 1_500.0, 600.0
EUR_PER_KWH_BATTERY = 150.0
KG_PER_KW_MACHINE = 0.45
KG_PER_KVA_INVERTER = 0.06
KG_GEARBOX = {"central": (180.0, 45.0), "e-axle": (120.0, 40.0)}
"""Gearbox mass: base and per gear [kg] (an e-axle's housing replaces the central axle's)."""
KG_PER_KWH_BATTERY = 6.0


@dataclass(frozen=True)
class Candidates:
    """A batch of concepts, one entry per candidate (arrays of equal length)."""

    topology: np.ndarray
    """0 central machine with gearbox before the axle, 1 e-axle."""
    machines: np.ndarray
    """1 or 2 identical machines on the same ratios."""
    speeds: np.ndarray
    """Number of gears."""
    machine_power_w: np.ndarray
    """Peak power of one machine [W]."""
    machine_max_speed_rpm: np.ndarray
    low_ratio: np.ndarray
    """Total ratio machine -> wheel in the lowest gear [-]."""
    top_ratio: np.ndarray
    """Total ratio in the top gear [-] (the gears between are geometric)."""
    inverter_current_a: np.ndarray
    """Phase current limit of one machine's inverter [A rms]."""
    battery_energy_j: np.ndarray

    def __len__(self) -> int:
        return len(self.topology)

    def take(self, index) -> "Candidates":
        return Candidates(**{k: np.asarray(v)[index] for k, v in self.__dict__.items()})


def reference_map(n_speed: int = 25, n_torque: int = 21) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference machine map: per-unit speed (of base speed) and torque (of peak torque) grids and
    efficiency [-] from a loss model in per-unit of rated power: copper k_cu t^2 (+ field-weakening
    current k_fw (w-1)^2 above base speed), iron k_fe w^1.5, friction and windage k_w w^3.
    Calibrated to a 96-97 % peak as published for truck PMSMs (docs/design.md)."""
    w = np.linspace(0.0, CONSTANT_POWER_SPEED_RATIO, n_speed)
    t = np.linspace(0.0, 1.0, n_torque)
    ww, tt = np.meshgrid(w, t, indexing="ij")
    t_avail = np.minimum(1.0, 1.0 / np.maximum(ww, 1e-9))
    t_eff = np.minimum(tt, t_avail)
    copper = 0.030 * t_eff ** 2 * (1.0 + 0.25 * np.clip(ww - 1.0, 0.0, None) ** 2)
    iron = 0.008 * ww ** 1.5
    windage = 0.0015 * ww ** 3 / CONSTANT_POWER_SPEED_RATIO ** 2
    out = ww * t_eff
    with np.errstate(invalid="ignore", divide="ignore"):
        eff = out / (out + copper + iron + windage + 0.002)
    eff[~np.isfinite(eff)] = 0.0
    floor = 0.5
    eff = np.clip(eff, floor, 0.99)
    eff[:, 0] = eff[:, 1]
    eff[0, :] = eff[1, :]
    return w, t, eff


@dataclass(frozen=True)
class Sizing:
    """Derived component figures per candidate (arrays): the totals of all machines."""

    peak_torque_nm: np.ndarray
    peak_power_w: np.ndarray
    continuous_torque_nm: np.ndarray
    continuous_power_w: np.ndarray
    max_speed_radps: np.ndarray
    base_speed_radps: np.ndarray
    ratios: np.ndarray
    """(candidates, 4) total ratios, lowest gear first, NaN beyond the candidate's gears."""
    driveline_efficiency: np.ndarray
    battery_resistance_ohm: np.ndarray
    battery_peak_power_w: np.ndarray
    inverter_power_w: np.ndarray
    cost_eur: np.ndarray
    mass_kg: np.ndarray


def size(c: Candidates, voltage_v: float, resistance_ohm_kwh: float = RESISTANCE_ENERGY_OHM_KWH) -> Sizing:
    """Scale every component of the candidates (laws in the module docstring)."""
    n = len(c)
    base = 2.0 * np.pi * c.machine_max_speed_rpm / 60.0 / CONSTANT_POWER_SPEED_RATIO
    inverter_w = np.sqrt(3.0) * voltage_v / np.sqrt(2.0) * c.inverter_current_a * POWER_FACTOR
    capped = np.minimum(1.0, inverter_w / c.machine_power_w)
    power = c.machines * c.machine_power_w * capped
    torque = c.machines * c.machine_power_w / base * capped
    ratios = np.full((n, 4), np.nan)
    for k in range(n):
        s = int(c.speeds[k])
        ratios[k, :s] = (np.geomspace(c.low_ratio[k], c.top_ratio[k], s) if s > 1 else [c.top_ratio[k]])
    central = c.topology == 0
    meshes = np.where(central, 2.0, np.where(c.speeds > 1, 3.0, 2.0))
    efficiency = MESH_EFFICIENCY ** meshes * np.where(central, AXLE_EFFICIENCY, 1.0)
    kwh = c.battery_energy_j / 3.6e6
    kva = c.machines * inverter_w / POWER_FACTOR / 1000.0
    gearbox_eur = EUR_GEARBOX_BASE + EUR_PER_GEAR * c.speeds
    kg_base = np.where(central, KG_GEARBOX["central"][0], KG_GEARBOX["e-axle"][0])
    kg_gear = np.where(central, KG_GEARBOX["central"][1], KG_GEARBOX["e-axle"][1])
    machine_kw = c.machines * c.machine_power_w / 1000.0
    cost = (EUR_PER_MACHINE * c.machines + EUR_PER_KW_MACHINE * machine_kw + EUR_PER_KVA_INVERTER * kva
            + gearbox_eur + EUR_PER_KWH_BATTERY * kwh)
    mass = (KG_PER_MACHINE * c.machines + KG_PER_KW_MACHINE * machine_kw + KG_PER_KVA_INVERTER * kva
            + kg_base + kg_gear * c.speeds + KG_PER_KWH_BATTERY * kwh)
    return Sizing(torque, power, CONTINUOUS_SHARE * torque, CONTINUOUS_SHARE * power,
                  2.0 * np.pi * c.machine_max_speed_rpm / 60.0, base, ratios, efficiency,
                  resistance_ohm_kwh / kwh, BATTERY_C_RATE * kwh * 1000.0, c.machines * inverter_w, cost, mass)


def wheel_force_limit_n(speed_mps, sizing: Sizing, wheel_radius_m: float) -> np.ndarray:
    """Largest traction force at the wheels [N], (candidates, speeds), over every gear: constant
    torque to base speed, constant power above, nothing beyond the maximum speed."""
    v = np.atleast_1d(np.asarray(speed_mps, float))[None, :, None]
    ratios = sizing.ratios[:, None, :]
    omega = np.maximum(v, 0.05) / wheel_radius_m * ratios
    torque = np.minimum(sizing.peak_torque_nm[:, None, None], sizing.peak_power_w[:, None, None] / omega)
    torque = np.where(omega <= sizing.max_speed_radps[:, None, None], torque, 0.0)
    force = torque * ratios * sizing.driveline_efficiency[:, None, None] / wheel_radius_m
    return np.nanmax(np.where(np.isnan(ratios), -np.inf, force), axis=2)
