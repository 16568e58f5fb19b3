"""Mass accuracy on the three shipped virtual-truck scenarios (fixed seeds, payload changes at
stops), against the issue's targets: per-segment error <= 3 % median and <= 6 % worst for
segments over 5 minutes with enough excitation; the gradient used is our own estimate."""

import numpy as np
import pytest

from test_gradient_virtual_truck import SCENARIO_SEEDS, virtual_drive_data

virtual_truck = pytest.importorskip("haulprofile.analysis.virtual_truck")


def _estimate(name, tmp_path_factory, filter_settings=None):
    from haulprofile.analysis.gradient import estimate_gradient
    from haulprofile.analysis.mass import FilterSettings, estimate_mass
    signals, truth, dem = virtual_drive_data(name, tmp_path_factory)
    signals = signals.assign(**estimate_gradient(signals, dem).samples)
    vehicle = virtual_truck.scenario_vehicle(virtual_truck.load_scenario(name))
    return estimate_mass(signals, vehicle, filter_settings or FilterSettings()), truth


def _errors(result, truth, method="mass_ls_kg", min_duration_s=300.0):
    time_s, mass = truth["time_s"].to_numpy(), truth["mass_kg"].to_numpy()
    errors = []
    for segment in result.segments:
        if segment["status"] != "ok" or segment["end_s"] - segment["start_s"] < min_duration_s:
            continue
        inside = (time_s >= segment["start_s"]) & (time_s <= segment["end_s"])
        assert np.ptp(mass[inside]) == 0, "a segment spans a payload change"
        errors.append(abs(segment[method] / mass[inside][0] - 1))
    return errors


@pytest.fixture(scope="module")
def estimates(tmp_path_factory):
    return {name: _estimate(name, tmp_path_factory) for name in sorted(SCENARIO_SEEDS)}


def test_per_segment_mass_meets_targets_on_every_scenario(estimates):
    every = []
    for name, (result, truth) in estimates.items():
        errors = _errors(result, truth)
        print(name, "LS", [f"{100 * e:.2f} %" for e in errors],
              "RLS", [f"{100 * e:.2f} %" for e in _errors(result, truth, "mass_rls_kg")],
              "LM", [f"{100 * e:.2f} %" for e in _errors(result, truth, "mass_lm_kg")],
              "CAN", [f"{100 * e:.2f} %" for e in _errors(result, truth, "reported_mass_kg")])
        assert errors, f"{name}: no segment over 5 minutes got a confident mass"
        assert np.median(errors) <= 0.03 and max(errors) <= 0.06, (name, errors)
        every += errors
    assert len(every) >= 5


@pytest.mark.parametrize("method", ["mass_rls_kg", "mass_lm_kg"])
def test_recursive_estimators_end_near_the_truth(estimates, method):
    for name, (result, truth) in estimates.items():
        errors = _errors(result, truth, method)
        assert np.median(errors) <= 0.03 and max(errors) <= 0.06, (name, method, errors)


def test_the_truth_lies_within_the_stated_uncertainty(estimates):
    for name, (result, truth) in estimates.items():
        time_s, mass = truth["time_s"].to_numpy(), truth["mass_kg"].to_numpy()
        for segment in result.segments:
            if segment["status"] == "ok":
                true = np.median(mass[(time_s >= segment["start_s"]) & (time_s <= segment["end_s"])])
                assert abs(segment["mass_ls_kg"] - true) <= 2 * segment["uncertainty_kg"], (name, segment)


def test_unexcited_segments_get_no_number_and_a_reason(estimates):
    result, _ = estimates["urban-delivery"]
    silent = [s for s in result.segments if s["status"] != "ok"]
    assert silent and all(s["reason"] for s in silent)
    for segment in silent:
        assert segment["status"] != "no_excitation" or segment["mass_ls_kg"] is None


def test_papers_filter_leaves_urban_drive_without_samples_and_says_so(tmp_path_factory):
    from haulprofile.analysis.mass import FilterSettings
    result, _ = _estimate("urban-delivery", tmp_path_factory, FilterSettings.paper())
    assert all(s["status"] == "no_excitation" and "pass the data filter" in s["reason"] for s in result.segments)
    assert np.isnan(result.columns["mass_kg"]).all()
