"""Torque-gain calibration from one weighing, and each mass's total uncertainty.

The engine's actual-torque report (and the driveline efficiency of the vehicle file) scale the
wheel force by an unknown gain k; every estimated mass is then k·m. A known mass of one segment
(a weighbridge ticket) gives k and corrects all other segments; without one, the gain's
uncertainty is part of every mass's uncertainty.
"""

from __future__ import annotations

import numpy as np

from ..errors import UserError


def calibrate(masses_kg, statistical_kg, other_kg, known: dict[int, float], gain_uncertainty: float):
    """Masses [kg] corrected by the torque gain from the known masses, their total 1-sigma [kg],
    and the gain (value, relative 1-sigma, source). ``statistical_kg``: each estimate's own
    1-sigma; ``other_kg``: further systematic 1-sigma terms (e.g. a fixed c_r's datasheet error)."""
    masses = np.asarray(masses_kg, dtype=float)
    statistical = np.asarray(statistical_kg, dtype=float)
    other = np.asarray(other_kg, dtype=float)
    usable = {j: kg for j, kg in known.items() if j < len(masses) and np.isfinite(masses[j])}
    if known and not usable:
        raise UserError(f"mass.weighed_masses_kg: segment(s) {', '.join(str(j + 1) for j in known)} have no mass estimate "
                        f"to calibrate against (there are {len(masses)} segments; see the table)")
    if not usable:
        total = np.sqrt(statistical ** 2 + other ** 2 + (masses * gain_uncertainty) ** 2)
        return masses, total, {"gain": 1.0, "relative_std": gain_uncertainty, "calibrated_from": None}
    ratios = np.array([masses[j] / kg for j, kg in usable.items()])
    ratio_var = np.array([(np.hypot(statistical[j], other[j]) / kg) ** 2 for j, kg in usable.items()])
    gain = float(np.sum(ratios / ratio_var) / np.sum(1 / ratio_var))
    gain_std = float(np.sqrt(1 / np.sum(1 / ratio_var)) / gain)
    corrected = masses / gain
    total = np.sqrt((statistical / gain) ** 2 + (other / gain) ** 2 + (corrected * gain_std) ** 2)
    for j, kg in usable.items():
        corrected[j], total[j] = kg, 0.0
    return corrected, total, {"gain": gain, "relative_std": gain_std,
                              "calibrated_from": [int(j + 1) for j in usable]}
