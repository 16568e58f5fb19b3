"""Monte Carlo generation: numba kernels against their references, seeds, physics, convergence."""

import numpy as np
import pytest

from haulprofile.analysis.markov import TransitionCounts, build_chain, count_transitions, generate
from haulprofile.analysis.markov import classes as cls
from haulprofile.analysis.markov.counting import physically_possible
from haulprofile.analysis.markov.ending import ending_for
from haulprofile.analysis.markov.generate import path_statistics, walk, path_statistics_reference, run_batch, walk_ending
from haulprofile.testing.drives import synthetic_drive


@pytest.fixture(scope="module")
def counts():
    return count_transitions(synthetic_drive(3 * 3600, seed=21, kind="urban"))


@pytest.fixture(scope="module")
def chain(counts):
    return build_chain(counts)


def _walk_both(chain, seed, index, n, update):
    paths = []
    for kernel in (walk, walk.py_func):
        path = np.empty(n, np.int64)
        with np.errstate(over="ignore"):
            kernel(chain.row_ptr, chain.dest, chain.count, chain.cum_count, chain.start_state, chain.start_cum,
                   seed, index, update, chain.count.copy(), np.empty(n, np.int64), path,
                   *ending_for(chain, n).as_tuple())
        paths.append(path)
    return paths


@pytest.mark.parametrize("update", [False, True])
def test_walk_kernel_equals_its_python_reference(chain, update):
    compiled, reference = _walk_both(chain, 7, 3, 600, update)
    np.testing.assert_array_equal(compiled, reference)


def test_path_statistics_kernel_and_python_equal_numpy(chain):
    path = generate(chain, 900, 1, seed=1).paths[0]
    expected = path_statistics_reference(path, chain.speed_mps, chain.gradient_pct, chain.mass_kg)
    for kernel in (path_statistics, path_statistics.py_func):
        out = np.empty((4, 4))
        kernel(path, chain.speed_mps, chain.gradient_pct, chain.mass_kg, out)
        np.testing.assert_allclose(out, expected, rtol=1e-9, atol=1e-9)


def test_same_seed_same_candidates_whatever_the_batch(chain):
    a = generate(chain, 600, 12, seed=5)
    b = generate(chain, 600, 12, seed=5)
    np.testing.assert_array_equal(a.paths, b.paths)
    single = generate(chain, 600, 1, seed=5, first_index=9)
    np.testing.assert_array_equal(single.paths[0], a.paths[9])
    stats, _ = run_batch(chain, 600, 12, seed=5)
    np.testing.assert_allclose(stats, a.statistics)
    assert not np.array_equal(generate(chain, 600, 12, seed=6).paths, a.paths)


def test_candidates_start_at_standstill_and_use_only_observed_physical_transitions(counts, chain):
    candidates = generate(chain, 1800, 50, seed=2)
    assert np.all(chain.speed_mps[candidates.paths[:, 0]] == 0)
    keys = chain.keys[candidates.paths]
    observed = set(zip(counts.from_key.tolist(), counts.to_key.tolist()))
    pairs = set(zip(keys[:, :-1].ravel().tolist(), keys[:, 1:].ravel().tolist()))
    assert pairs <= observed
    assert physically_possible(keys[:, :-1].ravel(), keys[:, 1:].ravel()).all()
    frame = candidates.frame(0)
    assert list(frame.columns) == ["time_s", "speed_mps", "accel_mps2", "gradient_pct", "mass_kg", "distance_m"]
    assert len(frame) == 1801


def test_transition_frequencies_of_a_long_walk_converge_to_the_counts(chain):
    path = generate(chain, 400_000, 1, seed=3).paths[0]
    src, dst = path[:-1], path[1:]
    visits = np.bincount(src, minlength=chain.n_states)
    busy = np.flatnonzero(visits >= 2000)
    assert busy.size >= 5
    for state in busy[:20]:
        a, b = chain.row_ptr[state], chain.row_ptr[state + 1]
        expected = chain.count[a:b] / chain.count[a:b].sum()
        seen = np.array([np.sum(dst[src == state] == d) for d in chain.dest[a:b]]) / visits[state]
        assert np.max(np.abs(seen - expected)) < 4.5 * np.sqrt(0.25 / visits[state]) + 1e-9


def test_statistics_of_many_candidates_converge_towards_the_input(counts, chain):
    measured = counts.statistics
    totals = np.add.reduceat(chain.count, chain.row_ptr[:-1])
    stationary_speed = np.sum(totals * chain.speed_mps) / totals.sum()
    assert stationary_speed == pytest.approx(measured[0, 0], rel=0.01)
    spread, bias = {}, {}
    for duration in (600, 7200):
        stats = generate(chain, duration, 400, seed=4).statistics
        spread[duration] = stats[:, 0, 0].std()
        bias[duration] = abs(stats[:, 0, 0].mean() / measured[0, 0] - 1)
        assert stats[:, 3, 0].mean() == pytest.approx(measured[3, 0], rel=0.05)
    # every candidate opens with a stop: a transient that fades as the cycle gets longer
    assert bias[7200] < 0.05 and bias[7200] < 0.5 * bias[600]
    assert spread[7200] < 0.6 * spread[600]
    long = generate(chain, 200_000, 1, seed=8).statistics[0]
    assert long[0, 0] == pytest.approx(measured[0, 0], rel=0.03)
    assert long[0, 1] == pytest.approx(measured[0, 1], rel=0.03)
    assert long[3, 0] == pytest.approx(measured[3, 0], rel=0.02)


def _two_loop_counts():
    """Standstill S with one observed departure each to X and Y (a hand-made chain)."""
    widths = cls.ClassWidths()
    s, x, y = cls.encode([0, 5, 9], [0, 0, 0], [150, 150, 150])
    return TransitionCounts(widths, np.array([s, s, x, y]), np.array([x, y, s, s]), np.array([1, 1, 1, 1]))


def test_update_counts_draws_without_replacement():
    chain = build_chain(_two_loop_counts())
    with_update = generate(chain, 40, 200, seed=1, update_counts=True).paths
    plain = generate(chain, 40, 200, seed=1).paths
    # S at even steps; without replacement the two departures of S alternate in each pair of visits
    assert np.all(with_update[:, 1] != with_update[:, 3])
    assert np.mean(plain[:, 1] != plain[:, 3]) == pytest.approx(0.5, abs=0.1)


def test_bad_requests_are_user_errors(chain):
    from haulprofile.analysis.errors import UserError
    with pytest.raises(UserError, match="duration"):
        generate(chain, 1, 1)
    with pytest.raises(UserError, match="seed"):
        generate(chain, 100, 1, seed=-1)


def test_random_stream_is_splitmix64():
    """First outputs of Vigna's splitmix64.c from state 0 (0xe220a8397b1dcdaf, 0x6e789e6aa1b965f4,
    0x06c45d188009454f), as doubles from their top 53 bits."""
    from haulprofile.analysis.markov.generate import uniform
    expected = [(x >> 11) * 2.0**-53 for x in (0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F)]
    for kernel in (uniform, uniform.py_func):
        state = np.zeros(1, np.uint64)
        with np.errstate(over="ignore"):
            assert [kernel(state) for _ in range(3)] == expected


@pytest.mark.parametrize("update", [False, True])
def test_batch_kernel_equals_its_python_reference(chain, update):
    from haulprofile.analysis.markov.generate import batch
    results = []
    for kernel in (batch, batch.py_func):
        stats = np.empty((4, 4, 4))
        paths = np.empty((4, 301), np.int64)
        with np.errstate(over="ignore"):
            kernel(chain.row_ptr, chain.dest, chain.count, chain.cum_count, chain.start_state, chain.start_cum,
                   chain.speed_mps, chain.gradient_pct, chain.mass_kg, 11, 2, 301, update, stats, paths,
                   *walk_ending(chain, 300).as_tuple())
        results.append((stats, paths))
    np.testing.assert_array_equal(results[0][1], results[1][1])
    np.testing.assert_allclose(results[0][0], results[1][0], rtol=1e-12)
    np.testing.assert_array_equal(results[0][1][0], generate(chain, 300, 1, seed=11, first_index=2,
                                                             update_counts=update).paths[0])
