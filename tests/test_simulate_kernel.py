"""The numba kernels against their Python run (``.py_func``) and closed forms."""

import numpy as np
import pandas as pd
import pytest
from scipy.interpolate import RegularGridInterpolator

from haulprofile.analysis.simulate import DriverSettings, distance_cycle, time_cycle
from haulprofile.analysis.simulate import kernel as K
from haulprofile.analysis.simulate.model import kernel_arguments, pack_parameters
from haulprofile.analysis.vehicle import load_vehicle


@pytest.fixture(scope="module")
def rigid():
    return load_vehicle("rigid-18t")


@pytest.fixture(scope="module")
def params(rigid):
    return pack_parameters(rigid, DriverSettings(), t_end_s=1e4)


def both(kernel):
    return [kernel, kernel.py_func]


@pytest.mark.parametrize("power_w", [-150_000.0, 0.0, 20_000.0, 400_000.0])
def test_battery_current_solves_terminal_power(params, power_w):
    u, r = params[K.P_OCV], params[K.P_RESISTANCE]
    expected = min(np.roots([r, -u, power_w]).real)
    for f in both(K.battery_current_a):
        current = f(power_w, params)
        assert current == pytest.approx(expected, rel=1e-12, abs=1e-9)
        assert u * current - current ** 2 * r == pytest.approx(power_w, rel=1e-9, abs=1e-6)


def test_battery_current_is_clipped_beyond_matched_load(params):
    u, r = params[K.P_OCV], params[K.P_RESISTANCE]
    for f in both(K.battery_current_a):
        assert f(u * u / (4 * r) * 2, params) == pytest.approx(u / (2 * r))


def test_machine_torque_limit_constant_torque_then_constant_power(params):
    corner = params[K.P_MAX_POWER] / params[K.P_MAX_TORQUE]
    for f in both(K.machine_torque_limit_nm):
        assert f(0.5 * corner, params) == params[K.P_MAX_TORQUE]
        assert f(1.5 * corner, params) == pytest.approx(params[K.P_MAX_POWER] / (1.5 * corner))
        assert f(params[K.P_MAX_SPEED] * 1.01, params) == 0.0


def test_bilinear_interpolation_matches_scipy():
    rng = np.random.default_rng(7)
    xs, ys = np.array([0.0, 100.0, 250.0, 420.0]), np.array([0.0, 500.0, 1500.0])
    table = rng.uniform(0.8, 0.97, (4, 3))
    reference = RegularGridInterpolator((xs, ys), table)
    for x, y in rng.uniform([0, 0], [420, 1500], (50, 2)):
        for f in both(K.interp_bilinear):
            assert f(x, y, xs, ys, table) == pytest.approx(reference([x, y])[0], rel=1e-12)
    for f in both(K.interp_bilinear):
        assert f(-5.0, 9000.0, xs, ys, table) == pytest.approx(table[0, 2])


def test_split_wheel_force_motoring_braking_and_limits(rigid, params):
    ratios = np.asarray(rigid.electric_powertrain.gear_ratios) * rigid.electric_powertrain.axle_ratio
    empty = (np.empty(0), np.empty(0), np.empty((0, 0)))
    r, eta = params[K.P_WHEEL_RADIUS], params[K.P_GEAR_EFF]
    speed = 10.0
    top_gear_force = K.machine_torque_limit_nm(speed / r * ratios[1], params) * ratios[1] * eta / r
    low_gear_force = K.machine_torque_limit_nm(speed / r * ratios[0], params) * ratios[0] * eta / r
    for f in both(K.split_wheel_force):
        assert f(5_000.0, speed, params, ratios, *empty) == (5_000.0, 0.0, 1, 0)
        trac, fric, gear, limited = f(0.5 * (top_gear_force + low_gear_force), speed, params, ratios, *empty)
        assert (gear, limited, fric) == (0, 0, 0.0)
        trac, fric, gear, limited = f(2 * low_gear_force, speed, params, ratios, *empty)
        assert trac == pytest.approx(max(low_gear_force, top_gear_force)) and limited == 1
        recup_force = params[K.P_MAX_RECUP] / (speed * eta)
        trac, fric, gear, limited = f(-80_000.0, speed, params, ratios, *empty)
        assert trac == pytest.approx(-recup_force, rel=1e-12)
        assert trac + fric == pytest.approx(-80_000.0)


HILLY = pd.DataFrame({"distance_m": [0, 10, 400, 900, 1200, 1210, 1800, 2000.0],
                      "target_speed_mps": np.array([0, 50, 70, 30, 0, 60, 40, 0]) / 3.6,
                      "gradient_pct": [0, 3.0, -4.0, 0.5, 0, 2.0, -1.0, 0],
                      "stop_time_s": [2, 0, 0, 0, 6.5, 0, 0, 1.0]})


@pytest.mark.parametrize("time_based", [False, True])
def test_run_kernel_python_and_numba_agree(rigid, time_based):
    settings = DriverSettings(time_step_s=0.5)
    if time_based:
        time = np.arange(0.0, 121.0, 2.0)
        frame = pd.DataFrame({"time_s": time, "speed_mps": 12 * np.sin(np.pi * time / 120) ** 2,
                              "gradient_pct": np.linspace(-3, 3, len(time))})
        cycle = time_cycle(frame, 16_000.0)
    else:
        cycle = distance_cycle(HILLY, 16_000.0)
    args_numba = kernel_arguments(cycle, rigid, epto_power_w=(np.array([0.0, 60.0]), np.array([0.0, 9e3])),
                                  settings=settings)
    args_python = args_numba[:-1] + (np.empty_like(args_numba[-1]),)
    n_numba, n_python = K.run_kernel(*args_numba), K.run_kernel.py_func(*args_python)
    assert n_numba == n_python > 100
    np.testing.assert_allclose(args_numba[-1][:, :n_numba], args_python[-1][:, :n_python], rtol=1e-9, atol=1e-6)
    if not time_based:
        standstill = args_numba[-1][K.C_STATE, :n_numba] == K.STANDSTILL
        assert standstill.sum() * 0.5 == pytest.approx(2 + 6.5 + 1.0)


def test_full_out_array_and_time_budget_are_reported(rigid):
    args = kernel_arguments(distance_cycle(HILLY, 16_000.0), rigid)
    assert K.run_kernel(*args[:-1], np.empty((K.N_COLUMNS, 10))) == -1
    short = args[13].copy()
    short[K.P_T_END] = 5.0
    assert K.run_kernel(*args[:13], short, *args[14:]) == -2


@pytest.mark.parametrize("compiled", [True, False])
def test_cursor_interpolation_equals_the_binary_search_bit_for_bit(compiled):
    """The time-based run looks values up with a cursor that only moves forward; it must find what
    ``_interp`` (searchsorted) finds, repeated knots and queries outside the table included."""
    rng = np.random.default_rng(29)
    interp = K._interp if compiled else K._interp.py_func
    cursor = K._interp_cursor if compiled else K._interp_cursor.py_func
    for n in (1, 2, 7, 300):
        xs = np.sort(np.round(rng.uniform(0, 100, n), 1))
        ys = rng.normal(size=n)
        queries = np.sort(np.concatenate([rng.uniform(-5, 105, 400), xs, xs + 1e-12]))
        at = 0
        for x in queries:
            value, at = cursor(x, xs, ys, at)
            assert value == interp(x, xs, ys)
