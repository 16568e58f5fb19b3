"""What the LS of (9) leaves out of a segment's mass that the joint fit models, as 1-sigma [kg].

Where the joint fit has too few samples for a segment (too few pass its filter at all: a GPS
outage no longer takes them, `joint.fit_joint` fits them with their head wind in σ), the LS stands
in (`mass._joint`). It takes the vehicle file's c_r and c_d·A, no
wind, no torque offset and no auxiliary power, so its statistical error (jackknife, gradient
bias) is not all its error: each of those is one unknown of the drive, fully correlated over the
segment, and moves the LS mass by dm = Σ φ ΔF / Σ φ² (φ the LS regressor, ΔF the force it leaves
out). Their sizes are the joint fit's priors (`JointSettings`), the same a drive that cannot
identify them puts into its masses.
"""

from __future__ import annotations

import numpy as np

from ..road_load import AIR_DENSITY_KGPM3, G_MPS2


def ls_unmodelled_kg(phi, y, speed_mps, cos_angle, mass_kg: float, vehicle, settings, offset=None, aux=None,
                     aux_width_w: float | None = None) -> float:
    """1-sigma [kg] of the LS mass ``mass_kg`` from what it leaves out, over the samples where
    ``phi`` and ``y`` are finite (the LS's): a head wind of ``wind_sigma_mps`` (the linear term
    ρ c_d A v h and the quadratic ½ ρ c_d A h², RMS), c_d·A and c_r off by their datasheet
    uncertainties, a torque offset of ``torque_offset_uncertainty`` (``offset``: its force column
    per reference torque) and an auxiliary power of ``aux_width_w`` (``aux``: force per watt; None:
    ``aux_power_sigma_w``), summed as independent terms."""
    phi, y = np.asarray(phi, dtype=float), np.asarray(y, dtype=float)
    used = np.isfinite(phi) & np.isfinite(y)
    if not used.any():
        return np.nan
    p = phi[used]
    norm = float(np.sum(p * p))
    if not norm > 0:
        return np.nan
    speed = np.asarray(speed_mps, dtype=float)[used]
    cda = vehicle.drag_coefficient * vehicle.frontal_area_m2
    wind = settings.wind_sigma_mps
    terms = [
        wind * np.sum(p * AIR_DENSITY_KGPM3 * cda * speed),
        np.sqrt(3.0) * 0.5 * AIR_DENSITY_KGPM3 * cda * wind ** 2 * np.sum(p),  # E h⁴ = 3 σ⁴
        settings.drag_area_uncertainty * np.sum(p * 0.5 * AIR_DENSITY_KGPM3 * cda * speed ** 2),
        settings.rolling_resistance_uncertainty * mass_kg * G_MPS2 * vehicle.rolling_resistance_coefficient
        * np.sum(p * np.asarray(cos_angle, dtype=float)[used]),
    ]
    if offset is not None:
        terms.append(settings.torque_offset_uncertainty * np.sum(p * np.nan_to_num(np.asarray(offset)[used])))
    if aux is not None:
        width = settings.aux_power_sigma_w if aux_width_w is None or not np.isfinite(aux_width_w) else aux_width_w
        terms.append(width * np.sum(p * np.nan_to_num(np.asarray(aux)[used])))
    return float(np.sqrt(np.sum(np.square(terms))) / norm)
