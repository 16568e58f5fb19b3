"""The wheel odometer's scale against the GPS track (`distance_scale`), and the gradient and mass
on the kinematics stage's distance and speed at the track's scale, ε applied once."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.distance_scale import wheel_distance_scale
from haulprofile.analysis.geodesy import EARTH_RADIUS_M

LATITUDE_DEG, LONGITUDE_DEG = 50.5, 7.3


def _log(scale_error, seed=0, town=slice(0, 0)):
    """10 Hz samples along a road with a long bend, GPS fixes at 1 Hz held between them (open-sky
    error 1.3 m correlated over 30 s; in ``town``, seconds of the drive, 8 m correlated over 5 s
    with a stated accuracy five times the open-sky one), ``distance_m`` from a wheel reading
    (1 + ``scale_error``) times the true distance."""
    rng = np.random.default_rng(seed)
    time_s = np.arange(0.0, 1200.0, 0.1)
    speed = 18 + 5 * np.sin(time_s / 90)
    path = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * 0.1)])
    heading = 0.6 * np.sin(path / 3000)
    step = np.diff(path, prepend=0.0)
    east, north = np.cumsum(step * np.cos(heading)), np.cumsum(step * np.sin(heading))
    fix_s = np.arange(0, 1200)
    in_town = (fix_s >= town.start) & (fix_s < town.stop)
    jitter = np.empty((len(fix_s), 2))
    state = rng.normal(size=2)
    for k in range(len(fix_s)):
        tau = 5.0 if in_town[k] else 30.0
        phi = np.exp(-1 / tau)
        state = phi * state + np.sqrt(1 - phi * phi) * rng.normal(size=2)
        jitter[k] = state * (8.0 if in_town[k] else 1.3)
    at = np.searchsorted(time_s, fix_s)
    fix_east, fix_north = east[at] + jitter[:, 0], north[at] + jitter[:, 1]
    held = np.searchsorted(fix_s, time_s, side="right") - 1
    lat = LATITUDE_DEG + np.degrees(fix_north / EARTH_RADIUS_M)
    lon = LONGITUDE_DEG + np.degrees(fix_east / (EARTH_RADIUS_M * np.cos(np.radians(LATITUDE_DEG))))
    h_acc = np.where(in_town, 9.0, 1.8) * rng.uniform(0.9, 1.1, len(fix_s))
    return pd.DataFrame({"time_s": time_s, "speed_mps": speed * (1 + scale_error),
                         "distance_m": path * (1 + scale_error), "latitude_deg": lat[held],
                         "longitude_deg": lon[held], "gps_h_acc_m": h_acc[held]})


@pytest.mark.parametrize("scale_error", [-0.025, 0.012, 0.004])
def test_the_odometers_scale_from_the_gps_track(scale_error):
    assert wheel_distance_scale(_log(scale_error)) == pytest.approx(scale_error, abs=1e-3)


def test_a_scale_the_track_cannot_tell_from_zero_is_not_told():
    """An odometer that reads true: the track's blocks scatter around 0 by more than half the
    estimate, and no correction smaller than its own uncertainty is made."""
    assert wheel_distance_scale(_log(0.0)) is None


def test_a_towns_jittering_fixes_do_not_lengthen_the_track(monkeypatch):
    """Multipath makes the steps jitter by metres: counted, the track reads long (the scale short);
    the fixes whose stated accuracy shows it are left out. Where the accuracy does not show it, the
    town's blocks scatter, and the scale is not told."""
    from haulprofile.analysis import distance_scale

    log = _log(0.02, seed=1, town=slice(300, 700))
    assert wheel_distance_scale(log) == pytest.approx(0.02, abs=1e-3)
    every_fix = log.assign(gps_h_acc_m=1.8)
    assert wheel_distance_scale(every_fix) is None
    monkeypatch.setattr(distance_scale, "SIGNIFICANCE", 0.0)
    assert wheel_distance_scale(every_fix) < 0.015


def test_no_track_no_scale():
    log = _log(0.02)
    assert wheel_distance_scale(log.drop(columns=["latitude_deg"])) is None
    assert wheel_distance_scale(log.iloc[:500]) is None


def test_the_gradient_over_the_kinematics_distance_reads_true_once():
    """A 3 % climb whose GPS altitude is at each fix's true place, the wheel 2 % long: the
    kinematics stage takes the distance to the track's scale and the gradient reads 3.0 %, not
    3 × 1.02 or 3 / 1.02 (ε applied once); with the correction off, over the wheel's distance,
    3 / 1.02 %. The grid's distance is the signals' own."""
    from haulprofile.analysis.gradient.force_balance import estimate_gradient_for_log
    from haulprofile.analysis.kinematics import KinematicsOptions, add_kinematics

    log = _log(0.02)
    rng = np.random.default_rng(3)
    true_m = log["distance_m"].to_numpy() / 1.02
    log = log.assign(gps_altitude_m=0.03 * true_m + rng.normal(0, 0.3, len(log)), gps_v_acc_m=1.0)
    median = {}
    for over_track in (True, False):
        frame = log.drop(columns=["distance_m"])
        add_kinematics(frame, KinematicsOptions(speed_over_track=over_track))
        result = estimate_gradient_for_log(frame, None)
        median[over_track] = float(np.nanmedian(result.samples["gradient_pct"]))
        assert result.grid["distance_m"].max() == pytest.approx(frame["distance_m"].max(), abs=20.0)
    assert median[True] == pytest.approx(3.0, abs=0.01)
    assert median[False] == pytest.approx(3.0 / 1.02, abs=0.01)


def test_the_mass_takes_the_signals_speed_as_it_is(monkeypatch):
    """The kinematics stage gave the speed and acceleration at the track's scale: the mass's
    regression gets them unchanged, with or without the gradient's posterior (no second division
    by 1 + ε, which a posterior naming ε made before)."""
    from haulprofile.analysis import mass

    class Built(Exception):
        pass

    seen = []

    def build_regression(frame, vehicle, settings):
        seen.append(frame[["gradient_pct", "speed_mps", "accel_mps2"]].to_numpy().copy())
        raise Built

    log = _log(0.02).assign(gradient_pct=2.0, gradient_std_pct=0.1, accel_mps2=0.3)

    class Posterior:
        distance_scale = 0.02

        def describes(self, gradient_pct):
            return True

    monkeypatch.setattr(mass, "build_regression", build_regression)
    for posteriors in ((Posterior(),), ()):
        with pytest.raises(Built):
            mass.estimate_mass(log, vehicle=None, gradient_posteriors=posteriors)
    for columns in seen:
        np.testing.assert_array_equal(columns, log[["gradient_pct", "speed_mps", "accel_mps2"]].to_numpy())


def test_a_fast_receivers_jitter_is_taken_a_second_apart_and_a_wild_scale_is_none():
    """Positions jittering white by 1.5 m in every 10 Hz row: steps of 2 m would read the track 46 %
    long; fixes a second apart read it within 1 %. A scale no tyre makes (the distance doubled) is
    not told."""
    log = _log(0.02)
    rng = np.random.default_rng(5)
    metres = 1.5 / EARTH_RADIUS_M
    jittered = log.assign(latitude_deg=log["latitude_deg"] + np.degrees(rng.normal(0, metres, len(log))),
                          longitude_deg=log["longitude_deg"] + np.degrees(rng.normal(0, metres, len(log))
                                                                          / np.cos(np.radians(LATITUDE_DEG))))
    assert wheel_distance_scale(jittered) == pytest.approx(0.02, abs=0.01)
    assert wheel_distance_scale(log.assign(distance_m=2 * log["distance_m"])) is None
