"""Road height and gradient as a state-space smoother over distance: forward (extended) Kalman
filter and backward Rauch-Tung-Striebel pass on the distance grid.

State per grid point i (spacing Δ [m], driving time dt_i [s] since the previous point, and clock
time Δt_i [s], standstills included, for the bias rate):

    x = [h, γ, d, r, b, e(, ḃ(, k))]
    h  road height [m]                 h' = h + Δ γ
    γ  gradient dh/ds [-]              γ' = γ + w_γ        (integrated random walk, curvature PSD q_c)
    d  barometric offset [m]           d' = d + dt r       (weather drift and the sensor's own height)
    r  its rate [m/s]                  r' = r + w_r        (drift rate random walk, PSD q_r)
    b  IMU bias [m/s²]                 b' = b + Δt ḃ + w_b (mounting pitch g·sin δ plus accelerometer bias)
    e  DEM error at the fixes [m]      e' = φ e + w_e      (Gauss-Markov, φ = exp(-Δ/L), var σ_e²)
    ḃ  the bias's rate [m/s³]          ḃ' = ḃ + w_ḃ        (optional 7th state, integrated random walk,
                                                          PSD q_ḃ over Δt: an IMU warming up with the
                                                          cab moves its bias along a smooth ramp,
                                                          which a random walk on b follows only by
                                                          trading with the gradient)
    k  log scale of the IMU channel    k' = k, or a fresh  (optional 8th state: the force balance's
       [-] (mass or torque gain)       draw at a reset     log(m_true/m), constant per mass segment)

With 6 states b is a random walk alone. The scale state comes with the rate's slot: without a
bias rate that is pinned (zero prior variance and q_ḃ = 0), which leaves every other state's
estimate as it is; the RTS pass gives a pinned state no correction.

Measurements (columns of ``z``; NaN = none in that bin):

    0 barometric height (6)            z = h + d
    1 DEM height at the GPS fixes      z = h + e
    2 IMU specific force minus dv/dt   z = g sin(atan γ) + b              (linearised at the prediction)
      with the scale state             z = e^k (g sin(atan γ) + u) - u + b,  u = dv/dt + g c_r per grid
                                       point: the force balance reads e^k times the true specific force
                                       (a log, so that no estimate can flip the force's sign)
    3 GPS altitude                     z = h

``step`` adds process variance per grid point on the diagonal: the barometric offset d steps at a
standstill (door and ventilation change the cab's overpressure; `smoother.SmootherSettings`). For
the scale state k a positive ``step`` is a reset instead: k restarts at 0 with that variance, the
prior of a new mass segment's error (k' = 0 k + w, independent of the segment before).

``numba`` kernel `smooth` beside the NumPy reference `smooth_reference` (same contract, tested equal).
"""

from __future__ import annotations

import numba
import numpy as np

from ..small_linalg import cholesky, cholesky_solve

N_STATES = 6
"""States without the optional ones; with the bias rate ``x0`` has `N_STATES_WITH_BIAS_RATE`, with
the scale state `N_STATES_WITH_SCALE`."""
N_STATES_WITH_BIAS_RATE = 7
N_STATES_WITH_SCALE = 8
N_MEASUREMENTS = 4
H, GAMMA, DRIFT, RATE, BIAS, DEM_ERROR, BIAS_RATE, SCALE = range(N_STATES_WITH_SCALE)
BARO, DEM, IMU, GPS = range(N_MEASUREMENTS)
PARAMETERS = ("spacing_m", "curvature_psd", "drift_rate_psd", "bias_psd", "dem_sigma_m", "dem_correlation_m", "g",
              "bias_rate_psd")


def _transition(spacing, dt, phi, ns=N_STATES, reset=False, clock=0.0):
    f = np.eye(ns)
    f[H, GAMMA] = spacing
    f[DRIFT, RATE] = dt
    f[DEM_ERROR, DEM_ERROR] = phi
    if ns > BIAS_RATE:
        f[BIAS, BIAS_RATE] = clock
    if ns > SCALE and reset:
        f[SCALE, SCALE] = 0.0
    return f


def _process_noise(spacing, dt, q_c, q_r, q_b, dem_var, phi, ns=N_STATES, q_bdot=0.0, clock=0.0):
    q = np.zeros((ns, ns))
    q[H, H], q[H, GAMMA], q[GAMMA, GAMMA] = q_c * spacing ** 3 / 3, q_c * spacing ** 2 / 2, q_c * spacing
    q[GAMMA, H] = q[H, GAMMA]
    q[DRIFT, DRIFT], q[DRIFT, RATE], q[RATE, RATE] = q_r * dt ** 3 / 3, q_r * dt ** 2 / 2, q_r * dt
    q[RATE, DRIFT] = q[DRIFT, RATE]
    q[BIAS, BIAS] = q_b * dt
    if ns > BIAS_RATE:
        q[BIAS, BIAS] += q_bdot * clock ** 3 / 3
        q[BIAS, BIAS_RATE] = q[BIAS_RATE, BIAS] = q_bdot * clock ** 2 / 2
        q[BIAS_RATE, BIAS_RATE] = q_bdot * clock
    q[DEM_ERROR, DEM_ERROR] = dem_var * (1 - phi * phi)
    return q


def smooth_reference(z, r, dt, step, params, x0, p0, regressor=None, clock=None):
    """Forward EKF + RTS smoother, matrix form. ``z``, ``r``: (n, 4) measurements and their
    variances; ``dt``: (n,) seconds of driving between grid points; ``step``: (n, ns) extra process
    variance added to the diagonal on the way into each point (for the scale state: its reset
    variance); ``params`` as `PARAMETERS`; ``x0``, ``p0``: prior of the first point, ns = 6 states,
    7 with the bias rate, or 8 with the scale state, whose ``regressor`` u (n,) is then needed
    (NaN: 0); a state with zero prior variance and no process noise (the bias rate beside the scale
    state) stays pinned at its prior; ``clock``: (n,) seconds of clock time between the grid
    points, standstills included, over which the bias rate acts (None: ``dt``). Returns (smoothed
    states (n, ns), smoothed covariances (n, ns, ns), innovations (n, 4), innovation variances (n, 4))."""
    spacing, q_c, q_r, q_b, dem_sigma, dem_corr, g, q_bdot = params
    n = len(dt)
    ns = len(x0)
    phi = np.exp(-spacing / dem_corr)
    x_pred, p_pred = np.empty((n, ns)), np.empty((n, ns, ns))
    x_filt, p_filt = np.empty((n, ns)), np.empty((n, ns, ns))
    innovation, innovation_var = np.full((n, N_MEASUREMENTS), np.nan), np.full((n, N_MEASUREMENTS), np.nan)
    x, p = np.array(x0, dtype=float), np.array(p0, dtype=float)
    u = np.zeros(n) if regressor is None else np.nan_to_num(np.asarray(regressor, dtype=float))
    clock = dt if clock is None else clock
    resets = np.zeros(n, bool) if ns <= SCALE else step[:, SCALE] > 0
    for i in range(n):
        if i > 0:
            f = _transition(spacing, dt[i], phi, ns, resets[i], clock[i])
            x = f @ x
            p = (f @ p @ f.T + _process_noise(spacing, dt[i], q_c, q_r, q_b, dem_sigma ** 2, phi, ns, q_bdot, clock[i])
                 + np.diag(step[i]))
        x_pred[i], p_pred[i] = x, p
        gamma = x[GAMMA]
        rows = np.zeros((N_MEASUREMENTS, ns))
        rows[BARO, [H, DRIFT]] = 1.0
        rows[DEM, [H, DEM_ERROR]] = 1.0
        rows[IMU, GAMMA] = g / (1 + gamma * gamma) ** 1.5
        rows[IMU, BIAS] = 1.0
        factor = np.exp(x[SCALE]) if ns > SCALE else 1.0
        rows[IMU, GAMMA] *= factor
        if ns > SCALE:
            rows[IMU, SCALE] = factor * (g * gamma / np.sqrt(1 + gamma * gamma) + u[i])
        rows[GPS, H] = 1.0
        predicted = rows @ x
        predicted[IMU] = factor * (g * gamma / np.sqrt(1 + gamma * gamma) + u[i]) - u[i] + x[BIAS]
        for m in range(N_MEASUREMENTS):
            if not (np.isfinite(z[i, m]) and np.isfinite(r[i, m]) and r[i, m] > 0):
                continue
            row = rows[m]
            s = row @ p @ row + r[i, m]
            # linearised once at the prediction: the IMU row's predicted value moves with the state
            nu = z[i, m] - predicted[m] - row @ (x - x_pred[i])
            gain = p @ row / s
            x = x + gain * nu
            ikh = np.eye(ns) - np.outer(gain, row)
            p = ikh @ p @ ikh.T + r[i, m] * np.outer(gain, gain)
            innovation[i, m], innovation_var[i, m] = nu, s
        x_filt[i], p_filt[i] = x, p
    x_s, p_s = x_filt.copy(), p_filt.copy()
    for i in range(n - 2, -1, -1):
        f = _transition(spacing, dt[i + 1], phi, ns, resets[i + 1], clock[i + 1])
        free = np.ix_(np.diag(p_pred[i + 1]) > 0, np.diag(p_pred[i + 1]) > 0)
        c = np.zeros((ns, ns))
        c[free] = np.linalg.solve(p_pred[i + 1][free], (f @ p_filt[i])[free]).T
        x_s[i] = x_filt[i] + c @ (x_s[i + 1] - x_pred[i + 1])
        p_s[i] = p_filt[i] + c @ (p_s[i + 1] - p_pred[i + 1]) @ c.T
    return x_s, p_s, innovation, innovation_var


@numba.njit(cache=True)
def _predict(x, p, spacing, dt, clock, phi, q_c, q_r, q_b, q_bdot, dem_var):
    """x, p <- F x, F p F^T + Q in place, using F's sparsity (three off-identity entries, four with
    the bias rate)."""
    rated = p.shape[0] > BIAS_RATE
    x[H] += spacing * x[GAMMA]
    x[DRIFT] += dt * x[RATE]
    x[DEM_ERROR] *= phi
    if rated:
        x[BIAS] += clock * x[BIAS_RATE]
    for j in range(p.shape[0]):  # rows: P <- F P
        p[H, j] += spacing * p[GAMMA, j]
        p[DRIFT, j] += dt * p[RATE, j]
        p[DEM_ERROR, j] *= phi
        if rated:
            p[BIAS, j] += clock * p[BIAS_RATE, j]
    for i in range(p.shape[0]):  # columns: (F P) F^T
        p[i, H] += spacing * p[i, GAMMA]
        p[i, DRIFT] += dt * p[i, RATE]
        p[i, DEM_ERROR] *= phi
        if rated:
            p[i, BIAS] += clock * p[i, BIAS_RATE]
    p[H, H] += q_c * spacing ** 3 / 3
    p[H, GAMMA] += q_c * spacing ** 2 / 2
    p[GAMMA, H] += q_c * spacing ** 2 / 2
    p[GAMMA, GAMMA] += q_c * spacing
    p[DRIFT, DRIFT] += q_r * dt ** 3 / 3
    p[DRIFT, RATE] += q_r * dt ** 2 / 2
    p[RATE, DRIFT] += q_r * dt ** 2 / 2
    p[RATE, RATE] += q_r * dt
    p[BIAS, BIAS] += q_b * dt
    if rated:
        p[BIAS, BIAS] += q_bdot * clock ** 3 / 3
        p[BIAS, BIAS_RATE] += q_bdot * clock ** 2 / 2
        p[BIAS_RATE, BIAS] += q_bdot * clock ** 2 / 2
        p[BIAS_RATE, BIAS_RATE] += q_bdot * clock
    p[DEM_ERROR, DEM_ERROR] += dem_var * (1 - phi * phi)


@numba.njit(cache=True)
def _reset_scale(x, p, variance):
    """The scale state restarts at 0 with ``variance``, independent of every other state."""
    x[SCALE] = 0.0
    for a in range(p.shape[0]):
        p[a, SCALE] = 0.0
        p[SCALE, a] = 0.0
    p[SCALE, SCALE] = variance


@numba.njit(cache=True)
def smooth(z, r, dt, step, params, x0, p0, backward=True, regressor=None, clock=None):
    """`smooth_reference` as a numba kernel (same arguments and results); ``backward=False``
    stops after the forward filter (filtered states; innovations for a likelihood)."""
    spacing, q_c, q_r, q_b, dem_sigma, dem_corr, g, q_bdot = (params[0], params[1], params[2], params[3],
                                                              params[4], params[5], params[6], params[7])
    n = len(dt)
    ns = x0.shape[0]
    rated = ns > BIAS_RATE
    scaled = ns > SCALE
    u = np.zeros(n)
    if regressor is not None:
        for i in range(n):
            u[i] = regressor[i] if np.isfinite(regressor[i]) else 0.0
    elapsed = dt.copy()
    if clock is not None:
        for i in range(n):
            elapsed[i] = clock[i]
    phi = np.exp(-spacing / dem_corr)
    dem_var = dem_sigma * dem_sigma
    x_pred, p_pred = np.empty((n, ns)), np.empty((n, ns, ns))
    x_filt, p_filt = np.empty((n, ns)), np.empty((n, ns, ns))
    innovation = np.full((n, N_MEASUREMENTS), np.nan)
    innovation_var = np.full((n, N_MEASUREMENTS), np.nan)
    x, p = x0.copy(), p0.copy()
    row = np.zeros(ns)
    pr = np.zeros(ns)
    for i in range(n):
        if i > 0:
            _predict(x, p, spacing, dt[i], elapsed[i], phi, q_c, q_r, q_b, q_bdot, dem_var)
            for a in range(N_STATES):
                p[a, a] += step[i, a]
            if scaled and step[i, SCALE] > 0:
                _reset_scale(x, p, step[i, SCALE])
        _store(x, p, x_pred, p_pred, i)
        gamma = x[GAMMA]
        for m in range(N_MEASUREMENTS):
            if not (np.isfinite(z[i, m]) and np.isfinite(r[i, m]) and r[i, m] > 0):
                continue
            row[:] = 0.0
            if m == BARO:
                row[H] = 1.0
                row[DRIFT] = 1.0
                predicted = x_pred[i, H] + x_pred[i, DRIFT]
            elif m == DEM:
                row[H] = 1.0
                row[DEM_ERROR] = 1.0
                predicted = x_pred[i, H] + x_pred[i, DEM_ERROR]
            elif m == IMU:
                row[GAMMA] = g / (1 + gamma * gamma) ** 1.5
                row[BIAS] = 1.0
                predicted = g * gamma / np.sqrt(1 + gamma * gamma) + x_pred[i, BIAS]
                if scaled:
                    factor = np.exp(x_pred[i, SCALE])
                    row[SCALE] = factor * (g * gamma / np.sqrt(1 + gamma * gamma) + u[i])
                    row[GAMMA] *= factor
                    predicted = row[SCALE] - u[i] + x_pred[i, BIAS]
            else:
                row[H] = 1.0
                predicted = x_pred[i, H]
            nu = z[i, m] - predicted
            for a in range(ns):
                nu -= row[a] * (x[a] - x_pred[i, a])
            s = r[i, m]
            for a in range(ns):
                acc = 0.0
                for b in range(ns):
                    acc += p[a, b] * row[b]
                pr[a] = acc
                s += row[a] * acc
            for a in range(ns):
                x[a] += pr[a] / s * nu
            # Joseph form with a scalar measurement reduces to P - pr pr^T / s (kept symmetric)
            for a in range(ns):
                for b in range(ns):
                    p[a, b] -= pr[a] * pr[b] / s
            innovation[i, m] = nu
            innovation_var[i, m] = s
        _store(x, p, x_filt, p_filt, i)
    x_s = x_filt.copy()
    p_s = p_filt.copy()
    if not backward:
        return x_s, p_s, innovation, innovation_var
    fp = np.empty((ns, ns))
    chol = np.empty((ns, ns))
    c = np.empty((ns, ns))
    cd = np.empty((ns, ns))
    dx = np.empty(ns)
    dp = np.empty((ns, ns))
    for i in range(n - 2, -1, -1):
        dti = dt[i + 1]
        for a in range(ns):  # F P_filt (rows)
            for b in range(ns):
                fp[a, b] = p_filt[i, a, b]
        for j in range(ns):
            fp[H, j] += spacing * fp[GAMMA, j]
            fp[DRIFT, j] += dti * fp[RATE, j]
            fp[DEM_ERROR, j] *= phi
            if rated:
                fp[BIAS, j] += elapsed[i + 1] * fp[BIAS_RATE, j]
            if scaled and step[i + 1, SCALE] > 0:
                fp[SCALE, j] = 0.0
        # C^T = P_pred^-1 F P_filt by Cholesky (P_pred is symmetric positive definite; a pinned
        # state's zero row and column give its pivot the floor and its rows of C^T zero)
        cholesky(p_pred[i + 1], chol)
        cholesky_solve(chol, fp, c)
        for a in range(ns):
            dx[a] = x_s[i + 1, a] - x_pred[i + 1, a]
            for b in range(ns):
                dp[a, b] = p_s[i + 1, a, b] - p_pred[i + 1, a, b]
        for a in range(ns):  # c holds C^T: C[a, k] = c[k, a]
            acc = 0.0
            for k in range(ns):
                acc += c[k, a] * dx[k]
            x_s[i, a] = x_filt[i, a] + acc
            for b in range(ns):
                acc = 0.0
                for k in range(ns):
                    acc += c[k, a] * dp[k, b]
                cd[a, b] = acc
        for a in range(ns):
            for b in range(ns):
                acc = 0.0
                for k in range(ns):
                    acc += cd[a, k] * c[k, b]
                p_s[i, a, b] = p_filt[i, a, b] + acc
    return x_s, p_s, innovation, innovation_var


@numba.njit(cache=True)
def _store(x, p, xs, ps, i):
    """xs[i], ps[i] = x, p element by element: an array assignment would make numba compile its
    shape-mismatch error message, seconds of a first run's compilation."""
    for a in range(x.shape[0]):
        xs[i, a] = x[a]
        for b in range(x.shape[0]):
            ps[i, a, b] = p[a, b]


def smoother_gains(p_filt, dt, step, params, clock=None):
    """The RTS smoother's gains C_i = P_filt,i F_{i+1}^T P_pred,i+1^-1 per grid point, (n, ns, ns), the
    last zero: the smoothed error is the backward Markov chain e_i = C_i e_{i+1} + own_i, so the
    smoothed cross-covariances are Cov(x_i, x_j | all data) = C_i … C_{j-1} P_j (i < j). ``p_filt``:
    the forward filter's covariances (`smooth` with ``backward=False``), the rest as
    `smooth_reference`. One stacked solve, no n × n matrix."""
    spacing, q_c, q_r, q_b, dem_sigma, dem_corr, g, q_bdot = params
    n, ns = len(dt), p_filt.shape[1]
    phi = np.exp(-spacing / dem_corr)
    clock = dt if clock is None else clock
    resets = np.zeros(n, bool) if ns <= SCALE else step[:, SCALE] > 0
    gains = np.zeros((n, ns, ns))
    if n < 2:
        return gains
    f = np.array([_transition(spacing, dt[i], phi, ns, resets[i], clock[i]) for i in range(1, n)])
    q = np.array([_process_noise(spacing, dt[i], q_c, q_r, q_b, dem_sigma ** 2, phi, ns, q_bdot, clock[i])
                  for i in range(1, n)])
    ahead = f @ p_filt[:-1]
    predicted = ahead @ np.swapaxes(f, 1, 2) + q
    predicted[:, range(ns), range(ns)] += step[1:]
    # a pinned state (zero predicted variance: its rows of F P_filt are zero too) gets a unit pivot,
    # which leaves its gains zero, as `smooth_reference` leaves them
    pinned = np.diagonal(predicted, axis1=1, axis2=2) <= 0
    predicted[:, range(ns), range(ns)] += pinned
    gains[:-1] = np.swapaxes(np.linalg.solve(predicted, ahead), 1, 2)
    return gains


def covariance_with_mean(gains, p_smooth, state):
    """Per grid point i, the smoothed covariance of one state's error there with that state's error
    averaged over the grid, (1/n) Σ_j Cov(x_i, x_j | all data): how much of a point's error it
    shares with the whole drive. ``gains``: the RTS smoother's (`smoother_gains`), ``p_smooth`` its
    smoothed covariances; the cross-covariances summed by one backward and one forward recursion
    (no n × n matrix)."""
    n, ns = p_smooth.shape[:2]
    later = np.zeros((n, ns))  # Σ_{j >= i} Cov(x_i, x_j[state])
    later[-1] = p_smooth[-1][:, state]
    for i in range(n - 2, -1, -1):
        later[i] = p_smooth[i][:, state] + gains[i] @ later[i + 1]
    row = np.zeros(ns)  # Σ_{j < i} (C_j … C_{i-1})[state, :]
    total = np.empty(n)
    unit = np.zeros(ns)
    unit[state] = 1.0
    for i in range(n):
        total[i] = later[i][state] + row @ p_smooth[i][:, state]
        row = (row + unit) @ gains[i]
    return total / n


def weighted_sum_covariance(gains, p_column, state, weights):
    """Covariance (k, k) of k weighted sums Σ_i W[i, a] e_i of one state's smoothed error e over the
    grid, W = ``weights`` (n, k): Wᵀ P W with P that state's n × n posterior covariance, from the RTS
    cross-covariances (``gains``, `smoother_gains`) and ``p_column`` (n, ns), the smoothed
    covariances' column of ``state``, P_i[:, state]. One backward recursion,
    L_i = P_i[:, state] W_i + C_i L_{i+1} = Σ_{j >= i} Cov(x_i, e_j) W_j, gives the upper triangle
    with its diagonal, U = Σ_i W_iᵀ L_i[state]; Wᵀ P W = U + Uᵀ - Σ_i P_i[state, state] W_iᵀ W_i.
    O(n ns² k), no n × n matrix; only the grid points from the first weighted one on are visited."""
    weights = np.asarray(weights, dtype=float)
    if weights.ndim == 1:
        weights = weights[:, None]
    k = weights.shape[1]
    used = np.flatnonzero(np.any(weights != 0, axis=1))
    if len(used) == 0:
        return np.zeros((k, k))
    first, last = used[0], used[-1]
    later = p_column[last][:, None] * weights[last][None, :]
    upper = np.outer(weights[last], later[state])
    for i in range(last - 1, first - 1, -1):
        later = p_column[i][:, None] * weights[i][None, :] + gains[i] @ later
        upper += np.outer(weights[i], later[state])
    part = weights[first:last + 1]
    diagonal = (part * p_column[first:last + 1, state][:, None]).T @ part
    return upper + upper.T - diagonal
