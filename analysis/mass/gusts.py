"""The head-wind gusts' share of the joint mass fit's covariance between its 30 s residual blocks.

A gust h(s) is a field along the road (correlated over some 100 m of travel): it adds
rho c_d A v h(s) to the wheel force, an error correlated over distance, so over tens of seconds at
urban speed, across the covariance's time blocks. The blocks treat two blocks as independent, so
the gust's covariance between them was missing from every mass's sigma. The drive's residual cannot
measure it: the fitted masses, wind, torque offset and auxiliary powers take up the slow part of the
gusts (the residual's autocovariance over distance shows a third to a half of the gust variance,
correlated over half the length), so the term comes from the gusts' physics:

    cov(r_k, r_l) = (rho c_d A I)² E|w|² v_k v_l exp(-|s_k - s_l| / L)

with I the turbulence intensity sigma_u / U near the ground and E|w|² the fitted mean wind's
square plus its variance (an unidentified wind keeps its prior's width).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..road_load import AIR_DENSITY_KGPM3


@dataclass(frozen=True)
class GustCovariance:
    """cov(r_k, r_l) = variance v_k v_l exp(-|s_k - s_l| / length_m) [N² / (m/s)²]."""

    variance: float
    length_m: float


def gust_covariance(drag_area_m2: float, wind_mean_square_m2ps2: float, intensity: float,
                    length_m: float) -> GustCovariance | None:
    """The residual's gust covariance for a drag area, the mean wind's expected square [m²/s²], a
    turbulence intensity and a gust length [m] (None where any is not positive)."""
    if not (drag_area_m2 > 0 and wind_mean_square_m2ps2 > 0 and intensity > 0 and length_m > 0):
        return None
    return GustCovariance((AIR_DENSITY_KGPM3 * drag_area_m2 * intensity) ** 2 * wind_mean_square_m2ps2, length_m)


@numba.njit(cache=True)
def _kernel_sums(rows, distance, length):
    """Per sample k, sum over all samples l of rows_l exp(-|s_k - s_l| / length) (k itself
    included); samples in order of distance. A forward and a backward first-order recursion."""
    n, p = rows.shape
    out = rows.copy()
    state = np.zeros(p)
    for k in range(1, n):
        factor = np.exp(-(distance[k] - distance[k - 1]) / length)
        for a in range(p):
            state[a] = factor * (state[a] + rows[k - 1, a])
            out[k, a] += state[a]
    state[:] = 0.0
    for k in range(n - 2, -1, -1):
        factor = np.exp(-(distance[k + 1] - distance[k]) / length)
        for a in range(p):
            state[a] = factor * (state[a] + rows[k + 1, a])
            out[k, a] += state[a]
    return out


def gust_meat(rows, jacobian, normal, speed_mps, distance_m, block, model: GustCovariance, factor: float):
    """What the gusts add to the covariance's meat beyond what its residual blocks hold of them
    [p x p]: E[S S^T] of the whole score S = sum_k z_k g_k (g the gusts' force, ``rows`` the
    samples' score rows z, weight times instrument row), less the blocks' expected share of it
    (times their small-sample ``factor``). The blocks' scores are of the residual, from which the
    fit has taken the gusts' projection on its parameters: s_b = t_b - C_b N^-1 S with t_b the
    block's score of the gusts and C_b = sum_(k in b) z_k x_k^T its part of the normal matrix
    ``normal`` (``jacobian``: the rows x), so a segment with few blocks shows little of its gust.
    Where the blocks' expected share exceeds the whole (a direction of the parameters where it does),
    nothing is taken from what the blocks measured: the difference's negative eigenvalues are 0."""
    order = np.argsort(distance_m, kind="stable")
    scaled = np.ascontiguousarray(rows[order] * speed_mps[order, None])
    distance = np.ascontiguousarray(distance_m[order], dtype=np.float64)
    ordered_block = block[order]
    sums = model.variance * _kernel_sums(scaled, distance, model.length_m)  # E[g_k S]/..., per sample
    total = scaled.T @ sums  # E[S S^T]
    n_blocks = int(block.max()) + 1
    p = rows.shape[1]
    own = np.zeros((n_blocks, p, p))  # E[t_b t_b^T]
    cross = np.zeros((n_blocks, p, p))  # E[S t_b^T]
    part = np.zeros((n_blocks, p, p))  # C_b
    np.add.at(part, block, rows[:, :, None] * jacobian[:, None, :])
    np.add.at(cross, ordered_block, sums[:, :, None] * scaled[:, None, :])
    for b in np.unique(ordered_block):
        inside = ordered_block == b
        within = model.variance * _kernel_sums(scaled[inside], distance[inside], model.length_m)
        own[b] = scaled[inside].T @ within
    inverse = np.linalg.pinv(normal)
    seen = np.einsum("bij,jk->bik", part, inverse)  # C_b N^-1
    taken = np.einsum("bij,bjk->ik", seen, cross)
    expected = own.sum(axis=0) - taken - taken.T + np.einsum("bij,jk,blk->il", seen, total, seen)
    value, vector = np.linalg.eigh(0.5 * (total - factor * expected + (total - factor * expected).T))
    return (vector * np.clip(value, 0.0, None)) @ vector.T
