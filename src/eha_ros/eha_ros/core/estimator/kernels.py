"""Compiled Kalman filter steps shared by the filters: predict (eq. 4.1-4.2) and a Joseph-form
update (eq. 4.4-4.6) with innovation and NIS, for small dense matrices (n <= 8, m <= 3).

The arrays are updated in place by one small product helper (:func:`mul`, :func:`mulv`);
with a workspace (:func:`update_ws`) a filter step allocates nothing but the m x m inverse.
filterpy's KalmanFilter computes the same (its update() is the Joseph form too) and is used as
the reference in the tests.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline='always')
def mul(A, B, out, C, sub, trans_b, sym):
    """out = C -/+ A op(B) (op(B) = B' if trans_b; C None = 0), each entry summed in index
    order from C; sym: only the upper triangle is computed and mirrored."""
    n, m = out.shape
    inner = A.shape[1]
    for i in range(n):
        for j in range(i if sym else 0, m):
            s = 0.0 if C is None else C[i, j]
            for k in range(inner):
                p = A[i, k] * (B[j, k] if trans_b else B[k, j])
                if sub:
                    s -= p
                else:
                    s += p
            out[i, j] = s
            if sym:
                out[j, i] = s


@njit(cache=True, inline='always')
def mulv(A, v, out, c, sub):
    """out = c -/+ A v (c None = 0), each entry summed in index order from c."""
    for i in range(out.shape[0]):
        s = 0.0 if c is None else c[i]
        for k in range(v.shape[0]):
            if sub:
                s -= A[i, k] * v[k]
            else:
                s += A[i, k] * v[k]
        out[i] = s


@njit(cache=True)
def predict(x, P, F, G, u, Q, tmp):
    """x <- F x + G u (eq. 4.1); P <- F P F' + Q (eq. 4.2). ``tmp`` is n x n scratch."""
    xn = tmp[0]                                # scratch row, free until F P below
    mulv(F, x, xn, None, False)
    mulv(G, u, xn, xn, False)
    x[:] = xn
    mul(F, P, tmp, None, False, False, False)
    mul(tmp, F, P, Q, False, True, True)


def workspace_size(n: int, m: int) -> int:
    """Scratch floats that :func:`update_ws` needs for n states and m measurements."""
    return 3 * n * m + 2 * n * n + n


@njit(cache=True)
def update(x, P, H, R, z, y, S):
    """Joseph-form update (eq. 4.4-4.6); writes the innovation y = z - H x and its covariance
    S = H P H' + R; returns the NIS y' S^-1 y. x and P are updated in place."""
    n = x.shape[0]
    m = z.shape[0]
    return update_ws(x, P, H, R, z, y, S, np.empty(3 * n * m + 2 * n * n + n))


@njit(cache=True)
def update_ws(x, P, H, R, z, y, S, ws):
    """:func:`update` with preallocated scratch ``ws`` (>= workspace_size(n, m) floats)."""
    return update_gated(x, P, H, R, z, y, S, ws, x.shape[0], 0.0, -1, -1, 0.0)


@njit(cache=True)
def update_gated(x, P, H, R, z, y, S, ws, i_frozen, gate, i_unexcited, i_moved, moved_gate):
    """:func:`update_ws`; when any innovation's |y_j| / sqrt(S_jj) exceeds ``gate`` (> 0),
    the gain rows of the states i_frozen .. n-1 are zeroed: those states are not
    updated by this sample, their covariance stays consistent (the Joseph form holds for any
    gain). Used to keep slow parameter states out of a fast transient the model cannot
    explain (core.estimator.adapt). The gain row of state ``i_unexcited`` (>= 0) is zeroed
    always: a parameter whose regressor is too small to tell it from model error (dead-zone
    adaptation, Ioannou & Sun, "Robust Adaptive Control", 1996, sec. 8.5). The gain row of
    state ``i_moved`` (>= 0) is zeroed when a later measurement's (j >= 1) normalised
    innovation exceeds ``moved_gate`` (> 0): the position sensor's offset is not updated by the
    sample on which the pressures show that the piston moved (a load step compresses the oil:
    C_eq x10 under 5 kN, 0.33 mm in one tick, 44 um of it taken for sensor offset before)."""
    n = x.shape[0]
    m = z.shape[0]
    o = 0
    PHt = ws[o:o + n * m].reshape((n, m))
    o += n * m
    K = ws[o:o + n * m].reshape((n, m))
    o += n * m
    KR = ws[o:o + n * m].reshape((n, m))
    o += n * m
    IKH = ws[o:o + n * n].reshape((n, n))
    o += n * n
    T = ws[o:o + n * n].reshape((n, n))
    o += n * n
    dx = ws[o:o + n]
    mul(P, H, PHt, None, False, True, False)
    mulv(H, x, y, z, True)                     # y = z - H x
    mul(H, PHt, S, R, False, False, False)     # S = R + H P H'
    Si = np.linalg.inv(S)
    mul(PHt, Si, K, None, False, False, False)
    if i_unexcited >= 0:
        for j in range(m):
            K[i_unexcited, j] = 0.0
    if i_moved >= 0 and moved_gate > 0.0:
        for j in range(1, m):
            if abs(y[j]) > moved_gate * math.sqrt(S[j, j]):
                for jj in range(m):
                    K[i_moved, jj] = 0.0
                break
    if gate > 0.0 and i_frozen < n:
        outlier = False
        for j in range(m):
            if abs(y[j]) > gate * math.sqrt(S[j, j]):
                outlier = True
        if outlier:
            for i in range(i_frozen, n):
                for j in range(m):
                    K[i, j] = 0.0
    nis = 0.0
    for i in range(m):
        for j in range(m):
            nis += y[i] * Si[i, j] * y[j]
    mulv(K, y, dx, None, False)
    for i in range(n):
        x[i] += dx[i]
    # Joseph form: P = (I - K H) P (I - K H)' + K R K'
    for i in range(n):
        for j in range(n):
            IKH[i, j] = 1.0 if i == j else 0.0
    mul(K, H, IKH, IKH, True, False, False)
    mul(IKH, P, T, None, False, False, False)
    mul(K, R, KR, None, False, False, False)
    mul(T, IKH, P, None, False, True, True)
    mul(KR, K, P, P, False, True, True)
    return nis


def warm_up():
    """Compile (or load from cache) both kernels, so the first real tick is not slow."""
    x = np.zeros(3)
    P = np.eye(3)
    F = np.eye(3)
    G = np.zeros((3, 1))
    predict(x, P, F, G, np.zeros(1), np.eye(3), np.empty((3, 3)))
    update(x, P, np.eye(1, 3), np.eye(1), np.zeros(1), np.zeros(1), np.zeros((1, 1)))


def refill(obj, name: str, value) -> None:
    """``obj.<name> = value``, written into the array already there (the estimator's compiled
    tick holds it, core.estimator.stepper)."""
    a = getattr(obj, name, None)
    if a is None:
        setattr(obj, name, np.array(value, float))
    else:
        a[...] = value


class StateView:
    """Position, velocity and position variance of a filter whose x = [x, x_dot, ...], P."""

    @property
    def position(self) -> float:
        return float(self.x[0])

    @property
    def velocity(self) -> float:
        return float(self.x[1])

    @property
    def position_variance(self) -> float:
        return float(self.P[0, 0])
