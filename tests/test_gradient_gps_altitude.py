"""GPS altitude's urban error: the receiver's stated accuracy above its open-sky level, scaled by
what the altitude's own residual shows (`gradient.gps_altitude`, `SmootherSettings.gps_multipath_share`)."""
import numpy as np
import pytest
from haulprofile.analysis.gradient import GradientSettings, estimate_gradient
from haulprofile.analysis.gradient import gps_altitude
from haulprofile.analysis.gradient.force_balance import estimate_gradient_force_balance
from haulprofile.analysis.gradient.smoother import SmootherSettings
from haulprofile.analysis.vehicle import load_vehicle
from test_gradient import _road_slope_table, synthetic_drive

OPEN_SKY_M, TOWN_M, SHARE = 3.0, 7.5, 0.4
TOWN_DISTANCE_M = (12_000.0, 20_000.0)


def _gauss_markov(rng, n, steps):
    phi = np.exp(-1.0 / steps)
    out = np.empty(n)
    out[0] = rng.normal()
    shocks = rng.normal(0.0, np.sqrt(1 - phi ** 2), n)
    for k in range(1, n):
        out[k] = phi * out[k - 1] + shocks[k]
    return out


def test_the_open_sky_level_is_the_lowest_running_median_and_a_town_drive_has_no_excess():
    rng = np.random.default_rng(3)
    stated = OPEN_SKY_M * rng.uniform(0.9, 1.1, 3000)
    stated[1000:2500] *= TOWN_M / OPEN_SKY_M
    stated[::97] = np.nan
    # the lowest of many windows' medians lies a little below the typical level
    assert gps_altitude.open_sky_accuracy_m(stated, 10.0) == pytest.approx(OPEN_SKY_M, rel=0.1)
    in_town = TOWN_M * rng.uniform(0.9, 1.1, 3000)
    level = gps_altitude.open_sky_accuracy_m(in_town, 10.0)
    assert level == pytest.approx(TOWN_M, rel=0.1)
    assert np.mean(gps_altitude.excess_variance_m2(in_town, level) > level ** 2) == 0.0
    assert gps_altitude.open_sky_accuracy_m(np.full(10, np.nan), 10.0) is None


def test_the_share_is_what_the_residual_holds_of_the_stated_excess():
    """Residuals drawn with the open-sky variance plus 0.4 of the stated excess: the share comes
    back within 0.1; a tunnel's few huge accuracies with small residuals do not move it much; too
    few town bins tell nothing."""
    rng = np.random.default_rng(5)
    n = 4000
    stated = np.full(n, OPEN_SKY_M)
    stated[1500:3500] = TOWN_M
    excess = stated ** 2 - OPEN_SKY_M ** 2
    residual = rng.normal(0.0, 1.0, n) * np.sqrt(OPEN_SKY_M ** 2 + SHARE * excess)
    height_var = np.zeros(n)
    share = gps_altitude.multipath_share(residual, height_var, stated, OPEN_SKY_M)
    assert share == pytest.approx(SHARE, abs=0.1)
    tunnel = stated.copy()
    tunnel[3500:3530] = 60.0
    assert gps_altitude.multipath_share(residual, height_var, tunnel, OPEN_SKY_M) == pytest.approx(share, abs=0.05)
    few = np.full(n, OPEN_SKY_M)
    few[:gps_altitude.MIN_EXCESS_BINS - 1] = TOWN_M
    assert gps_altitude.multipath_share(residual, height_var, few, OPEN_SKY_M) is None
    # the variance: the open-sky part as stated, the excess scaled; share 1 is the stated accuracy
    variance = gps_altitude.altitude_variance_m2(stated, 3.0, OPEN_SKY_M, SHARE)
    np.testing.assert_allclose(variance, 9.0 * (OPEN_SKY_M ** 2 + SHARE * excess))
    np.testing.assert_allclose(gps_altitude.altitude_variance_m2(stated, 3.0, OPEN_SKY_M, 1.0), (3.0 * stated) ** 2)


@pytest.fixture(scope="module")
def drive():
    return synthetic_drive()


def _gps_log(drive, town: bool, seed=11):
    """GPS altitude alone: an open-sky error of 3 m correlated over 30 s everywhere and, in the
    town, a multipath error of 0.4 of the stated excess variance, correlated over 1 s, while the
    receiver states 7.5 m there."""
    rng = np.random.default_rng(seed)
    n = len(drive)
    distance = drive["distance_m"].to_numpy()
    in_town = town & (distance > TOWN_DISTANCE_M[0]) & (distance < TOWN_DISTANCE_M[1])
    stated = np.where(in_town, TOWN_M, OPEN_SKY_M) * rng.uniform(0.95, 1.05, n)
    multipath = np.sqrt(SHARE * (TOWN_M ** 2 - OPEN_SKY_M ** 2)) * _gauss_markov(rng, n, 10.0)
    error = OPEN_SKY_M * _gauss_markov(rng, n, 300.0) + np.where(in_town, multipath, 0.0)
    return drive.drop(columns=["pressure_pa", "accel_x_mps2"]).assign(
        gps_altitude_m=drive["true_height_m"] + error, gps_v_acc_m=stated)


def _town_errors(result):
    grid = result.grid
    s = grid["distance_m"].to_numpy()
    truth = 100 * np.interp(s, *_road_slope_table(s.max()))
    keep = (s > TOWN_DISTANCE_M[0] + 500) & (s < TOWN_DISTANCE_M[1] - 500)
    return grid["gradient_pct"].to_numpy()[keep] - truth[keep], grid["gradient_smooth_std_pct"].to_numpy()[keep]


def _share_in_notes(result):
    notes = [n for n in result.notes if n.startswith("GPS altitude: of the receiver's stated variance")]
    return float(notes[0].split("its residual shows ")[1].split(";")[0]) if notes else None


def test_without_imu_and_barometer_the_share_is_found_in_the_residual_and_the_sigma_holds(drive):
    """`gps+can` (the force balance and GPS altitude): the share found through the smoother is
    near the 0.4 put in (its residual against a profile that follows GPS a little reads low), a
    note says it, the town's bins keep the truth inside ±2σ; with the setting off (a log with an
    IMU) there is no share."""
    log = _gps_log(drive, town=True)
    result = estimate_gradient_force_balance(log, None, load_vehicle("rigid-18t"))
    assert 0.25 <= _share_in_notes(result) <= 0.6
    error, std = _town_errors(result)
    assert np.mean(np.abs(error) <= 2 * std) >= 0.9
    assert _share_in_notes(estimate_gradient(log, None)) is None


def test_without_a_town_the_share_changes_nothing(drive):
    log = _gps_log(drive, town=False)
    plain = estimate_gradient(log, None).grid
    shared = estimate_gradient(log, None, GradientSettings(smoother=SmootherSettings(gps_multipath_share=True))).grid
    np.testing.assert_array_equal(plain["gradient_pct"].to_numpy(), shared["gradient_pct"].to_numpy())
    np.testing.assert_array_equal(plain["gradient_smooth_std_pct"].to_numpy(),
                                  shared["gradient_smooth_std_pct"].to_numpy())
