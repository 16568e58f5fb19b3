"""Longitudinal simulation of the target battery-electric truck (physics.md, simulation section).

Public: `simulate_cycle`, `read_cycle`, `distance_cycle`, `time_cycle`, `DriverSettings`; the
pipeline's stage is `analysis.simulate.stage.simulate_stage`.
"""

from __future__ import annotations

from .cycle import SimCycle, SimulationInputError, default_mass_kg, distance_cycle, read_cycle, time_cycle
from .model import DriverSettings, SimulationResult, simulate_cycle

__all__ = ["DriverSettings", "SimCycle", "SimulationInputError", "SimulationResult", "default_mass_kg",
           "distance_cycle", "read_cycle", "simulate_cycle", "time_cycle"]
