"""Mass estimators: kernels against their references and closed forms; the per-segment estimate on
a synthetic drive built with the vehicle model (payload change at a stop)."""

import numpy as np
import pytest

from haulprofile.analysis.dem.srtm import SrtmDem
from haulprofile.analysis.errors import UserError
from haulprofile.analysis.gradient import estimate_gradient
from haulprofile.analysis.mass import SegmentSettings, estimate_mass, kernels
from haulprofile.analysis.mass.segments import segment_bounds
from haulprofile.analysis.vehicle import load_vehicle
from test_gradient import synthetic_drive, write_route_dem


@pytest.fixture(scope="module")
def regression_data():
    rng = np.random.default_rng(7)
    phi = rng.uniform(0.05, 0.8, (2000, 2))
    y = phi @ np.array([21_000.0, 3_000.0]) + rng.normal(0, 500, 2000)
    y[[5, 50, 500]] = np.nan
    phi[77, 1] = np.nan
    return phi, y


def exponentially_weighted_ls(phi, y, lam, theta0, p0):
    """Closed form of RLS (11)-(13): argmin lam^n (theta-theta0)^T P0^-1 (theta-theta0)
    + sum lam^(n-k) (y_k - phi_k theta)^2 over the finite samples."""
    ok = np.isfinite(y) & np.all(np.isfinite(phi), axis=1)
    phi, y = phi[ok], y[ok]
    n = len(y)
    weights = lam ** (n - 1 - np.arange(n))
    prior = lam ** n * np.linalg.inv(p0)
    return np.linalg.solve(prior + (phi * weights[:, None]).T @ phi, prior @ theta0 + (phi * weights[:, None]).T @ y)


def test_least_squares_kernel_and_reference_agree_with_numpy_lstsq(regression_data):
    phi, y = regression_data
    ok = np.isfinite(y) & np.all(np.isfinite(phi), axis=1)
    expected = np.linalg.lstsq(phi[ok], y[ok], rcond=None)[0]
    for fn in (kernels.least_squares, kernels.least_squares.py_func, kernels.least_squares_reference):
        np.testing.assert_allclose(fn(phi, y), expected, rtol=1e-10)
    assert np.isnan(kernels.least_squares(np.zeros((10, 1)), np.ones(10))).all()


@pytest.mark.parametrize("lam", [1.0, 0.9985, 0.99])
def test_rls_kernel_and_reference_equal_the_closed_form(regression_data, lam):
    phi, y = regression_data
    theta0, p0 = np.array([8818.8, 0.0]), np.diag([1e3, 1e3])
    expected = exponentially_weighted_ls(phi, y, lam, theta0, p0)
    for fn in (kernels.rls, kernels.rls.py_func, kernels.rls_reference):
        path = fn(phi, y, lam, theta0, p0)
        np.testing.assert_allclose(path[-1], expected, rtol=1e-8)


def test_lm_without_damping_is_cumulative_least_squares(regression_data):
    phi, y = regression_data
    phi1, y1 = phi[:300, :1], y[:300]
    for fn in (kernels.levenberg_marquardt, kernels.levenberg_marquardt.py_func,
               kernels.levenberg_marquardt_reference):
        path = fn(phi1, y1, 1.0, 0.0, np.array([8818.8]))
        np.testing.assert_allclose(path[-1], kernels.least_squares_reference(phi1, y1), rtol=1e-9)


@pytest.mark.parametrize("p", [1, 2])
def test_damped_lm_kernel_matches_reference(regression_data, p):
    phi, y = regression_data
    theta0 = np.array([8818.8, 0.0])[:p]
    expected = kernels.levenberg_marquardt_reference(phi[:, :p], y, 0.9985, 0.1, theta0)
    for fn in (kernels.levenberg_marquardt, kernels.levenberg_marquardt.py_func):
        np.testing.assert_allclose(fn(np.ascontiguousarray(phi[:, :p]), y, 0.9985, 0.1, theta0), expected, rtol=1e-9)


def test_segments_split_at_long_stops_only():
    time = np.arange(0, 400.0, 1.0)
    speed = np.full(400, 10.0)
    speed[100:120] = 0.0  # traffic light, 20 s
    speed[200:290] = 0.0  # loading stop, 90 s
    assert segment_bounds(time, speed, SegmentSettings()) == [(0, 200), (290, 400)]


def test_a_dropout_inside_a_stop_is_still_the_stop_but_a_long_gap_is_not():
    time = np.arange(0, 400.0, 1.0)
    speed = np.full(400, 10.0)
    speed[200:290] = 0.0
    speed[240:242] = np.nan   # the logger missed two samples of the loading stop
    assert segment_bounds(time, speed, SegmentSettings()) == [(0, 200), (290, 400)]
    speed[200:290] = np.nan   # 90 s without speed: no evidence of a stop
    speed[[199, 290]] = 0.0
    assert segment_bounds(time, speed, SegmentSettings()) == [(0, 400)]


@pytest.fixture(scope="module")
def payload_change_drive(tmp_path_factory):
    drive = synthetic_drive(seed=3, duration_s=2400, mass_kg=12_500, stops_s=(1100.0,), mass_after_stop_kg=17_800)
    dem = SrtmDem(write_route_dem(tmp_path_factory.mktemp("dem")))
    gradient = estimate_gradient(drive, dem)
    for name, values in gradient.samples.items():
        drive[name] = values
    return drive


def test_per_segment_mass_within_three_percent_after_a_payload_change(payload_change_drive):
    vehicle = load_vehicle("rigid-18t")
    result = estimate_mass(payload_change_drive, vehicle)
    assert [s["status"] for s in result.segments] == ["ok", "ok"]
    for segment, truth in zip(result.segments, (12_500, 17_800)):
        assert abs(segment["mass_ls_kg"] / truth - 1) < 0.03, segment
        assert abs(segment["mass_ls_kg"] - truth) < 4 * segment["uncertainty_kg"] + 0.01 * truth
        for method in ("mass_rls_kg", "mass_lm_kg"):
            assert abs(segment[method] / truth - 1) < 0.08, (method, segment)
    mass = result.columns["mass_kg"]
    time = payload_change_drive["time_s"].to_numpy()
    assert abs(np.nanmedian(mass[time > 1300]) / 17_800 - 1) < 0.03


def test_too_little_excitation_gives_no_confident_number(payload_change_drive):
    vehicle = load_vehicle("rigid-18t")
    short = payload_change_drive.iloc[:200].copy()
    result = estimate_mass(short, vehicle)
    assert result.segments[0]["status"] in ("no_excitation", "uncertain")
    assert np.isnan(result.columns["mass_kg"]).all()


def test_no_valid_samples_says_why_and_gives_no_number(payload_change_drive):
    vehicle = load_vehicle("rigid-18t")
    idle = payload_change_drive.assign(engine_torque_nm=100.0)
    result = estimate_mass(idle, vehicle)
    assert "no sample passes the data filter" in result.notes[0] and "engine torque" in result.notes[0]
    assert all(s["mass_ls_kg"] is None for s in result.segments)
    with pytest.raises(UserError, match="engine_torque_nm"):
        estimate_mass(payload_change_drive.drop(columns=["engine_torque_nm"]), vehicle)


def test_survives_nans_and_gaps(payload_change_drive):
    vehicle = load_vehicle("rigid-18t")
    broken = payload_change_drive.copy()
    broken.loc[2000:2600, ["engine_torque_nm", "engine_speed_rpm"]] = np.nan
    broken.loc[15000:15100, "speed_mps"] = np.nan
    broken.loc[4000:4100, "gradient_pct"] = np.nan
    result = estimate_mass(broken, vehicle)
    for segment, truth in zip(result.segments, (12_500, 17_800)):
        assert abs(segment["mass_ls_kg"] / truth - 1) < 0.03, segment


@pytest.mark.parametrize("after_kg", [None, 14_000.0])
def test_a_payload_change_at_a_short_stop_is_found_from_the_data(after_kg):
    """A 20 s stop (shorter than the 60 s that always cuts): cut where the mass changed there,
    not where it did not (a red light)."""
    drive = synthetic_drive(stops_s=(900.0,), stop_duration_s=20.0, mass_after_stop_kg=after_kg)
    result = estimate_mass(drive.assign(gradient_pct=drive["true_gradient_pct"]), load_vehicle("rigid-18t"))
    if after_kg is None:
        assert len(result.segments) == 1
        return
    assert len(result.segments) == 2 and result.segments[0]["end_s"] < 900 < result.segments[1]["start_s"]
    for segment, true in zip(result.segments, (20_000.0, after_kg)):
        assert abs(segment["mass_kg"] / true - 1) < 0.02


def test_the_kernels_condition_number_is_numpys():
    """`small_linalg.condition_number_symmetric` (Jacobi, no LAPACK to compile) decides
    singularity as ``np.linalg.cond`` does, from well-conditioned to singular normal matrices."""
    from haulprofile.analysis.small_linalg import condition_number_symmetric
    rng = np.random.default_rng(5)
    for p in (1, 2, 3, 5):
        for spread in (1.0, 1e4, 1e8, 1e14):
            basis, _ = np.linalg.qr(rng.normal(size=(p, p)))
            normal = basis @ np.diag(np.geomspace(1.0, 1.0 / spread, p)) @ basis.T
            for fn in (condition_number_symmetric, condition_number_symmetric.py_func):
                np.testing.assert_allclose(fn(normal), np.linalg.cond(normal), rtol=1e-3 if spread < 1e14 else 0.5)
    assert condition_number_symmetric(np.zeros((2, 2))) == np.inf
    assert condition_number_symmetric(np.array([[1.0, 1.0], [1.0, 1.0]])) > 1e12
