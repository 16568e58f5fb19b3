"""Criteria (physics.md), score (15) and selection of the best valid candidate."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.markov import ClassWidths, build_chain, count_transitions, evaluate, resample_1hz, select_cycle
from haulprofile.analysis.markov import classes as cls
from haulprofile.analysis.markov.criteria import ALLOWANCE, IS_MASS, NAMES, deviations, scores
from haulprofile.analysis.markov.generate import run_batch
from haulprofile.testing.drives import synthetic_drive


@pytest.fixture(scope="module")
def counts():
    return count_transitions(synthetic_drive(4 * 3600, seed=31, kind="urban"))


def test_criteria_are_the_papers_list_plus_mass():
    assert NAMES[:3] == ("speed_mps_mean", "speed_mps_std", "speed_mps_max")
    assert len(NAMES) == 15 and IS_MASS.sum() == 4
    np.testing.assert_allclose(ALLOWANCE, [0.10] * 3 + [0.15] * 12)


def test_deviation_and_score_by_hand():
    widths = ClassWidths(3.6, 0.5, 100.0)          # 1 m/s speed classes
    measured = np.array([[10.0, 5.0, 0.0, 20.0], [0.1, 2.0, -4.0, 4.0], [0.0, 0.4, -1.0, 1.0],
                         [20_000.0, 2_000.0, 15_000.0, 25_000.0]])
    candidate = measured.copy()
    candidate[0, 0] = 11.0        # 10 % of the mean speed
    candidate[1, 0] = 0.5         # mean gradient near zero: relative to its std 2 % → 20 %
    candidate[2, 0] = 0.05        # mean acceleration: std 0.4 below one class (1 m/s per s) → 5 %
    candidate[3, 1] = 2_300.0     # 15 % of the mass std
    candidate[1, 2] = -4.4        # 10 % of the minimum gradient
    d = deviations(candidate, measured, widths)
    expected = np.zeros(15)
    expected[[0, 3, 5, 7, 12]] = [0.10, 0.20, 0.10, 0.05, 0.15]
    np.testing.assert_allclose(d, expected, atol=1e-12)
    ratio = expected / ALLOWANCE
    assert scores(d) == pytest.approx(ratio.mean())
    assert scores(d, with_mass=False) == pytest.approx(ratio[~IS_MASS].mean())
    constant_mass = measured.copy()
    constant_mass[3] = [20_000.0, 0.0, 20_000.0, 20_000.0]
    shifted = constant_mass.copy()
    shifted[3, 1] = 10.0          # std of a constant mass: one mass class (100 kg) is the scale
    assert deviations(shifted, constant_mass, widths)[12] == pytest.approx(0.1)


def test_the_measured_data_judged_against_itself_is_perfect():
    drive = synthetic_drive(1800, seed=32, kind="urban")
    widths = ClassWidths()
    frame = resample_1hz(drive)
    quantised = frame.assign(
        speed_mps=cls.class_index(frame.speed_mps, widths.speed_mps) * widths.speed_mps,
        gradient_pct=cls.class_index(frame.gradient_pct, widths.gradient_pct) * widths.gradient_pct,
        mass_kg=cls.class_index(frame.mass_kg, widths.mass_kg) * widths.mass_kg)
    criteria = evaluate(quantised, drive, widths)
    assert criteria.valid and criteria.score == pytest.approx(0.0, abs=1e-9)


def test_select_returns_the_lowest_scoring_valid_candidate_reproducibly(counts):
    chain = build_chain(counts)
    first = select_cycle(counts, 1800, 1500, seed=9, chain=chain)
    again = select_cycle(counts, 1800, 1500, seed=9, chain=chain)
    pd.testing.assert_frame_equal(first.cycle, again.cycle)
    assert first.n_valid > 0 and first.criteria.valid
    stats, _ = run_batch(chain, 1800, 1500, 9)
    d = deviations(stats, counts.statistics, counts.widths)
    valid = (d <= ALLOWANCE).all(axis=1)
    valid_scores = scores(d)[valid]
    assert first.criteria.score == pytest.approx(valid_scores.min())
    assert valid.sum() == first.n_valid
    assert first.criteria.score == pytest.approx(evaluate(first.cycle, counts).score)
    summary = first.as_dict()
    assert summary["valid"] and summary["seed"] == 9 and set(summary["criteria"]) == set(NAMES)


def test_without_a_valid_candidate_the_best_invalid_one_says_what_failed(counts):
    selection = select_cycle(counts, 60, 50, seed=1)    # one minute cannot represent four hours
    assert not selection.criteria.valid and selection.n_valid == 0
    assert selection.criteria.score == pytest.approx(selection.all_scores.min())
    statement = selection.criteria.statement()
    assert statement.startswith("NOT valid") and selection.criteria.failed
    assert all(name in statement for name in selection.criteria.failed)
