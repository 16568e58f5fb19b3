"""The batched design kernel against the simulate stage's `simulate_cycle` on the same candidate,
through the concept's own vehicle file and efficiency map, and its reduction against NumPy."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.design import DesignOptions
from haulprofile.analysis.design import components as C
from haulprofile.analysis.design import kernel as DK
from haulprofile.analysis.design.evaluate import Evaluator
from haulprofile.analysis.design.result import MAP_FILE
from haulprofile.analysis.simulate import DriverSettings, distance_cycle, read_cycle, simulate_cycle, time_cycle
from haulprofile.analysis.vehicle import load_vehicle

TARGETS = {"design_grade_force_n": 1.0, "startability_force_n": 1.0, "top_speed_force_n": 1.0}


def hilly_cycle(mass_kg):
    distance = np.arange(0.0, 6000.0, 100.0)
    frame = pd.DataFrame({"distance_m": distance, "target_speed_mps": np.where(distance % 2000 < 100, 0.0, 16.0),
                          "stop_time_s": np.where(distance % 2000 < 100, 20.0, 0.0),
                          "gradient_pct": 4.0 * np.sin(distance / 700.0)})
    return distance_cycle(frame, mass_kg, "hilly")


def trace_cycle(mass_kg):
    time = np.arange(0.0, 400.0)
    speed = 18.0 * np.sin(np.pi * time / 399.0) ** 2
    return time_cycle(pd.DataFrame({"time_s": time, "speed_mps": speed, "gradient_pct": 2.0}), mass_kg, "trace")


@pytest.fixture(scope="module")
def setup():
    vehicle = load_vehicle("tractor-40t")
    options = DesignOptions(time_step_s=0.5, thermal_windows_s=(10.0, 60.0))
    cycles = [hilly_cycle(30_000.0), trace_cycle(30_000.0)]
    evaluator = Evaluator(vehicle, cycles, options, TARGETS, 100e3)
    x = np.array([[0.1, 0.2, 0.9, 0.6, 0.3, 0.2, 0.5, 0.6, 0.5],    # central, 1 machine, 4 gears
                  [0.9, 0.9, 0.1, 0.4, 0.7, 0.5, 0.5, 0.2, 0.2]])   # e-axle, 2 machines, 1 gear
    c = evaluator.decode(x)
    s = C.size(c, evaluator.voltage_v, evaluator.resistance)
    return vehicle, options, cycles, evaluator, c, s, evaluator.simulate(c, s)


def test_decoded_candidates_span_the_topologies(setup):
    _, _, _, _, c, _, _ = setup
    assert list(c.topology) == [0, 1] and list(c.machines) == [1, 2] and list(c.speeds) == [4, 1]


@pytest.mark.parametrize("index", [0, 1])
def test_batch_equals_simulate_cycle_through_the_concept_file(setup, tmp_path, index):
    """Concept -> vehicle file with its map CSV -> load_vehicle -> simulate_cycle: the same energy,
    distance and misses as the batched kernel (the cycles at the concept's heavier curb mass)."""
    import tomli_w

    from haulprofile.analysis.vehicle import load_vehicle as load

    vehicle, options, cycles, evaluator, c, s, metrics = setup
    speed, torque, eff = evaluator.machine_map(s, index)
    gs, gt = np.meshgrid(speed * 60.0 / (2 * np.pi), torque, indexing="ij")
    pd.DataFrame({"speed_rpm": gs.ravel(), "torque_nm": gt.ravel(), "efficiency": eff.ravel()}).to_csv(
        tmp_path / MAP_FILE, index=False)
    concept = evaluator.powertrain(c, s, index, MAP_FILE)
    ep = {k: (list(v) if isinstance(v, tuple) else v) for k, v in concept.electric_powertrain.__dict__.items()
          if v is not None}
    veh = {k: v for k, v in concept.__dict__.items()
           if k in ("name", "curb_mass_kg", "drag_coefficient", "frontal_area_m2", "rolling_resistance_coefficient",
                    "wheel_radius_m", "driveline_efficiency")}
    (tmp_path / "concept.toml").write_text(tomli_w.dumps({"vehicle": veh, "electric_powertrain": ep}))
    loaded = load(tmp_path / "concept.toml")
    delta = concept.curb_mass_kg - vehicle.curb_mass_kg
    assert delta == pytest.approx(evaluator.mass_delta_kg(s)[index])
    heavier = [hilly_cycle(30_000.0 + delta), trace_cycle(30_000.0 + delta)]
    settings = DriverSettings(time_step_s=options.time_step_s)
    traces = []
    for j, cycle in enumerate(heavier):
        result = simulate_cycle(cycle, loaded, settings=settings)
        traces.append(result.trace)
        energy_j = result.numbers["battery_terminal_energy_kwh"] * 3.6e6
        assert metrics[index, j, DK.M_ENERGY_J] == pytest.approx(energy_j, rel=1e-9)
        assert metrics[index, j, DK.M_DISTANCE_M] == pytest.approx(result.numbers["distance_km"] * 1000.0, rel=1e-12)
        assert metrics[index, j, DK.M_MISSED_S] == pytest.approx(
            float(((result.trace["traction_limited"] > 0)
                   & (result.trace["target_speed_mps"] - result.trace["speed_mps"] > 0.5)).sum()) * 0.5)
    reference = DK.batch_reference(traces, options.time_step_s, settings.speed_tolerance_mps, evaluator.window_steps)
    np.testing.assert_allclose(metrics[index, :, :DK.M_STALLED], reference[:, :DK.M_STALLED], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(metrics[index, :, DK.M_DURATION_S:], reference[:, DK.M_DURATION_S:], rtol=1e-6,
                               atol=1e-6)


def test_vecto_cycle_batch_matches_serial_runs():
    vehicle = load_vehicle("rigid-18t")
    options = DesignOptions(time_step_s=1.0, thermal_windows_s=(60.0,))
    from pathlib import Path

    cycle = read_cycle(Path(__file__).parent / "data" / "vecto-cycles" / "MunicipalUtility.vdri", vehicle)
    evaluator = Evaluator(vehicle, [cycle], options, TARGETS, 100e3)
    x = np.random.default_rng(3).random((6, 9))
    c = evaluator.decode(x)
    s = C.size(c, evaluator.voltage_v, evaluator.resistance)
    batch = evaluator.simulate(c, s)
    one_by_one = np.concatenate([evaluator.simulate(c.take([i]), s_i) for i, s_i in
                                 ((i, C.size(c.take([i]), evaluator.voltage_v, evaluator.resistance)) for i in range(6))])
    np.testing.assert_array_equal(np.nan_to_num(batch), np.nan_to_num(one_by_one))
