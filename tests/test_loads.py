"""Load collectives: rainflow via the `rainflow` package (ASTM E1049), time conservation, closed forms."""

import numpy as np
import pytest
import rainflow

from haulprofile.analysis import road_load
from haulprofile.analysis.loads.collectives import (damage_equivalent_range, level_crossings, level_edges, rainflow_cycles,
                                        rainflow_matrix, residence_matrix, sample_durations_s, time_at_level,
                                        wheel_loads)
from haulprofile.analysis.vehicle import load_vehicle

# ASTM E1049-85 (2017), section 5.4.4 / Fig. 6 example history and its rainflow count (range: cycles).
ASTM_E1049_HISTORY = [-2, 1, -3, 5, -1, 3, -4, 4, -2]
ASTM_E1049_COUNTS = {3: 0.5, 4: 1.5, 6: 0.5, 8: 1.0, 9: 0.5}


@pytest.fixture(scope="module")
def rigid():
    return load_vehicle("rigid-18t")


@pytest.fixture(scope="module")
def torque_series():
    rng = np.random.default_rng(42)
    time = np.arange(0.0, 600.0, 0.1)
    torque = 3000 * np.sin(2 * np.pi * time / 40) + np.cumsum(rng.normal(0, 60, len(time)))
    return time, torque


def test_rainflow_reproduces_astm_e1049_example():
    cycles = rainflow_cycles(ASTM_E1049_HISTORY)
    counted = cycles.groupby("range")["count"].sum().to_dict()
    assert counted == ASTM_E1049_COUNTS
    assert sorted(counted.items()) == rainflow.count_cycles(ASTM_E1049_HISTORY)


def test_rainflow_matrix_equals_package_counts(torque_series):
    _, torque = torque_series
    cycles = rainflow_cycles(torque)
    binsize = 250.0
    range_edges = np.arange(0.0, cycles["range"].max() + binsize, binsize)
    mean_edges = level_edges(torque, n_bins=15)
    matrix = rainflow_matrix(cycles, range_edges, mean_edges)
    assert matrix.sum() == pytest.approx(sum(c for _, c in rainflow.count_cycles(torque)))
    by_range = dict(rainflow.count_cycles(torque, binsize=binsize))
    expected = np.array([by_range.get((i + 1) * binsize, 0.0) for i in range(len(range_edges) - 1)])
    np.testing.assert_allclose(matrix.sum(axis=1), expected)


def test_histograms_conserve_total_time(rigid, torque_series):
    time, torque = torque_series
    speed = np.clip(12 + 8 * np.sin(time / 30), 0, None)
    valid = np.ones(len(time), bool)
    valid[1000:1200] = False
    loads = wheel_loads(time, speed, np.gradient(speed, time), np.sin(time / 50) * 4, 20_000.0, rigid, valid=valid)
    expected_s = (time[-1] - time[0]) - sample_durations_s(time)[~valid].sum()
    assert loads["duration_s"].sum() == pytest.approx(expected_s)
    for quantity in ("wheel_force_n", "wheel_torque_nm", "wheel_speed_rpm", "wheel_power_w"):
        narrow = level_edges(loads[quantity].iloc[:100], n_bins=10)
        assert time_at_level(loads[quantity], loads["duration_s"], narrow).sum() == pytest.approx(expected_s)
    matrix = residence_matrix(loads["wheel_speed_rpm"], loads["wheel_torque_nm"], loads["duration_s"],
                              level_edges(loads["wheel_speed_rpm"], n_bins=7), level_edges([-100, 100], n_bins=5))
    assert matrix.sum() == pytest.approx(expected_s)


def test_sample_durations_sum_to_span_on_irregular_time():
    time = np.cumsum(np.random.default_rng(3).uniform(0.05, 2.0, 500))
    assert sample_durations_s(time).sum() == pytest.approx(time[-1] - time[0])


def test_wheel_loads_match_closed_form_road_load(rigid):
    time = np.arange(0.0, 100.0, 0.5)
    speed = np.full(len(time), 22.0)
    loads = wheel_loads(time, speed, 0.0, 0.0, 18_000.0, rigid)
    force = 18_000.0 * road_load.G_MPS2 * rigid.rolling_resistance_coefficient + 0.5 * 1.2 * rigid.drag_coefficient \
        * rigid.frontal_area_m2 * 22.0 ** 2
    np.testing.assert_allclose(loads["wheel_force_n"], force)
    np.testing.assert_allclose(loads["wheel_torque_nm"], force * rigid.wheel_radius_m)
    np.testing.assert_allclose(loads["wheel_power_w"], force * 22.0)
    np.testing.assert_allclose(loads["wheel_speed_rpm"], 22.0 / rigid.wheel_radius_m * 60 / (2 * np.pi))


def level_crossings_reference(series, levels):
    counts = []
    for level in levels:
        counts.append(sum(1 for a, b in zip(series[:-1], series[1:]) if a < level <= b))
    return counts


def test_level_crossings_match_plain_loop(torque_series):
    _, torque = torque_series
    levels = np.array([2500.0, -3000.0, 0.0, 1e9, 117.3])
    assert list(level_crossings(torque[:3000], levels)) == level_crossings_reference(list(torque[:3000]), levels)
    assert list(level_crossings([0, 1, 0, 1], [0.5, 1.0, 0.0])) == [2, 2, 0]


def test_damage_equivalent_torque_of_a_sine_is_closed_form():
    amplitude, frequency, duration = 1500.0, 0.2, 500.0
    time = np.arange(0.0, duration + 0.025, 0.05)
    cycles = rainflow_cycles(amplitude * np.cos(2 * np.pi * frequency * time))
    dets = damage_equivalent_range(cycles, duration * 1.0)
    assert set(dets) == set(range(3, 11))
    n_cycles = cycles["count"].sum()
    for k, value in dets.items():
        assert value == pytest.approx(2 * amplitude * (frequency * duration / duration) ** (1 / k), rel=1e-9)
    assert n_cycles == pytest.approx(frequency * duration)


def test_time_quantile_weights_samples_by_their_time():
    from haulprofile.analysis.loads.summary import time_quantile
    values = np.array([5.0, 1.0, 3.0, 2.0])
    durations = np.array([1.0, 1.0, 1.0, 7.0])
    assert time_quantile(values, durations, 0.5) == 2.0
    assert time_quantile(values, durations, 0.95) == 5.0
    assert time_quantile(values, durations, 0.05) == 1.0
