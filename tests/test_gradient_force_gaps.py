"""The force balance over windows of known force between brake applications and across gear
shifts (`gradient.force_gaps`), and its use in the `gps+can` force balance."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.gradient import force_gaps
from haulprofile.analysis.road_load import AIR_DENSITY_KGPM3, G_MPS2
from haulprofile.analysis.vehicle import load_vehicle

MASS_KG = 16_000.0
SHIFT_S = 1.0


def road_gradient_pct(distance_m):
    """A road that rises and falls by 3 % over 240 m."""
    return 3.0 * np.sin(2 * np.pi * np.asarray(distance_m) / 240.0)


def stop_and_go_log(seed=5, cycles=14, wheel_noise_mps=0.014, gap_torque_nm=300.0):
    """A 10 Hz log of an urban truck (rigid-18t, 16 t): each cycle pulls away through the gears
    with a 1-s shift at 1450 rpm (ETC2 reports gear 0 while the clutch is open; the engine's report
    then reads ``gap_torque_nm``, which does not reach the wheels), cruises, and brakes to a stop.
    Speed is the wheel speed's reading at each sample, the torque its bin's mean, as ingest makes
    them; returns the frame, the vehicle and the true g sin(alpha) per sample."""
    vehicle = load_vehicle("rigid-18t")
    rng = np.random.default_rng(seed)
    ratios = np.asarray(vehicle.total_ratios)
    r, eta, c_r = vehicle.wheel_radius_m, vehicle.driveline_efficiency, vehicle.rolling_resistance_coefficient
    dt = 0.1
    rows = []
    s, v, gear, shift_left, target_gear = 0.0, 0.0, 1, 0.0, 1
    for cycle in range(cycles):
        phase_s = 0.0
        for k in range(int(90 / dt)):
            t = len(rows) * dt
            alpha = np.arctan(road_gradient_pct(s) / 100)
            resistance = MASS_KG * G_MPS2 * (c_r * np.cos(alpha) + np.sin(alpha)) \
                + 0.5 * AIR_DENSITY_KGPM3 * vehicle.drag_coefficient * vehicle.frontal_area_m2 * v * v
            braking = phase_s > 60.0
            brake, reported = False, 0.0
            if braking:
                force = -MASS_KG * 1.2 if v > 0 else 0.0
                brake, gear_out, rpm = v > 0, gear, max(v / r * ratios[gear - 1] * 30 / np.pi, 600.0)
                reported = -60.0
            elif shift_left > 0:
                force, gear_out = 0.0, 0
                rpm = v / r * ratios[target_gear - 1] * 30 / np.pi
                reported = gap_torque_nm
                shift_left -= dt
                if shift_left <= 1e-9:
                    gear = target_gear
            else:
                rpm = max(v / r * ratios[gear - 1] * 30 / np.pi, 600.0)
                if rpm > 1450 and gear < len(ratios) and v < 13.0:
                    target_gear, shift_left = gear + 1, SHIFT_S
                wanted = MASS_KG * (0.5 if v < 14.0 else 0.0) + resistance
                reported = float(np.clip(wanted * r / (eta * ratios[gear - 1]), 0, 1800))
                force, gear_out = eta * ratios[gear - 1] * reported / r, gear
            accel = (force - resistance) / MASS_KG if not (braking and v <= 0) else 0.0
            if v + accel * dt < 0:
                accel = -v / dt
            rows.append((t, v, rpm, reported, gear_out, float(brake), G_MPS2 * np.sin(alpha)))
            s += v * dt + 0.5 * accel * dt * dt
            v = max(v + accel * dt, 0.0)
            phase_s += dt
            if braking and v == 0:
                gear, target_gear, shift_left = 1, 1, 0.0
    frame = pd.DataFrame(rows, columns=["time_s", "true_speed_mps", "engine_speed_rpm", "engine_torque_nm",
                                        "current_gear", "brake_switch", "true_sine_mps2"])
    noisy = frame["true_speed_mps"] + rng.normal(0, wheel_noise_mps, len(frame)) * (frame["true_speed_mps"] > 0.3)
    frame["speed_mps"] = np.maximum(np.round(noisy * 3.6 * 256) / 256 / 3.6, 0.0)
    return frame, vehicle


def old_filter_samples(frame, vehicle):
    from haulprofile.analysis.gradient.force_balance import virtual_accelerometer_mps2
    from haulprofile.analysis.kinematics import acceleration_mps2
    with_accel = frame.assign(accel_mps2=acceleration_mps2(frame["time_s"], frame["speed_mps"]), gradient_pct=0.0)
    return np.isfinite(virtual_accelerometer_mps2(with_accel, vehicle, np.full(len(frame), MASS_KG), slow=True))


def test_across_a_shift_with_the_clutch_open_the_force_balance_reads_the_gradient_within_its_sigma():
    """With ETC2 reporting no gear the engine does not drive the wheels, whatever its torque report
    says (here 300 Nm): the windows over the shift give g sin(alpha) where the data filter has no
    sample, within their stated sigma from the wheel speed's noise."""
    frame, vehicle = stop_and_go_log()
    sine, accel, variance = force_gaps.windowed_force_balance(frame, vehicle, MASS_KG, 1.0, 200.0, 1.0)
    opened = frame["current_gear"].to_numpy() == 0
    moving = frame["true_speed_mps"].to_numpy() > 1.0
    gap = opened & moving
    assert gap.sum() > 100 and not old_filter_samples(frame, vehicle)[gap].any()
    assert np.isfinite(sine[gap]).all()
    error = sine - frame["true_sine_mps2"].to_numpy()
    z = error[gap] / np.sqrt(variance[gap])
    assert np.mean(np.abs(z) <= 2) >= 0.9
    assert abs(np.mean(error[gap])) < 0.01


def test_the_noise_is_the_wheel_speeds_from_its_own_second_differences():
    frame, _ = stop_and_go_log(wheel_noise_mps=0.02)
    found = force_gaps.wheel_speed_noise_mps(frame["speed_mps"].to_numpy(), 1.0)
    assert found == pytest.approx(0.02, rel=0.15)


def test_no_window_reaches_into_the_brakes_margin_nor_across_an_unreported_shift():
    """Between brake readings the brake may act unseen: the windows keep the data filter's margin
    from them, as from a change of gear with no neutral reported between."""
    frame, vehicle = stop_and_go_log(cycles=3)
    sine, _, _ = force_gaps.windowed_force_balance(frame, vehicle, MASS_KG, 1.0, 200.0, 1.0)
    near_brake = force_gaps.near(frame["brake_switch"].to_numpy() > 0.5, frame, 1.0)
    assert near_brake.any() and not np.isfinite(sine[near_brake]).any()
    gear = frame["current_gear"].to_numpy()
    direct = gear.astype(float)
    direct[gear == 0] = np.nan
    direct = pd.Series(direct).ffill().bfill().to_numpy()  # the neutral not reported
    sine_direct, _, _ = force_gaps.windowed_force_balance(frame.assign(current_gear=direct), vehicle, MASS_KG, 1.0,
                                                          200.0, 1.0)
    changed = force_gaps.near(np.concatenate([[False], np.diff(direct) != 0]), frame, 1.0)
    assert changed.any() and not np.isfinite(sine_direct[changed]).any()


def test_with_gps_altitude_the_gradient_across_the_shifts_is_the_force_balances(monkeypatch):
    """`gps+can` with a first pass's masses: the bins the data filter left without a sample around
    the shifts were GPS altitude's (1.34 %-pt RMS here, 94 % inside ±2σ); with the windows across
    the clutch-open gaps the force balance measures there too (0.46 %-pt, 97 %)."""
    from haulprofile.analysis.gradient import force_balance
    from haulprofile.analysis.gradient.force_balance import estimate_gradient_force_balance
    from haulprofile.analysis.kinematics import acceleration_mps2, distance_m
    frame, vehicle = stop_and_go_log()
    rng = np.random.default_rng(11)
    time_s, speed = frame["time_s"].to_numpy(), frame["speed_mps"].to_numpy()
    distance = distance_m(time_s, frame["true_speed_mps"].to_numpy())
    height = np.concatenate([[0.0], np.cumsum(np.diff(distance) * road_gradient_pct(distance[1:]) / 100)])
    phi = np.exp(-0.1 / 30.0)
    noise = np.zeros(len(frame))
    for k in range(1, len(frame)):
        noise[k] = phi * noise[k - 1] + rng.normal(0, 4.0 * np.sqrt(1 - phi ** 2))
    log = frame.drop(columns=["true_speed_mps", "true_sine_mps2"]).assign(
        distance_m=distance_m(time_s, speed), accel_mps2=acceleration_mps2(time_s, speed),
        gps_altitude_m=height + noise, gps_v_acc_m=4.0)
    mass = np.full(len(frame), MASS_KG)
    monkeypatch.setattr(force_balance, "segment_masses_kg", lambda f, v: (mass, 0.03 * mass, np.zeros(len(mass))))

    def shift_bins_error(enabled):
        monkeypatch.setattr(force_balance, "FORCE_GAPS", enabled)
        grid = estimate_gradient_force_balance(log, None, vehicle).grid
        s = grid["distance_m"].to_numpy()
        dropped = ~old_filter_samples(frame, vehicle) & (frame["current_gear"].to_numpy() == 0) & (speed > 1.0)
        bins = np.unique(np.floor(log["distance_m"].to_numpy()[dropped] / 10).astype(int))
        bins = bins[(bins > 20) & (bins < len(s) - 20)]
        error = grid["gradient_pct"].to_numpy()[bins] - road_gradient_pct(s[bins])
        within = np.abs(error) <= 2 * grid["gradient_smooth_std_pct"].to_numpy()[bins]
        return float(np.sqrt(np.mean(error ** 2))), float(np.mean(within))

    before, _ = shift_bins_error(False)
    after, within = shift_bins_error(True)
    assert after < 0.5 * before
    assert within >= 0.9


def test_where_the_brake_may_act_the_windows_bound_the_gradient_from_above():
    """The brakes only take force away: over windows that span brake readings, the force balance
    with the engine's force alone is an upper bound of g sin(alpha), within its sigma."""
    frame, vehicle = stop_and_go_log(cycles=4)
    measured, _, _ = force_gaps.windowed_force_balance(frame, vehicle, MASS_KG, 1.0, 200.0, 1.0)
    bound, _, variance = force_gaps.windowed_force_balance(frame, vehicle, MASS_KG, 1.0, 200.0, 1.0, brakes=False)
    braking = frame["brake_switch"].to_numpy() > 0.5
    assert np.isfinite(bound[braking]).sum() > 100 and not np.isfinite(measured[braking]).any()
    truth = frame["true_sine_mps2"].to_numpy()
    spans = np.isfinite(bound) & ~np.isfinite(measured)
    assert np.mean(bound[spans] + 2 * np.sqrt(variance[spans]) >= truth[spans]) >= 0.97


def test_with_a_given_mass_the_windows_keep_the_mass_filters_speed_floor():
    """`can-only` (a given mass) keeps the data filter's 5.5 m/s floor: the windows add the shift
    gaps above it, none below, and leave the filter's own samples as they were."""
    from haulprofile.analysis.gradient.force_balance import _force_filter, _with_force_gaps, virtual_accelerometer_mps2
    from haulprofile.analysis.kinematics import acceleration_mps2
    frame, vehicle = stop_and_go_log(cycles=4)
    frame = frame.assign(accel_mps2=acceleration_mps2(frame["time_s"], frame["speed_mps"]), gradient_pct=0.0)
    mass = np.full(len(frame), MASS_KG)
    virtual = virtual_accelerometer_mps2(frame, vehicle, mass)
    floor = _force_filter(True).min_speed_mps
    gaps = _with_force_gaps(frame, vehicle, mass, virtual, frame["accel_mps2"].to_numpy(), floor)
    added, variance = gaps.added, gaps.variance_m2ps4
    speed = frame["speed_mps"].to_numpy()
    opened = frame["current_gear"].to_numpy() == 0
    assert added.sum() > 0 and (added & opened).any()
    assert np.all(speed[added] > floor)
    assert np.array_equal(gaps.virtual_mps2[~added], virtual[~added], equal_nan=True)
    assert np.all(variance[~added] == 0) and np.all(variance[added] > 0)
