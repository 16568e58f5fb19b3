"""Counting the 2D chain: classes, sparse additive counts, physically impossible transitions."""

import pickle
from collections import Counter

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.markov import ClassWidths, count_transitions, resample_1hz
from haulprofile.analysis.markov import classes as cls
from haulprofile.analysis.markov.counting import enforce_physics, physically_possible, statistics_of
from haulprofile.testing.drives import synthetic_drive


@pytest.fixture(scope="module")
def urban():
    return synthetic_drive(2 * 3600, seed=11, kind="urban")


@pytest.fixture(scope="module")
def regional():
    return synthetic_drive(2 * 3600, seed=12, kind="regional")


def test_class_index_centres_and_key_round_trip():
    widths = ClassWidths(1.0, 0.5, 100.0)
    speed = cls.class_index(np.array([0.0, 0.49, 0.51, 80.4]) / 3.6, widths.speed_mps)
    assert speed.tolist() == [0, 0, 1, 80]
    gradient = cls.class_index(np.array([-6.3, -0.2, 0.26, 8.0]), widths.gradient_pct)
    assert gradient.tolist() == [-13, 0, 1, 16]
    mass = cls.class_index(np.array([8818.8, 22007.4, 40000.0, 49.0]), widths.mass_kg)
    assert mass.tolist() == [88, 220, 400, 0]
    assert [a.tolist() for a in cls.decode(cls.encode(speed, gradient, mass))] == [
        speed.tolist(), gradient.tolist(), mass.tolist()]
    with pytest.raises(UserError, match="out of range"):
        cls.encode([1], [0], [-1])
    with pytest.raises(UserError, match="positive"):
        ClassWidths(mass_kg=0)


def test_resample_1hz_interpolates_holds_mass_and_splits_at_gaps():
    time = np.concatenate([np.arange(0, 10.01, 0.1), np.arange(20, 25.01, 0.1)])
    frame = pd.DataFrame({"time_s": time, "speed_mps": time * 0.5, "gradient_pct": 1.0,
                          "mass_kg": np.where(time < 4.95, 10_000.0, 12_000.0)})
    out = resample_1hz(frame)
    assert out["time_s"].tolist() == list(range(11)) + list(range(20, 26))
    np.testing.assert_allclose(out["speed_mps"], out["time_s"] * 0.5)
    assert out.loc[out.time_s == 4, "mass_kg"].item() == 10_000 and out.loc[out.time_s == 5, "mass_kg"].item() == 12_000
    assert out["segment"].nunique() == 2


def _brute_force_counts(frame, widths):
    """Independent reference: class every 1 Hz sample, apply the rules, count pairs with Counter."""
    counter = Counter()
    for _, seg in resample_1hz(frame).groupby("segment"):
        v = np.floor(np.clip(seg.speed_mps.to_numpy(), 0, None) / widths.speed_mps + 0.5).astype(int)
        g, m = enforce_physics(v, np.floor(seg.gradient_pct.to_numpy() / widths.gradient_pct + 0.5).astype(int),
                               np.floor(seg.mass_kg.to_numpy() / widths.mass_kg + 0.5).astype(int))
        states = list(zip(v.tolist(), g.tolist(), m.tolist()))
        for a, b in zip(states[:-1], states[1:]):
            if (a[0] == 0 and b[0] == 0 and a[1] == b[1]) or (not (a[0] == 0 and b[0] == 0) and a[2] == b[2]):
                counter[(a, b)] += 1
    return counter


def test_counts_equal_a_brute_force_count(urban):
    widths = ClassWidths()
    counts = count_transitions(urban, widths, close_loops=False)
    reference = _brute_force_counts(urban, widths)
    ours = Counter()
    for f, t, c in zip(counts.from_key, counts.to_key, counts.count):
        a = cls.decode([f, t])
        ours[(tuple(int(x[0]) for x in a), tuple(int(x[1]) for x in a))] = int(c)
    assert ours == reference
    assert counts.count.sum() == counts.n_samples - 1 - counts.n_dropped


def test_counts_add_up_like_one_count_and_pickle(urban, regional):
    widths = ClassWidths()
    a = count_transitions(urban, widths, close_loops=False)
    b = count_transitions(regional, widths, close_loops=False)
    both = count_transitions([urban, regional], widths, close_loops=False)
    total = a + b
    for name in ("from_key", "to_key", "count"):
        np.testing.assert_array_equal(getattr(total, name), getattr(both, name))
    np.testing.assert_allclose(total.moments, both.moments)
    assert sum([a, b]).count.sum() == total.count.sum()
    copy = pickle.loads(pickle.dumps(total))
    np.testing.assert_array_equal(copy.count, total.count)
    with pytest.raises(UserError, match="class widths"):
        a + count_transitions(urban, ClassWidths(mass_kg=1000.0))


def test_measured_statistics_are_those_of_the_class_centres(urban):
    widths = ClassWidths()
    counts = count_transitions(urban, widths)
    frame = resample_1hz(urban)
    speed = cls.class_index(frame.speed_mps, widths.speed_mps) * widths.speed_mps
    stats = counts.statistics
    np.testing.assert_allclose(stats[0], [speed.mean(), speed.std(), speed.min(), speed.max()], rtol=1e-9)
    accel = np.diff(speed)
    np.testing.assert_allclose(stats[2], [accel.mean(), accel.std(), accel.min(), accel.max()], rtol=1e-9, atol=1e-12)
    mass = frame.mass_kg.to_numpy()
    assert abs(stats[3, 0] - mass.mean()) < widths.mass_kg
    np.testing.assert_allclose(statistics_of(np.array([[3, 6, 14, 1, 3]]))[0], [2, np.sqrt(2 / 3), 1, 3])


def test_no_physically_impossible_transition_even_from_noisy_estimates(regional):
    rng = np.random.default_rng(5)
    noisy = regional.copy()
    noisy["mass_kg"] += rng.normal(0, 400, len(noisy))          # an estimator wandering while driving
    noisy["gradient_pct"] += rng.normal(0, 0.4, len(noisy))     # gradient noise at standstill too
    counts = count_transitions(noisy)
    v0, g0, m0 = cls.decode(counts.from_key)
    v1, g1, m1 = cls.decode(counts.to_key)
    standstill = (v0 == 0) & (v1 == 0)
    assert np.all(g0[standstill] == g1[standstill]), "gradient changed at standstill"
    assert np.all(m0[~standstill] == m1[~standstill]), "mass changed while moving"
    assert np.any(m0[standstill] != m1[standstill]), "payload changes at stops must survive"
    assert physically_possible(counts.from_key, counts.to_key).all()


def test_enforce_physics_rules_on_a_hand_made_sequence():
    v = np.array([0, 0, 0, 3, 4, 4, 0, 0, 0, 5, 0])
    g = np.array([1, 2, 3, 4, 5, 6, 7, 8, 9, 1, 2])
    m = np.array([10, 11, 12, 13, 14, 14, 15, 16, 17, 20, 21])
    g2, m2 = enforce_physics(v, g, m)
    assert g2.tolist() == [1, 1, 1, 4, 5, 6, 7, 7, 7, 1, 2]
    assert m2.tolist() == [10, 11, 14, 14, 14, 14, 14, 16, 20, 20, 20]


def test_memory_grows_with_the_data_not_with_the_class_grid(urban):
    coarse = count_transitions(urban, ClassWidths(1.0, 0.5, 1000.0))
    fine = count_transitions(urban, ClassWidths(1.0, 0.5, 1.0))
    assert len(fine) <= fine.n_samples and len(coarse) <= coarse.n_samples
    assert fine.nbytes <= 24 * fine.n_samples + 100


def test_bad_input_is_a_one_line_user_error():
    with pytest.raises(UserError, match="mass_kg"):
        count_transitions(pd.DataFrame({"time_s": [0.0, 1.0], "speed_mps": [0.0, 1.0], "gradient_pct": [0.0, 0.0]}))
    with pytest.raises(UserError, match="no usable samples"):
        count_transitions(pd.DataFrame({"time_s": [0.0, 1.0], "speed_mps": [0.0, 1.0], "gradient_pct": [0.0, 0.0],
                                        "mass_kg": [np.nan, np.nan]}))


def test_mass_missing_around_stops_is_filled_but_a_trip_without_mass_stays_a_gap():
    from haulprofile.analysis.stop_mass import mass_at_stops
    nan = np.nan
    speed = np.array([0.0, 0.0, 0.3, 5.0, 5.0, 0.3, 0.0, 0.0, 0.4, 6.0, 0.2, 0.0, 0.0, 0.5, 7.0])
    mass = np.array([nan, nan, nan, 9e3, 9e3, nan, nan, nan, nan, nan, nan, nan, nan, 8e3, nan])
    filled = mass_at_stops(np.arange(len(speed), dtype=float), speed, mass)
    np.testing.assert_array_equal(filled[:8], [9e3] * 8)
    assert np.isnan(filled[8:11]).all()              # a trip without any mass estimate
    np.testing.assert_array_equal(filled[11:], [8e3] * 4)   # the stop after it: the departure mass


def test_a_loggers_dropout_in_the_delivery_stop_keeps_both_payloads_in_one_chain():
    """Seen on a demo logged under load: 1 s gaps in the wheel speed inside a 5-minute delivery
    stop left the stop without a mass, split the 1 Hz data there and so cut the chain in two: no
    walk could go from the loaded to the unloaded truck, and no cycle was valid."""
    time = np.arange(0.0, 1200.0, 0.1)
    speed = np.interp(time, [0, 400, 410, 700, 710, 1200], [12, 12, 0, 0, 12, 12])
    mass = np.where(time < 550, 16e3, 13e3)
    mass[(time > 400) & (time < 720)] = np.nan        # the estimator gives no mass around the stop
    for start in (520.0, 523.0, 526.0):                # three dropouts of 1.5 s
        speed[(time >= start) & (time < start + 1.5)] = np.nan
    frame = pd.DataFrame({"time_s": time, "speed_mps": speed, "gradient_pct": 0.0, "mass_kg": mass})
    assert resample_1hz(frame)["segment"].nunique() == 1
    counts = count_transitions(frame)
    mass_from, mass_to = cls.decode(counts.from_key)[2], cls.decode(counts.to_key)[2]
    assert ((mass_from == 160) & (mass_to == 130)).any()


def test_enforce_physics_leaves_only_possible_transitions_on_any_sequence():
    from hypothesis import given, settings, strategies as st

    @settings(max_examples=200, deadline=None, derandomize=True)
    @given(st.lists(st.tuples(st.integers(0, 3), st.integers(-3, 3), st.integers(100, 104)), min_size=2,
                    max_size=60))
    def check(states):
        v, g, m = (np.array(x) for x in zip(*states))
        g2, m2 = enforce_physics(v, g, m)
        keys = cls.encode(v, g2, m2)
        possible = physically_possible(keys[:-1], keys[1:])
        standstill_runs_of_one = ((v[1:-1] == 0) & (v[:-2] > 0) & (v[2:] > 0)).sum()
        assert (~possible).sum() <= standstill_runs_of_one
        assert np.array_equal(v, cls.decode(keys)[0])

    check()
