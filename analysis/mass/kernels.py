"""Estimator kernels for linear-in-parameter regressions y_k = phi_k^T theta, equations (9)-(14).

Each numba kernel has a plain NumPy/Python reference beside it (``*_reference``) and the tests run
both against the same expected values. ``phi`` is (n, p), ``y`` is (n,); samples with a NaN in
``y`` or ``phi`` are skipped (the estimate is held).
"""

from __future__ import annotations

import numba
import numpy as np

from ..small_linalg import cholesky, cholesky_solve, condition_number_symmetric


def least_squares_reference(phi: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(9): theta = (Phi^T Phi)^-1 Phi^T Y over finite rows; NaN where Phi^T Phi is singular."""
    phi = np.asarray(phi, dtype=float).reshape(len(y), -1)
    ok = np.isfinite(y) & np.all(np.isfinite(phi), axis=1)
    normal = phi[ok].T @ phi[ok]
    if ok.sum() < phi.shape[1] or np.linalg.cond(normal) > 1e12:
        return np.full(phi.shape[1], np.nan)
    return np.linalg.solve(normal, phi[ok].T @ y[ok])


@numba.njit(cache=True)
def least_squares(phi, y):
    """(9) as a numba kernel: accumulates the normal equations in one pass [same units as y/phi]."""
    n, p = phi.shape
    normal = np.zeros((p, p))
    rhs = np.zeros(p)
    used = 0
    for k in range(n):
        ok = np.isfinite(y[k])
        for i in range(p):
            ok = ok and np.isfinite(phi[k, i])
        if not ok:
            continue
        used += 1
        for i in range(p):
            rhs[i] += phi[k, i] * y[k]
            for j in range(p):
                normal[i, j] += phi[k, i] * phi[k, j]
    if used < p or condition_number_symmetric(normal) > 1e12:
        return np.full(p, np.nan)
    if p == 1:
        rhs[0] /= normal[0, 0]
        return rhs
    lower = np.empty((p, p))
    cholesky(normal, lower)
    solution = np.empty((p, 1))
    cholesky_solve(lower, rhs.reshape((p, 1)), solution)
    return solution[:, 0].copy()


def rls_reference(phi, y, forgetting_factor, theta0, p0):
    """(11)-(13), recursive least squares with forgetting factor lambda; returns theta after each
    sample, shape (n, p). ``p0`` is the initial covariance P_0 (p, p)."""
    phi = np.asarray(phi, dtype=float)
    theta = np.array(theta0, dtype=float)
    cov = np.array(p0, dtype=float)
    history = np.empty((len(y), len(theta)))
    for k in range(len(y)):
        x = phi[k]
        if np.isfinite(y[k]) and np.all(np.isfinite(x)):
            px = cov @ x
            denominator = forgetting_factor + x @ px
            theta = theta + px / denominator * (y[k] - x @ theta)
            # (13) as P - px px^T / d keeps P exactly symmetric; P - K px^T does not, and with
            # lambda < 1 its antisymmetric rounding error grows like lambda^-k
            cov = (cov - np.outer(px, px) / denominator) / forgetting_factor
        history[k] = theta
    return history


@numba.njit(cache=True)
def rls(phi, y, forgetting_factor, theta0, p0):
    """(11)-(13) as a numba kernel; same contract as `rls_reference`."""
    n, p = phi.shape
    theta = theta0.copy()
    cov = p0.copy()
    history = np.empty((n, p))
    px = np.empty(p)
    for k in range(n):
        ok = np.isfinite(y[k])
        for i in range(p):
            ok = ok and np.isfinite(phi[k, i])
        if ok:
            denominator = forgetting_factor
            for i in range(p):
                acc = 0.0
                for j in range(p):
                    acc += cov[i, j] * phi[k, j]
                px[i] = acc
                denominator += phi[k, i] * acc
            error = y[k]
            for i in range(p):
                error -= phi[k, i] * theta[i]
            for i in range(p):
                theta[i] += px[i] / denominator * error
            for i in range(p):
                for j in range(p):
                    cov[i, j] = (cov[i, j] - px[i] * px[j] / denominator) / forgetting_factor
        for i in range(p):
            history[k, i] = theta[i]
    return history


def levenberg_marquardt_reference(phi, y, forgetting_factor, damping, theta0):
    """(14), damped recursive form: R_k = lambda R_{k-1} + J^T J, P_k = (R_k + mu I)^-1,
    theta_k = theta_{k-1} + P_k J^T e_k with J_k = phi_k; returns theta after each sample (n, p)."""
    phi = np.asarray(phi, dtype=float)
    theta = np.array(theta0, dtype=float)
    p = len(theta)
    information = np.zeros((p, p))
    history = np.empty((len(y), p))
    for k in range(len(y)):
        jac = phi[k]
        if np.isfinite(y[k]) and np.all(np.isfinite(jac)):
            information = forgetting_factor * information + np.outer(jac, jac)
            step = np.linalg.solve(information + damping * np.eye(p), jac * (y[k] - jac @ theta))
            theta = theta + step
        history[k] = theta
    return history


@numba.njit(cache=True)
def levenberg_marquardt(phi, y, forgetting_factor, damping, theta0):
    """(14) as a numba kernel; same contract as `levenberg_marquardt_reference`."""
    n, p = phi.shape
    theta = theta0.copy()
    information = np.zeros((p, p))
    history = np.empty((n, p))
    damped = np.empty((p, p))
    lower = np.empty((p, p))
    gradient = np.empty((p, 1))
    step = np.empty((p, 1))
    for k in range(n):
        ok = np.isfinite(y[k])
        for i in range(p):
            ok = ok and np.isfinite(phi[k, i])
        if ok:
            error = y[k]
            for i in range(p):
                error -= phi[k, i] * theta[i]
            for i in range(p):
                for j in range(p):
                    information[i, j] = forgetting_factor * information[i, j] + phi[k, i] * phi[k, j]
            if p == 1:
                theta[0] += phi[k, 0] * error / (information[0, 0] + damping)
            else:
                for i in range(p):
                    for j in range(p):
                        damped[i, j] = information[i, j] + (damping if i == j else 0.0)
                    gradient[i, 0] = phi[k, i] * error
                cholesky(damped, lower)
                cholesky_solve(lower, gradient, step)
                for i in range(p):
                    theta[i] += step[i, 0]
        for i in range(p):
            history[k, i] = theta[i]
    return history
