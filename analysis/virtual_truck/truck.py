"""`drive`: a scenario, a vehicle and a seed in; ground truth and sensor streams out."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd

from ..errors import UserError
from ..vehicle import EXAMPLES, Vehicle, load_vehicle
from . import sensors as sensor_models
from .driver import OUTPUTS, simulate_kernel
from .disturbances import Accessories, accessories_schedule, engine_loads, head_wind_mps, trailer_change
from .realism import IDEAL, Realism
from .realism import realism_level as make_realism
from .road import Road
from .world import build_road
from .scenario import Scenario, ScenarioFileError
from .sensor_errors import apply_sensor_errors

SIM_STEP_S = 0.01
"""Internal simulation step [s] (100 Hz)."""
TRUTH_RATE_HZ = 10.0

TRUTH_COLUMNS = ("time_s", "distance_m", "speed_mps", "accel_mps2", "gradient_pct", "road_height_m",
                 "terrain_height_m", "mass_kg", "latitude_deg", "longitude_deg", "gear", "engine_speed_rpm",
                 "engine_torque_nm", "wheel_force_n", "brake_active", "shifting", "in_tunnel", "stop",
                 "clutch_slip", "fuel_cut")


@dataclass
class VirtualDrive:
    """One drive: the world (``road``), the 100 Hz ``states``, the 10 Hz ``truth`` and the
    ``sensors`` streams (each a DataFrame at its own rate, plus the constant
    ``engine_reference_torque_nm``)."""

    scenario: Scenario
    vehicle: Vehicle
    seed: int
    road: Road
    states: pd.DataFrame
    truth: pd.DataFrame
    sensors: dict
    realism: Realism = IDEAL
    injected: dict = field(default_factory=dict)
    """The sizes of every error injected into this drive (for the truth files)."""

    @property
    def duration_s(self) -> float:
        return float(self.truth["time_s"].iloc[-1])


def scenario_vehicle(scenario: Scenario) -> Vehicle:
    """The vehicle a scenario names (a shipped example or a file beside the scenario)."""
    name = scenario.vehicle
    return load_vehicle(name if name in EXAMPLES else scenario.base_dir / name)


def _masses(scenario: Scenario, vehicle: Vehicle, n_stops: int) -> tuple[float, np.ndarray]:
    payload = scenario.payload
    limit = vehicle.max_payload_kg
    for key, values in (("initial_kg", [payload.initial_kg]), ("after_stop_kg", payload.after_stop_kg)):
        if limit is not None and any(p > limit for p in values):
            raise ScenarioFileError(f"{scenario.name} [payload].{key}: above the vehicle's max_payload_kg "
                                    f"({limit:g} kg)")
    after = list(payload.after_stop_kg[:n_stops])
    while len(after) < n_stops:
        after.append(after[-1] if after else payload.initial_kg)
    return vehicle.curb_mass_kg + payload.initial_kg, vehicle.curb_mass_kg + np.asarray(after, float)


def simulate(scenario: Scenario, vehicle: Vehicle, road: Road, kernel=simulate_kernel,
             head_wind_mps: np.ndarray | None = None, after_stop_kg: np.ndarray | None = None,
             accessories: Accessories | None = None) -> pd.DataFrame:
    """The 100 Hz states of the drive (columns `driver.OUTPUTS` plus ``time_s``); ``head_wind_mps``
    on the road's grid (default calm), ``after_stop_kg`` total mass after each stop (default from
    the scenario's payload), ``accessories`` between engine and gearbox (default none, a driveline
    as nominal)."""
    if vehicle.engine is None or vehicle.total_ratios is None or vehicle.engine_reference_torque_nm is None:
        raise UserError(f"vehicle {vehicle.name}: the virtual truck needs [engine], gear_ratios, axle_ratio "
                        f"and engine_reference_torque_nm in the vehicle file")
    engine, driver = vehicle.engine, scenario.driver
    initial_mass, after = _masses(scenario, vehicle, len(road.stop_distance_m))
    after = after if after_stop_kg is None else np.asarray(after_stop_kg, float)
    wind = np.zeros(road.distance_m.shape) if head_wind_mps is None else np.asarray(head_wind_mps, float)
    vehicle_params = np.array([vehicle.rolling_resistance_coefficient, vehicle.drag_coefficient,
                               vehicle.frontal_area_m2, vehicle.wheel_radius_m, vehicle.driveline_efficiency])
    engine_params = np.array([vehicle.engine_reference_torque_nm, engine.idle_speed_rpm, engine.max_speed_rpm,
                              engine.max_power_w, engine.shift_up_speed_rpm, engine.shift_down_speed_rpm,
                              engine.shift_time_s])
    driver_params = np.array([driver.max_accel_mps2, driver.comfort_decel_mps2, driver.max_decel_mps2,
                              driver.speed_gain_per_s, driver.downhill_overspeed_kmh / 3.6])
    ratios = np.asarray(vehicle.total_ratios, float)
    accessories = Accessories.none(vehicle) if accessories is None else accessories
    expected_s = (np.sum(np.diff(road.distance_m) / np.maximum(road.target_speed_mps[1:], 1.0))
                  + road.stop_duration_s.sum() + road.initial_stop_s)
    max_steps = int(1.5 * expected_s / SIM_STEP_S) + 60_000
    for _ in range(4):
        out = np.zeros((len(OUTPUTS), max_steps))
        steps = kernel(SIM_STEP_S, max_steps, road.target_speed_mps, road.gradient_pct, wind, road.stop_distance_m,
                       road.stop_duration_s, after, road.initial_stop_s, initial_mass, vehicle_params,
                       engine_params, ratios, driver_params, accessories.compressor_w, accessories.fan_rated_w,
                       accessories.gear_efficiency, accessories.spin_loss_nm, out)
        if steps > 0:
            break
        max_steps *= 2
    else:
        raise UserError(f"scenario {scenario.name}: the virtual truck did not reach the end of the route "
                        f"(a grade too steep for {vehicle.name}?)")
    states = pd.DataFrame({name: out[j, :steps] for j, name in enumerate(OUTPUTS)})
    states.insert(0, "time_s", np.arange(steps) * SIM_STEP_S)
    for name in ("gear",):
        states[name] = states[name].astype(np.int16)
    for name in ("brake_active", "shifting", "clutch_slip", "stop", "fuel_cut"):
        states[name] = states[name].astype(bool)
    return states


def drive(scenario: Scenario, vehicle: Vehicle | None = None, seed: int = 0,
          realism: str | Realism | None = None, gust_seed: int | None = None) -> VirtualDrive:
    """Drive a scenario: deterministic for a seed (same seed, byte-identical outputs).

    ``realism``: a level name (``ideal``, ``typical``, ``harsh``) or a `Realism`; None takes the
    scenario's ``[realism]`` (ideal unless the file says otherwise). ``gust_seed``: the wind's
    gusts drawn from their own seed, everything else the drive ``seed`` draws (mean wind, trailer,
    accessories, sensor errors) as without it; None: from ``seed`` like the rest."""
    vehicle = vehicle if vehicle is not None else scenario_vehicle(scenario)
    level = scenario.realism if realism is None else make_realism(realism)
    road = build_road(scenario, seed, level)
    injected = {"realism": asdict(level), "seed": seed}
    if level.is_ideal:
        states = simulate(scenario, vehicle, road)
    else:
        states, more = _realistic_states(scenario, vehicle, road, level, seed, gust_seed)
        injected.update(more)
    distance = states["distance_m"].to_numpy()
    east, north = road.at(road.east_m, distance), road.at(road.north_m, distance)
    states["latitude_deg"], states["longitude_deg"] = road.latlon(east, north)
    states["road_height_m"] = road.at(road.height_m, distance)
    states["terrain_height_m"] = states["road_height_m"] + road.at(road.cover_m, distance)
    states["in_tunnel"] = road.at(road.in_tunnel.astype(float), distance) > 0.5
    states["curvature_per_m"] = road.at(road.curvature_per_m, distance)
    states["tunnel_depth_in_m"] = road.at(road.tunnel_depth_in_m, distance)
    step = int(round(1.0 / (TRUTH_RATE_HZ * SIM_STEP_S)))
    truth = states.iloc[::step][list(TRUTH_COLUMNS)].reset_index(drop=True)
    rng = np.random.default_rng(np.random.SeedSequence([scenario.terrain.seed, seed, 0x5E45]))
    streams = sensor_models.make_sensors(states, road, scenario, vehicle, rng)
    if not level.is_ideal:
        sensor_rng = np.random.default_rng(np.random.SeedSequence([scenario.terrain.seed, seed, 0x5E46]))
        injected.update(apply_sensor_errors(streams, states, road, scenario.sensors, level, sensor_rng))
    if level.torque_report == "indicated":
        injected.update(sensor_models.report_indicated_torque(streams["engine"], states, vehicle))
    return VirtualDrive(scenario, vehicle, seed, road, states, truth, streams, level, injected)


def _realistic_states(scenario: Scenario, vehicle: Vehicle, road: Road, level: Realism, seed: int,
                      gust_seed: int | None = None):
    """States with wind, a trailer change and the driveline's and auxiliaries' torque; and the sizes.

    Two passes: the first, without accessories, gives the times they run (the fan's "hot" rule
    reads its load); the second drives with them between engine and gearbox, and is the truth."""
    rng = np.random.default_rng(np.random.SeedSequence([scenario.terrain.seed, seed, 0x3EA1]))
    gust_rng = None if gust_seed is None else np.random.default_rng(
        np.random.SeedSequence([scenario.terrain.seed, seed, gust_seed, 0x6057]))
    wind, injected = head_wind_mps(road, level, rng, gust_rng)
    if gust_seed is not None:
        injected["gust_seed"] = gust_seed
    after = None
    if level.trailer_change:
        _, after = _masses(scenario, vehicle, len(road.stop_distance_m))
        after, more = trailer_change(after, road.stop_duration_s, vehicle.curb_mass_kg, vehicle.max_payload_kg, rng)
        injected.update(more)
    first = simulate(scenario, vehicle, road, head_wind_mps=wind, after_stop_kg=after)
    accessories = accessories_schedule(first, vehicle, level, rng)
    states = simulate(scenario, vehicle, road, head_wind_mps=wind, after_stop_kg=after, accessories=accessories)
    states["head_wind_mps"] = road.at(wind, states["distance_m"].to_numpy())
    columns, more = engine_loads(states, vehicle, level, accessories)
    for name, values in columns.items():
        states[name] = values
    injected.update(more)
    return states, injected

