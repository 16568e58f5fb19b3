"""The chain: loop closing between stops, pruning of dead ends and censored parking, start states."""

import numpy as np

from haulprofile.analysis.markov import ClassWidths, TransitionCounts, build_chain, count_transitions, generate
from haulprofile.analysis.markov import classes as cls
from haulprofile.analysis.markov.counting import closures, physically_possible
from haulprofile.testing.drives import synthetic_drive

WIDTHS = ClassWidths()


def _keys(v, g, m):
    return cls.encode(np.array(v), np.array(g), np.array(m))


def test_closing_links_the_final_stop_to_a_stop_at_the_same_gradient_never_within_one_stop():
    # stop at g=2 (t0-1), drive, stop at g=5 (t4-5), drive, final stop at g=5 (t8-9)
    segment = _keys([0, 0, 3, 4, 0, 0, 6, 2, 0, 0], [2, 2, 3, 4, 5, 5, 5, 5, 5, 5], [150] * 10)
    closing_from, closing_to = closures([segment])
    assert (closing_from.tolist(), closing_to.tolist()) == ([segment[9]], [segment[4]])
    assert physically_possible(closing_from, closing_to).all()
    # no other stop at the final gradient, none at the initial one: nothing to close
    lonely = _keys([0, 0, 3, 4, 0, 0], [2, 2, 3, 4, 7, 7], [150] * 6)
    assert len(closures([lonely])[0]) == 0


def test_closing_links_logs_given_together_and_changes_mass_only_at_standstill():
    first = _keys([0, 0, 5, 5, 0, 0], [1, 1, 2, 3, 4, 4], [150] * 6)
    second = _keys([0, 0, 5, 5, 0, 0], [4, 4, 3, 2, 1, 1], [120] * 6)
    closing_from, closing_to = closures([first, second])
    pairs = set(zip(closing_from.tolist(), closing_to.tolist()))
    assert (first[5], second[0]) in pairs and (second[5], first[0]) in pairs
    v0, g0, m0 = cls.decode(closing_from)
    v1, g1, m1 = cls.decode(closing_to)
    assert np.all(v0 == 0) and np.all(v1 == 0) and np.all(g0 == g1) and np.any(m0 != m1)


def test_pruning_removes_dead_ends_and_a_stop_never_left():
    s, a, b, dead, p = _keys([0, 3, 5, 7, 0], [0, 0, 0, 0, 1], [150] * 5)
    # S → A → B → S (a loop), B → dead (never left), A → P → P (a parking never left)
    counts = TransitionCounts(WIDTHS, np.array([s, a, b, b, a, p]), np.array([a, b, s, dead, p, p]),
                              np.array([1, 1, 1, 1, 1, 5]), start_key=np.array([s]), start_count=np.array([1]))
    chain = build_chain(counts)
    assert set(chain.keys[chain.dest[chain.drawn]].tolist()) == {s, a, b}
    assert sorted(chain.keys.tolist()) == sorted([s, a, b, p]), "the parking only as the walks' ending"
    assert np.all(np.diff(chain.row_ptr) > 0)
    assert chain.transitions_left_out == 7
    assert chain.keys[chain.start_state].tolist() == [s]
    free = generate(chain, 600, 5, seed=0, end_at_stop=False).paths
    assert set(chain.keys[free].ravel().tolist()) == {s, a, b}
    paths = generate(chain, 600, 5, seed=0).paths
    parked = chain.keys[paths] == p
    assert parked[:, -1].all() and np.all(np.diff(parked.astype(int), axis=1) >= 0), "parked only at the end"
    assert set(chain.keys[paths[~parked]].tolist()) == {s, a, b}


def test_one_way_drive_keeps_its_start_and_drops_its_censored_final_stop():
    rng = np.random.default_rng(3)
    cruise = 20 + rng.integers(-1, 2, 600)
    speed_kmh = np.concatenate([np.zeros(20), np.linspace(0, 20, 21), cruise, np.linspace(20, 0, 21), np.zeros(30)])
    drive = {"speed_mps": speed_kmh / 3.6, "gradient_pct": np.where(np.arange(len(speed_kmh)) < 300, 1.0, -2.0),
             "mass_kg": np.full(len(speed_kmh), 15_000.0)}
    counts = count_transitions(drive)
    chain = build_chain(counts)
    assert counts.n_closed == 0
    final_stop = cls.encode([0], [-4], [150])[0]
    assert final_stop in counts.to_key and final_stop not in chain.keys[chain.dest[chain.drawn]]
    start = cls.encode([0], [2], [150])[0]
    assert chain.keys[chain.start_state].tolist() == [start]
    for end_at_stop in (False, True):
        candidate = generate(chain, 1800, 1, seed=0, end_at_stop=end_at_stop)
        assert candidate.frame(0)["speed_mps"].iloc[-600:-120].min() > 0
    assert chain.keys[candidate.paths[0, -1]] == final_stop, "the drive's own end: its final stop"


def _random_graph(rng, n):
    n_edges = int(rng.integers(0, 4 * n))
    return rng.integers(0, n, n_edges), rng.integers(0, n, n_edges)


def test_strong_components_are_scipys_partition():
    """The chain's own strongly connected parts (no graph library on a first run's way) are the
    partition scipy's finds, on random graphs with self-loops, isolated nodes and no edges."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from haulprofile.analysis.markov.chain import _strong_components

    rng = np.random.default_rng(29)
    for n in list(range(1, 8)) + [20, 60, 200] * 5:
        src, dst = _random_graph(rng, n)
        ours = _strong_components(n, src, dst)
        graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n, n)).tocsr()
        n_parts, theirs = connected_components(graph, directed=True, connection="strong")
        assert ours.max() + 1 == n_parts
        same = (ours[:, None] == ours[None, :]) == (theirs[:, None] == theirs[None, :])
        assert same.all()


def test_parking_is_a_closed_part_of_standstill_states_only():
    """`_parking` on the standstill states' own graph marks what the definition on the whole graph
    marks: a used part with standstill states only that no transition leaves (scipy's parts)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from haulprofile.analysis.markov.chain import _parking

    rng = np.random.default_rng(4)
    marked = 0
    for n in [2, 5, 12, 40, 120] * 8:
        src, dst = _random_graph(rng, n)
        standstill = rng.random(n) < rng.choice([0.3, 0.7, 1.0])
        graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n, n)).tocsr()
        n_parts, label = connected_components(graph, directed=True, connection="strong")
        leaves = np.ones(n_parts, bool)
        leaves[label[src[label[src] != label[dst]]]] = False
        moving = np.zeros(n_parts, bool)
        moving[label[~standstill]] = True
        used = np.zeros(n_parts, bool)
        used[label[src]] = True
        expected = leaves[label] & ~moving[label] & used[label]
        np.testing.assert_array_equal(_parking(src, dst, n, standstill), expected)
        marked += expected.sum()
    assert marked > 0


def test_ending_weights_are_the_sparse_products_bit_for_bit():
    """The ending's backward steps (`ending._step_back`) equal scipy's CSR product exactly."""
    from scipy.sparse import csr_matrix

    from haulprofile.analysis.markov.ending import _step_back

    counts = count_transitions(synthetic_drive(1800, seed=3, kind="urban"))
    chain = build_chain(counts)
    rows = np.repeat(np.arange(chain.n_states), np.diff(chain.row_ptr))
    probability = chain.count / np.add.reduceat(chain.count, chain.row_ptr[:-1]).astype(float)[rows]
    matrix = csr_matrix((probability, chain.dest, chain.row_ptr), shape=(chain.n_states, chain.n_states))
    h = np.random.default_rng(0).random(chain.n_states)
    for _ in range(20):
        ours, theirs = _step_back(probability, rows, chain.dest, h, chain.n_states), matrix @ h
        assert ours.tobytes() == theirs.tobytes()
        h = ours / ours.max()
