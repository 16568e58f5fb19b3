"""Torque-gain calibration from weighings, and each mass's total uncertainty.

The engine's actual-torque report (and the driveline efficiency of the vehicle file) scale the
wheel force by an unknown gain k = 1 + δ; every estimated mass is then m̂_j = m_j + m_j δ + e_j,
with e_j the fit's own error. Without a weighing, the gain's prior width is part of every mass's
uncertainty. A weighed segment w (a weighbridge ticket) observes z_w = m̂_w - m_w = m_w δ + e_w,
and the calibration is the linear-Gaussian update of the errors u_j = m_j δ + e_j on z: prior
δ ~ N(0, σ_g²), e ~ N(0, C) with C the fit's covariance of the masses (their shared part, from the
drive's wind, c_d·A or torque offset, moves all masses together and is corrected in full; their
independent part, noise and gusts, stays with its segment). Each mass becomes m̂_j - E[u_j | z],
its 1-sigma the posterior's, and the gain the posterior of δ.
"""

from __future__ import annotations

import numpy as np

from ..errors import UserError

ITERATIONS = 50
"""At most this many steps of the fixed point δ̂ (the errors' gain column m_j = m̂_j / (1 + δ̂))."""


def calibrate(masses_kg, statistical_kg, other_kg, known: dict[int, float], gain_uncertainty: float,
              covariance_kg2=None):
    """Masses [kg] corrected by the torque gain from the known masses, their total 1-sigma [kg],
    and the gain (value, relative 1-sigma, source). ``statistical_kg``: each estimate's own
    1-sigma; ``other_kg``: further systematic 1-sigma terms (e.g. a fixed c_r's datasheet error);
    ``covariance_kg2``: the estimates' error covariance C [kg²] (its diagonal statistical² +
    other²), None: independent errors. Without a known mass the gain's prior width is added to each
    1-sigma and nothing else changes."""
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
    if covariance_kg2 is None:
        covariance_kg2 = np.diag(statistical ** 2 + other ** 2)
    estimated = np.flatnonzero(np.isfinite(masses))
    weighed = np.searchsorted(estimated, list(usable))
    posterior = gain_posterior(masses[estimated], np.asarray(covariance_kg2, dtype=float)[np.ix_(estimated, estimated)],
                               weighed, np.array(list(usable.values())), gain_uncertainty)
    corrected, total = np.full(len(masses), np.nan), np.full(len(masses), np.nan)
    corrected[estimated], total[estimated] = posterior["masses_kg"], posterior["std_kg"]
    for j, kg in usable.items():
        corrected[j], total[j] = kg, 0.0
    gain = 1.0 + posterior["delta"]
    return corrected, total, {"gain": gain, "relative_std": posterior["delta_std"] / gain,
                              "calibrated_from": [int(j + 1) for j in usable]}


def gain_posterior(masses_kg, covariance_kg2, weighed, weighed_kg, gain_uncertainty: float) -> dict:
    """The update of δ = k - 1 and the errors u = m̂ - m on z = m̂_w - m_w (``weighed``: positions
    in ``masses_kg``, ``weighed_kg`` their known masses): masses_kg m̂ - E[u | z], std_kg the
    posterior's 1-sigma, delta and delta_std δ's posterior. The errors' gain column m_j is taken as
    m̂_j / (1 + δ̂) (the weighed ones' own m_w), iterated to its fixed point: with m̂_j in its place
    a pure gain error would leave (k - 1)² of every mass. A NaN in ``covariance_kg2`` counts as 0."""
    masses = np.asarray(masses_kg, dtype=float)
    covariance = np.nan_to_num(np.asarray(covariance_kg2, dtype=float))
    covariance = 0.5 * (covariance + covariance.T)
    z = masses[weighed] - weighed_kg
    prior_var = gain_uncertainty ** 2
    delta = 0.0
    for _ in range(ITERATIONS):
        column = masses / (1.0 + delta)
        column[weighed] = weighed_kg
        total = prior_var * np.outer(column, column) + covariance
        towards = total[:, weighed]
        solved = np.linalg.lstsq(total[np.ix_(weighed, weighed)], np.column_stack([z, towards.T, column[weighed]]),
                                 rcond=None)[0]
        new_delta = float(prior_var * column[weighed] @ solved[:, 0])
        converged = abs(new_delta - delta) <= 1e-12
        delta = new_delta
        if converged:
            break
    mean = towards @ solved[:, 0]
    posterior = total - towards @ solved[:, 1:1 + len(masses)]
    delta_var = prior_var - prior_var ** 2 * float(column[weighed] @ solved[:, -1])
    return {"masses_kg": masses - mean, "std_kg": np.sqrt(np.clip(np.diag(posterior), 0.0, None)),
            "delta": delta, "delta_std": float(np.sqrt(max(delta_var, 0.0)))}
