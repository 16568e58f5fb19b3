"""Fleet runner: additive statistics against independent references, and the same result from a
serial run, a local process pool and a Dask LocalCluster of 2 worker processes."""

import random

import numpy as np
import pandas as pd
import pytest
import rainflow

from haulprofile.analysis.fleet import (FleetSpec, LoadBins, SparseHistogram, log_statistics, read_counts, reduce_group,
                            run_fleet, sum_statistics)
from haulprofile.testing.fleet import virtual_fleet
from haulprofile.analysis.loads import loads_of, resample_mean
from haulprofile.analysis.loads.collectives import damage_equivalent_range, rainflow_cycles
from haulprofile.analysis.fleet.cycle_target import load_target_of
from haulprofile.analysis.markov import build_chain, count_transitions
from haulprofile.analysis.markov.converge import select_refined
from haulprofile.analysis.markov.load_criteria import LOAD_NAMES, load_target
from haulprofile.testing.drives import synthetic_drive
from haulprofile.analysis.vehicle import load_vehicle

VEHICLE = load_vehicle("rigid-18t")


def drive_signals(seed: int, duration_s: float = 1200.0) -> pd.DataFrame:
    """A 1 Hz synthetic drive with the columns the fleet statistics need."""
    frame = synthetic_drive(duration_s, seed=seed, kind="regional")
    frame["accel_mps2"] = np.gradient(frame["speed_mps"].to_numpy(), frame["time_s"].to_numpy())
    return frame


def test_sparse_histogram_equals_numpy_on_fixed_edges_and_adds_up():
    rng = np.random.default_rng(4)
    a, b = rng.normal(3.0, 7.0, 5000), rng.normal(-2.0, 4.0, 3000)
    wa, wb = rng.uniform(0, 1, 5000), rng.uniform(0, 1, 3000)
    summed = SparseHistogram.of({"x": a}, {"x": 0.5}, wa) + SparseHistogram.of({"x": b}, {"x": 0.5}, wb)
    edges = np.arange(np.floor(min(a.min(), b.min()) / 0.5), np.ceil(max(a.max(), b.max()) / 0.5) + 1) * 0.5
    reference, _ = np.histogram(np.concatenate([a, b]), bins=edges, weights=np.concatenate([wa, wb]))
    dense = np.zeros(len(edges) - 1)
    dense[summed.keys[:, 0] - int(round(edges[0] / 0.5))] = summed.values
    np.testing.assert_allclose(dense, reference, rtol=1e-12, atol=1e-12)
    counted = SparseHistogram.of({"x": a, "y": -a}, {"x": 1.0, "y": 2.0})
    assert counted.total == len(a) and counted.keys.shape[1] == 2


def test_log_statistics_hold_the_loads_reference_values():
    signals = drive_signals(1)
    stats = log_statistics("a", signals, {}, VEHICLE)
    loads = loads_of(resample_mean(signals, 1.0), VEHICLE)
    assert stats.totals["loads_s"] == pytest.approx(loads["duration_s"].sum())
    for name, histogram in stats.histograms.items():
        if name.startswith("time_at_level") or name.startswith("residence"):
            assert histogram.total == pytest.approx(stats.totals["loads_s"], rel=1e-12)
    torque = loads["wheel_torque_nm"].to_numpy()
    assert stats.histograms["rainflow_range_mean_counts"].total == pytest.approx(
        sum(count for _, count in rainflow.count_cycles(torque)))
    reference = damage_equivalent_range(rainflow_cycles(torque), stats.totals["loads_s"])
    for k, value in stats.damage_equivalent_torque_nm().items():
        assert value == pytest.approx(reference[k], rel=1e-9)
    counts = count_transitions(signals)
    assert np.array_equal(stats.counts.count, counts.count) and np.array_equal(stats.counts.to_key, counts.to_key)
    distance_km = (signals["distance_m"].iloc[-1] - signals["distance_m"].iloc[0]) / 1000
    assert stats.totals["distance_km"] == pytest.approx(distance_km, rel=2e-3)


def test_a_fleet_target_counts_the_stops_the_mass_stage_left_without_a_mass():
    """A log whose mass is missing at its stops (as the mass stage leaves it) has the run's load
    target, stops included: the walks of its chain stand there."""
    signals = drive_signals(2, 2400.0)
    standing = signals["speed_mps"] < 0.1
    assert standing.mean() > 0.05
    signals["mass_kg"] = signals["mass_kg"].where(~standing)
    stats = log_statistics("a", signals, {}, VEHICLE)
    assert stats.totals["loads_s"] == pytest.approx(len(signals), abs=2)
    chain = build_chain(stats.counts)
    fleet, run = load_target_of(stats, VEHICLE, chain), load_target(signals, VEHICLE, chain)
    exact = [i for i, name in enumerate(LOAD_NAMES) if "power_exceeded" not in name]
    np.testing.assert_allclose(fleet.measured[exact], run.measured[exact], rtol=1e-6)


def test_load_target_of_a_one_log_fleet_is_the_runs_load_target():
    """The refined selection's load target from the additive statistics alone equals the one the
    run's cycle stage takes from the drive's signals: exactly where a sum carries it, within a bin of
    the fine power histogram for the power levels."""
    signals = drive_signals(2, 2400.0)
    stats = log_statistics("a", signals, {}, VEHICLE)
    chain = build_chain(stats.counts)
    fleet, run = load_target_of(stats, VEHICLE, chain), load_target(signals, VEHICLE, chain)
    exact = [i for i, name in enumerate(LOAD_NAMES) if "power_exceeded" not in name]
    np.testing.assert_allclose(fleet.measured[exact], run.measured[exact], rtol=1e-6)
    power = [i for i, name in enumerate(LOAD_NAMES) if "power_exceeded" in name]
    assert np.all(np.abs(fleet.measured[power] - run.measured[power]) <= LoadBins().power_level_w)
    np.testing.assert_allclose(fleet.resistance_n, run.resistance_n)
    assert fleet.residence_share.sum() == pytest.approx(1.0)


def test_sum_of_logs_is_the_sum_of_their_statistics_in_path_order():
    parts = [log_statistics(f"log-{i}", drive_signals(i, 600.0), {}, VEHICLE) for i in range(3)]
    total = sum_statistics(parts)
    counts = count_transitions(drive_signals(0, 600.0)) + count_transitions(drive_signals(1, 600.0)) \
        + count_transitions(drive_signals(2, 600.0))
    assert np.array_equal(total.counts.count, counts.count) and np.array_equal(total.counts.from_key, counts.from_key)
    for key in ("loads_s", "distance_km", "rainflow_cycles"):
        assert total.totals[key] == pytest.approx(sum(p.totals[key] for p in parts))
    for name, histogram in total.histograms.items():
        assert histogram.total == pytest.approx(sum(p.histograms[name].total for p in parts))
    from haulprofile.analysis.fleet import LogResult
    results = [LogResult(f"log-{i}", "g", p) for i, p in enumerate(parts)]
    shuffled = results[:]
    random.Random(3).shuffle(shuffled)
    assert reduce_group(shuffled).same_as(reduce_group(results))
    assert reduce_group(shuffled).logs == ["log-0", "log-1", "log-2"]


def test_histograms_of_different_bins_do_not_add():
    a = log_statistics("a", drive_signals(1, 300.0), {}, VEHICLE)
    b = log_statistics("b", drive_signals(2, 300.0), {}, VEHICLE, bins=LoadBins(wheel_torque_nm=250.0))
    with pytest.raises(Exception, match="different bins"):
        a + b


@pytest.fixture(scope="module")
def small_fleet(tmp_path_factory):
    """Two groups: two short MCAP logs of the rigid truck (with DEM), two signals tables."""
    root = tmp_path_factory.mktemp("fleet")
    group_dirs, dem_dir = virtual_fleet(root, {"rigid": ("urban-delivery", "rigid-18t")}, 2, n_sections=5,
                                        say=lambda _m: None)
    tables = root / "tables"
    tables.mkdir()
    for seed in (0, 1):
        drive_signals(seed, 900.0).to_parquet(tables / f"drive-{seed}.parquet")
    return [group_dirs[0], tables], dem_dir


def run_small(small_fleet, out, **how):
    dirs, dem_dir = small_fleet
    spec = FleetSpec.of(dirs, [VEHICLE], dem_dir=dem_dir, n_candidates=300, seed=5, duration_s=600.0)
    return run_fleet(spec, out, say=lambda _m: None, **how)


@pytest.fixture(scope="module")
def serial_run(small_fleet, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    return run_small(small_fleet, out, workers=1), out


def test_serial_run_writes_each_group(serial_run):
    fleet, out = serial_run
    assert [g.name for g in fleet.groups] == ["rigid", "tables"]
    for group in fleet.groups:
        assert not group.failed and len(group.statistics.logs) == 2
        for name in ("cycle.csv", "cycle.vdri", "counts.npz", "fleet-summary.json",
                     "histograms/residence_speed_torque_s.csv"):
            assert (out / group.name / name).is_file(), name
        counts = read_counts(out / group.name / "counts.npz")
        assert np.array_equal(counts.count, group.statistics.counts.count)
        chain = build_chain(counts)
        target = load_target_of(group.statistics, VEHICLE, chain)
        again = select_refined(counts, 600.0, 5, chain, target, VEHICLE, n_pool=300)[0]
        pd.testing.assert_frame_equal(again.cycle, group.cycle)
        assert group.selection["method"] == "refined" and "load_criteria" in group.selection
    assert (out / "fleet-summary.json").is_file()
    assert fleet.groups[0].statistics.mass_segments, "the MCAP logs went through the mass stage"


def assert_same(a, b):
    for x, y in zip(a.groups, b.groups):
        assert x.statistics.same_as(y.statistics), x.name
        pd.testing.assert_frame_equal(x.cycle, y.cycle, check_exact=True)
        assert x.selection == y.selection


def test_without_figures_the_same_result_and_no_per_log_figures(small_fleet, serial_run, tmp_path):
    dirs, dem_dir = small_fleet
    spec = FleetSpec.of(dirs, [VEHICLE], dem_dir=dem_dir, n_candidates=300, seed=5, duration_s=600.0,
                        figures=False)
    fleet = run_fleet(spec, tmp_path, say=lambda _m: None, workers=1)
    serial, serial_out = serial_run
    assert_same(fleet, serial)
    per_log = [p for p in serial_out.rglob("*.png") if p.parent.name not in ("rigid", "tables")]
    assert {p.name for p in per_log} == {"gradient.png", "mass.png"}
    assert not [p for p in tmp_path.rglob("*.png") if p.parent.name not in ("rigid", "tables")]


def test_process_pool_gives_the_serial_result(small_fleet, serial_run, tmp_path):
    assert_same(serial_run[0], run_small(small_fleet, tmp_path, workers=2))


def test_dask_local_cluster_gives_the_serial_result(small_fleet, serial_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        fleet = run_small(small_fleet, tmp_path, scheduler=cluster.scheduler_address)
    assert fleet.executor.startswith("dask")
    assert_same(serial_run[0], fleet)


def test_torque_level_crossings_on_the_fixed_grid_equal_a_plain_count():
    from haulprofile.analysis.fleet.statistics import crossing_histogram

    torque = np.cumsum(np.random.default_rng(8).normal(0.0, 400.0, 2000))
    crossings = crossing_histogram(torque, 500.0)
    for level_index, count in zip(crossings.keys[:, 0], crossings.values):
        level = level_index * 500.0
        assert count == sum(1 for x0, x1 in zip(torque[:-1], torque[1:]) if x0 < level <= x1)
    levels_spanned = np.arange(np.ceil(torque.min() / 500), np.floor(torque.max() / 500) + 1)
    assert set(crossings.keys[:, 0]) <= set(levels_spanned.astype(int))
