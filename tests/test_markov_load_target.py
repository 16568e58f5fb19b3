"""The load target is the drive the chain walks: its stops count although a mass estimator leaves
them without a mass (docs/cycles.md, "Stops in the load target")."""

import numpy as np
import pytest

from haulprofile.analysis.markov import build_chain, count_transitions
from haulprofile.analysis.markov.converge import select_refined
from haulprofile.analysis.markov.counting import resample_1hz
from haulprofile.analysis.markov.load_criteria import (LOAD_NAMES, evaluate_loads, load_target, measured_loads,
                                                       within_allowance)
from haulprofile.analysis.testing.drives import synthetic_drive
from haulprofile.analysis.vehicle import load_vehicle

STANDING_MPS = 0.1
MEDIAN_POWER = LOAD_NAMES.index("wheel_power_exceeded_50pct_w")


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle("rigid-18t")


@pytest.fixture(scope="module")
def drive():
    """Regional driving with its true mass everywhere (stops: 28 % of the time)."""
    return synthetic_drive(2 * 3600, seed=31, kind="regional")


@pytest.fixture(scope="module")
def estimated(drive):
    """The same drive as the mass stage leaves it: no mass while the truck stands."""
    return drive.assign(mass_kg=drive["mass_kg"].where(drive["speed_mps"] >= STANDING_MPS))


def test_the_measured_loads_cover_the_seconds_the_chain_counts(drive, estimated, vehicle):
    counted = resample_1hz(estimated)
    standing = counted["speed_mps"] < STANDING_MPS
    assert standing.mean() > 0.1
    loads = measured_loads(estimated, vehicle)
    assert loads["duration_s"].sum() == pytest.approx(len(counted), abs=2)
    assert (loads["speed_mps"] < STANDING_MPS).sum() == pytest.approx(standing.sum(), abs=2)


def test_a_mass_missing_at_stops_leaves_the_load_target_as_with_the_true_mass(drive, estimated, vehicle):
    chain = build_chain(count_transitions(drive))
    truth, target = load_target(drive, vehicle, chain), load_target(estimated, vehicle, chain)
    np.testing.assert_allclose(target.measured, truth.measured, rtol=1e-9)
    # the standing threshold moves a payload change by a second at most, in a few stops
    np.testing.assert_allclose(target.residence_share, truth.residence_share, atol=1e-3)


def test_the_cycle_selected_on_the_estimated_mass_carries_the_true_wheel_loads(drive, estimated, vehicle):
    """Without the stops in the target, the median wheel power the selection aims at is that of
    driving alone (+1.5 allowances here) and the cycle follows it."""
    counts = count_transitions(estimated)
    chain = build_chain(counts)
    selection = select_refined(counts, 1800, 0, chain, load_target(estimated, vehicle, chain), vehicle,
                               n_pool=2000, n_moves=1500)[0]
    judged = evaluate_loads(selection.cycle, vehicle, load_target(drive, vehicle, chain))
    assert judged[LOAD_NAMES[MEDIAN_POWER]]["passed"], judged[LOAD_NAMES[MEDIAN_POWER]]
    assert within_allowance(judged), {name: j for name, j in judged.items() if not j["passed"]}
