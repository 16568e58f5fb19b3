"""Small dense linear algebra as numba loops: Cholesky factor and solves, the condition number of
a symmetric matrix. For the few-by-few systems of the estimators (the smoother's 6 states, a
regression's parameters) these compile in a fraction of the time numba takes for
``np.linalg.solve`` or ``np.linalg.cond`` (LAPACK's LU and SVD, with their error paths), seconds of
every fresh install's first run, and run as fast."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def cholesky(a, out):
    """Lower Cholesky factor of the symmetric positive definite ``a`` into ``out``."""
    n = a.shape[0]
    for i in range(n):
        for j in range(i + 1):
            acc = a[i, j]
            for k in range(j):
                acc -= out[i, k] * out[j, k]
            if i == j:
                out[i, i] = np.sqrt(max(acc, 1e-300))
            else:
                out[i, j] = acc / out[j, j]
        for j in range(i + 1, n):
            out[i, j] = 0.0


@numba.njit(cache=True)
def cholesky_solve(chol, rhs, out):
    """out = A^-1 rhs for A = chol chol^T, column by column."""
    n = chol.shape[0]
    y = np.empty(n)
    for col in range(rhs.shape[1]):
        for i in range(n):
            acc = rhs[i, col]
            for k in range(i):
                acc -= chol[i, k] * y[k]
            y[i] = acc / chol[i, i]
        for i in range(n - 1, -1, -1):
            acc = y[i]
            for k in range(i + 1, n):
                acc -= chol[k, i] * out[k, col]
            out[i, col] = acc / chol[i, i]


@numba.njit(cache=True)
def condition_number_symmetric(a):
    """2-norm condition number of the symmetric ``a`` (``np.linalg.cond``) from its eigenvalues by
    cyclic Jacobi rotations."""
    n = a.shape[0]
    m = a.copy()
    scale = 0.0
    for i in range(n):
        for j in range(n):
            scale += m[i, j] * m[i, j]
    for _sweep in range(60):
        off = 0.0
        for i in range(n):
            for j in range(i + 1, n):
                off += m[i, j] * m[i, j]
        if off <= 1e-32 * scale:
            break
        for p in range(n):
            for q in range(p + 1, n):
                if m[p, q] == 0.0:
                    continue
                theta = (m[q, q] - m[p, p]) / (2.0 * m[p, q])
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):
                    kp, kq = m[k, p], m[k, q]
                    m[k, p], m[k, q] = c * kp - s * kq, s * kp + c * kq
                for k in range(n):
                    pk, qk = m[p, k], m[q, k]
                    m[p, k], m[q, k] = c * pk - s * qk, s * pk + c * qk
    largest, smallest = 0.0, np.inf
    for i in range(n):
        largest = max(largest, abs(m[i, i]))
        smallest = min(smallest, abs(m[i, i]))
    return np.inf if smallest == 0.0 else largest / smallest
