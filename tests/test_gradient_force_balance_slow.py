"""The force balance with a first pass's masses (`gps+can`) measures at low speed too
(`gradient.force_balance.virtual_accelerometer_mps2`'s ``slow``)."""

import numpy as np

from haulprofile.analysis.vehicle import load_vehicle


def test_with_a_first_pass_mass_the_force_balance_also_measures_below_the_mass_filters_speed_floor():
    """The mass filter's 5.5 m/s is the paper's rule for the mass regression's excitation; as a
    gradient measurement the force balance holds below it (the ratio rule drops a slipping
    clutch): with ``slow`` it measures there too, the same value wherever both measure."""
    from haulprofile.analysis.gradient.force_balance import MOVING_SPEED_MPS, virtual_accelerometer_mps2
    from test_gradient import synthetic_drive
    drive = synthetic_drive().assign(gradient_pct=0.0)
    vehicle = load_vehicle("rigid-18t")
    mass = drive["true_mass_kg"].to_numpy()
    fast = virtual_accelerometer_mps2(drive, vehicle, mass)
    slow = virtual_accelerometer_mps2(drive, vehicle, mass, slow=True)
    speed = drive["speed_mps"].to_numpy()
    added = np.isfinite(slow) & ~np.isfinite(fast)
    assert added.sum() > 0 and np.all(speed[added] <= 5.5) and np.all(speed[added] > MOVING_SPEED_MPS)
    assert np.array_equal(np.isfinite(fast), np.isfinite(slow) & (speed > 5.5))
    both = np.isfinite(fast)
    assert np.allclose(fast[both], slow[both])
