"""The LS of (9) standing in for the joint fit: its uncertainty holds what it leaves out (wind,
c_r, c_d·A, torque offset, accessories), not only its own scatter."""

from dataclasses import replace

import numpy as np

from haulprofile.analysis.mass.joint import JointSettings
from haulprofile.analysis.mass.unmodelled import ls_unmodelled_kg
from haulprofile.analysis.road_load import AIR_DENSITY_KGPM3, G_MPS2
from haulprofile.analysis.vehicle import load_vehicle

VEHICLE = load_vehicle("rigid-18t")
NOTHING = dict(drag_area_uncertainty=0.0, rolling_resistance_uncertainty=0.0, torque_offset_uncertainty=0.0)


def _segment(rng, n=3000):
    """10 Hz samples of urban driving: speed, acceleration and gradient, and the LS regressor."""
    t = np.arange(n) * 0.1
    speed = 9 + 4 * np.sin(t / 40) + 2 * np.sin(t / 9)
    accel = np.gradient(speed, t)
    angle = np.arctan(0.02 * np.sin(t / 50) + rng.normal(0, 0.001))
    phi = accel + G_MPS2 * (VEHICLE.rolling_resistance_coefficient * np.cos(angle) + np.sin(angle))
    keep = phi > 0.1
    return speed[keep], phi[keep], np.cos(angle)[keep]


def test_the_ls_holds_the_head_wind_it_leaves_out():
    """A steady head wind h the LS does not model adds ρ c_d A (v h + h²/2) to the force its mass
    is fitted to. Drawn per drive from the joint fit's prior (5 m/s per component), over 200 drives
    the LS's error lies inside ±2σ of the wind's term on 95 % of them, RMS z 1.03 (N(0, 1): 95 %,
    1); its statistical uncertainty alone (the jackknife, what the LS stood in with) held none (0 of
    200: the samples here have no noise)."""
    rng = np.random.default_rng(3)
    settings = replace(JointSettings(), **NOTHING)
    mass = 14_000.0
    cda = VEHICLE.drag_coefficient * VEHICLE.frontal_area_m2
    inside, ratio = [], []
    for _ in range(200):
        speed, phi, cos_angle = _segment(rng)
        head = rng.normal(0.0, settings.wind_sigma_mps)
        y = mass * phi + AIR_DENSITY_KGPM3 * cda * (speed * head + 0.5 * head ** 2)
        error = np.sum(phi * y) / np.sum(phi * phi) - mass
        sigma = ls_unmodelled_kg(phi, y, speed, cos_angle, mass, VEHICLE, settings)
        inside.append(abs(error) <= 2 * sigma)
        ratio.append(error / sigma)
    assert 0.92 <= np.mean(inside) <= 0.99, np.mean(inside)
    assert 0.7 <= np.sqrt(np.mean(np.square(ratio))) <= 1.1


def test_each_left_out_term_adds_and_none_without_samples():
    """Every prior the joint fit carries widens the LS's term (c_r, c_d·A, the torque offset's and
    the accessories' columns); with nothing left out it is 0; with no usable sample, NaN."""
    rng = np.random.default_rng(0)
    speed, phi, cos_angle = _segment(rng)
    y = 14_000.0 * phi
    offset, aux = np.full(len(phi), 900.0), np.full(len(phi), 0.08)
    none = replace(JointSettings(), wind_sigma_mps=0.0, **NOTHING)
    assert ls_unmodelled_kg(phi, y, speed, cos_angle, 14_000.0, VEHICLE, none, offset) == 0.0
    base = ls_unmodelled_kg(phi, y, speed, cos_angle, 14_000.0, VEHICLE, JointSettings(), offset)
    for name in ("wind_sigma_mps", *NOTHING):
        alone = replace(none, **{name: getattr(JointSettings(), name)})
        assert 0 < ls_unmodelled_kg(phi, y, speed, cos_angle, 14_000.0, VEHICLE, alone, offset) < base
    assert ls_unmodelled_kg(phi, y, speed, cos_angle, 14_000.0, VEHICLE, JointSettings(), offset, aux, 800.0) > base
    assert np.isnan(ls_unmodelled_kg(np.full(5, np.nan), y[:5], speed[:5], cos_angle[:5], 14_000.0, VEHICLE,
                                     JointSettings()))
