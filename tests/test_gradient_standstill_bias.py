"""The accelerometer's bias step at a long standstill (`gradient.standstill_bias`): measured where
the truck stands, taken out of the accelerometer before the smoother and put back into the bias
it states, so that the stretches either side of the stop do not read high and low by it (in the
gradient, and in the mass's accelerometer regressor and the road load fitted with it)."""

import numpy as np
import pytest

from haulprofile.analysis.dem.srtm import SrtmDem
from haulprofile.analysis.gradient import estimate_gradient
from haulprofile.analysis.gradient.estimate import GradientSettings
from haulprofile.analysis.gradient.smoother import SmootherSettings
from haulprofile.analysis.gradient.standstill_bias import StepSettings, standstill_steps, step_offsets
from haulprofile.analysis.mass import estimate_mass
from haulprofile.analysis.vehicle import load_vehicle
from test_gradient import synthetic_drive, write_route_dem

STOP_S, STOP_LENGTH_S = 1200.0, 600.0
STEP_MPS2 = -0.03
"""The bias's step over the stop: a cab warming by 3 K at 1 mg/K, or the tractor's pitch 0.18°
lower on its springs under a new trailer."""
MASSES_KG = (20_000.0, 12_000.0)
STIFF = SmootherSettings(bias_psd_candidates=())
"""The smoother with its bias's slowest random walk (what the likelihood picks on most drives of
the accuracy matrix): it cannot follow a step within the driving either side of the stop."""


def _ramp(time_s, start_s, length_s, step):
    return step * np.clip((time_s - start_s) / length_s, 0, 1)


@pytest.fixture(scope="module")
def drive():
    """A 10 Hz drive with a 10-minute stop and a new load there, the accelerometer's bias
    (0.05 m/s² of mounting pitch) moving by the step while the truck stands."""
    frame = synthetic_drive(duration_s=2400.0, stops_s=(STOP_S,), stop_duration_s=STOP_LENGTH_S,
                            mass_after_stop_kg=MASSES_KG[1], mass_kg=MASSES_KG[0])
    time_s = frame["time_s"].to_numpy()
    excess = frame["accel_mps2"].to_numpy() + 9.81 * np.sin(np.arctan(frame["true_gradient_pct"].to_numpy() / 100))
    bias = 0.05 + _ramp(time_s, STOP_S - STOP_LENGTH_S / 2, STOP_LENGTH_S, STEP_MPS2)
    noise = np.random.default_rng(3).normal(0, 0.02, len(frame))
    return frame.assign(accel_x_mps2=excess + bias + noise, true_bias_mps2=bias)


def test_a_standstill_measures_the_step_beyond_its_noise_and_nothing_else():
    time_s = np.arange(0, 400, 0.1)
    speed = np.where((time_s > 100) & (time_s < 300), 0.0, 15.0)
    noise = np.random.default_rng(0).normal(0, 0.02, len(time_s))
    accel = 0.2 + _ramp(time_s, 100, 200, STEP_MPS2) + noise
    (step,) = standstill_steps(time_s, speed, accel)
    # the windows' means lie 5 s inside either end and are 20 s long: 170 s of the 200 s ramp lie between them
    assert step.step_mps2 == pytest.approx(STEP_MPS2 * 170 / 200, abs=3 * step.std_mps2)
    # 0.02 m/s² of white noise over two 20 s windows at 10 Hz: 0.02 · sqrt(2 / 200)
    assert step.std_mps2 == pytest.approx(0.02 * np.sqrt(2 / 200), rel=0.5)
    assert standstill_steps(time_s, speed, 0.2 + noise) == []  # no step: nothing beyond the noise
    assert standstill_steps(time_s, np.where((time_s > 100) & (time_s < 150), 0.0, 15.0), accel) == []  # short
    assert standstill_steps(time_s, np.where(time_s < 200, 0.0, 15.0), accel) == []  # no driving before it


def test_the_offsets_ramp_between_the_windows_and_the_clock_leaves_the_standstill_out():
    time_s = np.arange(0, 400, 0.1)
    speed = np.where((time_s > 100) & (time_s < 300), 0.0, 15.0)
    accel = 0.2 + _ramp(time_s, 100, 200, STEP_MPS2) + np.random.default_rng(0).normal(0, 0.002, len(time_s))
    steps = standstill_steps(time_s, speed, accel)
    offset, std, clock = step_offsets(time_s, steps)
    settings = StepSettings()
    early = 100.1 + settings.settle_s + settings.window_s / 2
    late = 299.9 - settings.settle_s - settings.window_s / 2
    assert np.all(offset[time_s <= early] == 0) and np.all(offset[time_s >= late] == steps[0].step_mps2)
    assert clock[-1] == pytest.approx(time_s[-1] - (late - early))
    assert np.all(std == steps[0].std_mps2)


@pytest.fixture(scope="module")
def route_dem(tmp_path_factory):
    return SrtmDem(write_route_dem(tmp_path_factory.mktemp("dem")))


@pytest.mark.parametrize("with_dem", [False, True])
def test_the_bias_either_side_of_a_standstill_carries_its_step(drive, with_dem, request):
    """Without the step the smoother's one bias across the stop is low before it and high after
    it (with the barometer, and with the DEM too); with it both stretches read their own, and the
    gradient with them."""
    source = request.getfixturevalue("route_dem") if with_dem else None
    time_s = drive["time_s"].to_numpy()
    moving = drive["speed_mps"].to_numpy() > 3
    before, after = moving & (time_s < STOP_S), moving & (time_s > STOP_S)
    errors = {}
    for on in (False, True):
        result = estimate_gradient(drive, source, GradientSettings(imu_standstill_steps=on, smoother=STIFF))
        error = result.samples["imu_bias_mps2"] - drive["true_bias_mps2"].to_numpy()
        gradient = result.samples["gradient_smooth_pct"] - drive["true_gradient_pct"].to_numpy()
        errors[on] = (np.nanmean(error[before]), np.nanmean(error[after]), np.sqrt(np.nanmean(gradient[moving] ** 2)))
        assert any("stepped by" in note for note in result.notes) == on
    print(errors)
    assert errors[False][1] - errors[False][0] > 0.01
    assert abs(errors[True][0]) < 0.003 and abs(errors[True][1]) < 0.003
    assert errors[True][2] < errors[False][2]


def test_a_bias_step_is_read_neither_as_road_load_nor_as_mass(drive):
    """The mass's accelerometer regressor with the smoother's bias: without the step the joint fit
    takes it for road load on this drive (c_r -28 %; on the matrix's long-haul drive it went into
    the mass after the stop instead); with it, c_r and the masses are the drive's."""
    vehicle = load_vehicle("rigid-18t")
    fits = {}
    for on in (False, True):
        samples = estimate_gradient(drive, None, GradientSettings(imu_standstill_steps=on, smoother=STIFF)).samples
        result = estimate_mass(drive.assign(**samples), vehicle)
        assert [s["mass_regressor"] for s in result.segments] == ["imu", "imu"]
        fits[on] = (result.road_load["rolling_resistance_coefficient"]["value"],
                    np.array([s["mass_kg"] for s in result.segments]) / np.array(MASSES_KG) - 1)
    print(fits)
    assert fits[False][0] < 0.8 * vehicle.rolling_resistance_coefficient
    assert fits[True][0] == pytest.approx(vehicle.rolling_resistance_coefficient, rel=0.1)
    assert np.all(np.abs(fits[True][1]) < 0.01)
