"""The numba kernel of hindsight's fixed-lag Rauch–Tung–Striebel smoother (hindsight.smooth; docs/method.md §6.3).

One call smooths the rows of a buffer of track rows: the RTS terms of each row that has a next row of its track
(the gain, the prediction and its covariance), the resets among them, then each asked row's backward recursion from
its horizon. Every product and sum is written out in the order of the numpy statements it replaced (kept as
tests/reference_tracking.reference_smooth, checked bit for bit by tests/test_tracking_hindsight.py): plain products
and sums in a fixed order, no BLAS or LAPACK, so the outputs carry the same bits on every CPU.

Frames and units: states [x, y, vx, vy] in the tracking frame, m and m/s; covariances of those (4x4); stamps int64
ns; q the white-noise acceleration spectral density of the constant-velocity model ((m/s²)²/Hz).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from .bundles import RtsWork

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True, inline="always")
def _noise(dt: float, dt3: float, dt4: float, q: float, out: np.ndarray) -> None:
    """Q of white-noise acceleration of spectral density q over dt s (dt3, dt4: dt to the powers 3 and 4, as pow
    gives them) into out (4, 4): 0.25 dt^4 q on the positions, 0.5 dt^3 q between a position and its speed, dt^2 q
    on the speeds, 0 elsewhere."""
    qa = 0.25 * dt4 * q
    qb = 0.5 * dt3 * q
    qc = (dt * dt) * q
    out[:, :] = 0.0
    out[0, 0] = out[1, 1] = qa
    out[0, 2] = out[2, 0] = out[1, 3] = out[3, 1] = qb
    out[2, 2] = out[3, 3] = qc


@njit(cache=True, inline="always")
def _mm(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = a b (4x4), each entry summed over k in order from its k = 0 product."""
    for i in range(4):
        for j in range(4):
            acc = a[i, 0] * b[0, j]
            for k in range(1, 4):
                acc = acc + a[i, k] * b[k, j]
            out[i, j] = acc


@njit(cache=True, inline="always")
def _gain(dt, dt3, dt4, P, state_r, cov_n, q, q_most, tolerance, C, xp, Pp, work) -> bool:
    """The RTS terms of a step of dt s (dt3, dt4: its powers 3 and 4, as pow gives them) from a row (filtered state
    state_r, covariance P) to its next row (filtered covariance cov_n) with process noise q: the gain
    C = P F' Pp^-1, the prediction xp and its covariance Pp (into C, xp, Pp); returns whether the next row is a
    reset: its covariance exceeds the prediction's with q_most at least by more than `tolerance` of that one's
    trace (an update never increases it; see hindsight.smooth). work: the scratch, bundles.RtsWork."""
    F, Ft, PFt, FPFt = work.F, work.Ft, work.PFt, work.FPFt
    Q, m, x = work.Q, work.m, work.x
    F[:, :] = 0.0
    for i in range(4):
        F[i, i] = 1.0
    F[0, 2] = F[1, 3] = dt
    for i in range(4):
        for j in range(4):
            Ft[i, j] = F[j, i]
    _mm(P, Ft, PFt)
    _mm(F, PFt, FPFt)
    _noise(dt, dt3, dt4, q, Q)
    for i in range(4):
        for j in range(4):
            m[i, j] = FPFt[i, j] + Q[i, j]
    for i in range(4):
        for j in range(4):
            Pp[i, j] = 0.5 * (m[i, j] + m[j, i])
    # C = P F' Pp^-1, by solving Pp' C' = (P F')' (Pp symmetric): elimination without pivoting, back substitution
    for i in range(4):
        for j in range(4):
            m[i, j] = Pp[i, j]
            x[i, j] = PFt[j, i]
    for k in range(4):
        for i in range(k + 1, 4):
            f = m[i, k] / m[k, k]
            for c in range(k, 4):
                m[i, c] -= f * m[k, c]
            for c in range(4):
                x[i, c] -= f * x[k, c]
    for i in range(3, -1, -1):
        for c in range(4):
            acc = x[i, c]
            for j in range(i + 1, 4):
                acc -= m[i, j] * x[j, c]
            x[i, c] = acc / m[i, i]
    for i in range(4):
        for j in range(4):
            C[i, j] = x[j, i]
    for i in range(4):
        acc = F[i, 0] * state_r[0]
        for k in range(1, 4):
            acc = acc + F[i, k] * state_r[k]
        xp[i] = acc
    # the reset test: the largest eigenvalue of excess = sym(cov_n) - widest above a share of widest's trace, that is
    # limit I - excess not positive definite (a pivot of its elimination without pivoting not positive)
    _noise(dt, dt3, dt4, max(q, q_most), Q)
    a = m
    for i in range(4):
        for j in range(4):
            widest = FPFt[i, j] + Q[i, j]
            Q[i, j] = widest
            a[i, j] = 0.5 * (cov_n[i, j] + cov_n[j, i]) - widest
    trace = Q[0, 0] + Q[1, 1] + Q[2, 2] + Q[3, 3]
    limit = tolerance * trace
    for i in range(4):
        for j in range(4):
            a[i, j] = (limit if i == j else 0.0) - a[i, j]
    above = False
    for k in range(4):
        above |= not (a[k, k] > 0)
        pivot = 1.0 if above else a[k, k]
        for i in range(k + 1, 4):
            f = a[i, k] / pivot
            for c in range(k, 4):
                a[i, c] -= f * a[k, c]
    return above


@njit(cache=True)
def smooth_rows(t_ns, nxt, prv, state, cov, q, rows, lag_ns, covariance, q_most, tolerance):
    """Fixed-lag RTS states of `rows` of a buffer of track rows (see hindsight.smooth): t_ns (n,) int64 ns, nxt and
    prv (n,) the row of the same track at its next and previous stamp or -1 (hindsight.chains; changed in place: a
    reset ends a chain), state (n, 4), cov (n, 4, 4) float64, q (n,) the q of each row's step to its next row,
    rows (m,) int64, lag_ns, covariance (also give the smoothed covariances), q_most (the largest q the tracker
    may step with), tolerance (hindsight.RESET_TOLERANCE). Returns (states (m, 4), covariances (m, 4, 4), empty
    (0, 4, 4) without covariance)."""
    n = len(t_ns)
    C = np.zeros((n, 4, 4))
    xp = np.zeros((n, 4))
    Pp = np.zeros((n, 4, 4))
    work = RtsWork(
        F=np.zeros((4, 4)),
        Ft=np.zeros((4, 4)),
        PFt=np.zeros((4, 4)),
        FPFt=np.zeros((4, 4)),
        Q=np.zeros((4, 4)),
        m=np.zeros((4, 4)),
        x=np.zeros((4, 4)),
    )
    reset = np.zeros(n, np.bool_)
    step, dt, dt3, dt4 = -1, 0.0, 0.0, 0.0
    for r in range(n):
        k = nxt[r]
        if k < 0:
            continue
        if t_ns[k] - t_ns[r] != step:  # the powers once a step length (a log's scans come at a few)
            step = t_ns[k] - t_ns[r]
            dt = float(step) * 1e-9
            dt3, dt4 = math.pow(dt, 3.0), math.pow(dt, 4.0)
        reset[r] = _gain(dt, dt3, dt4, cov[r], state[r], cov[k], q[r], q_most, tolerance, C[r], xp[k], Pp[k], work)
    for r in range(n):
        if reset[r]:  # a reset starts the track anew: nothing is smoothed across it
            prv[nxt[r]] = -1
            nxt[r] = -1
    m = len(rows)
    xs = np.zeros((m, 4))
    Ps = np.zeros((m if covariance else 0, 4, 4))
    x = np.zeros(4)
    d = np.zeros(4)
    P = np.zeros((4, 4))
    D = np.zeros((4, 4))
    CD = np.zeros((4, 4))
    Ct = np.zeros((4, 4))
    for i in range(m):
        r = rows[i]
        cur = r
        limit = t_ns[r] + lag_ns
        while nxt[cur] >= 0 and t_ns[nxt[cur]] <= limit:  # the horizon: the last row within the lag
            cur = nxt[cur]
        x[:] = state[cur]
        if covariance:
            P[:, :] = cov[cur]
        while cur != r:
            p = prv[cur]
            Cp = C[p]
            for j in range(4):
                d[j] = x[j] - xp[cur, j]
            for j in range(4):
                acc = Cp[j, 0] * d[0]
                for k in range(1, 4):
                    acc = acc + Cp[j, k] * d[k]
                x[j] = state[p, j] + acc
            if covariance:
                for a in range(4):
                    for b in range(4):
                        D[a, b] = P[a, b] - Pp[cur, a, b]
                        Ct[a, b] = Cp[b, a]
                _mm(Cp, D, CD)
                _mm(CD, Ct, P)
                for a in range(4):
                    for b in range(4):
                        P[a, b] = cov[p, a, b] + P[a, b]
            cur = p
        xs[i] = x
        if covariance:
            Ps[i] = P
    return xs, Ps
