"""Compiled Kalman filter steps shared by the filters: predict (eq. 4.1-4.2) and a Joseph-form
update (eq. 4.4-4.6) with innovation and NIS, for small matrices (n <= 12, m <= 3).

The arrays are updated in place by small product helpers (:func:`mul`, :func:`mulv`). The two
n^3 products of each step, F P F' and (I - K H) P (I - K H)', go through :func:`sandwich`,
which skips the exact zeros of F and of I - K H (the chamber filter's F has 29 non-zero
entries of 144) and keeps the dense products' bits. With the scratch of :func:`scratch` and
:func:`workspace_size` a filter step allocates nothing (S^-1 from np.linalg.inv's LAPACK calls
into the scratch: :func:`inverse`).
filterpy's KalmanFilter computes the same (its update() is the Joseph form too) and is used as
the reference in the tests.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.np.linalg import _LAPACK


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


@njit(cache=True, inline='always')
def pattern(S, idx, cnt):
    """The columns of each row of S that are not exactly 0.0, ascending: idx[i, :cnt[i]]
    (stored as floats in scratch; a NaN counts as non-zero)."""
    for i in range(S.shape[0]):
        c = 0
        for k in range(S.shape[1]):
            if S[i, k] != 0.0:
                idx[i, c] = k
                c += 1
        cnt[i] = c


def scratch(n: int) -> np.ndarray:
    """:func:`predict`'s scratch for n states: T, U and S's pattern of :func:`sandwich`."""
    return np.empty((3 * n + 1, n))


@njit(cache=True, inline='always')
def sandwich(S, P, C, T, W):
    """P <- S P S' (+ C), P symmetric, over S's non-zero pattern; T n x n and W (2 n + 1) x n
    scratch. T = S P, then P = T S' + C, each formed a row at a time from the entries of S that
    are not zero (U = T' makes the second product row-wise too). Each entry is summed in the
    index order of :func:`mul` and a skipped term is a signed zero, so the result is
    :func:`mul`'s to the bit while the operands are finite (a NaN spreads less far)."""
    n = P.shape[0]
    U, idx, cnt = W[:n], W[n:2 * n], W[2 * n]
    pattern(S, idx, cnt)
    for i in range(n):                         # T = S P
        for j in range(n):
            T[i, j] = 0.0
        for c in range(int(cnt[i])):
            k = int(idx[i, c])
            s = S[i, k]
            for j in range(n):
                T[i, j] += s * P[k, j]
    for i in range(n):
        for j in range(n):
            U[j, i] = T[i, j]
    for j in range(n):                         # P[i, j] = C[i, j] + sum_k T[i, k] S[j, k], i <= j
        for i in range(j + 1):
            P[j, i] = 0.0 if C is None else C[i, j]
        for c in range(int(cnt[j])):
            k = int(idx[j, c])
            s = S[j, k]
            for i in range(j + 1):
                P[j, i] += U[k, i] * s
        for i in range(j):
            P[i, j] = P[j, i]


@njit(cache=True, inline='always')
def propagate(F, P, Q, tmp):
    """P <- F P F' + Q (eq. 4.2) over F's non-zero pattern; ``tmp``: :func:`scratch` (or n x n,
    the rest then allocated)."""
    n = P.shape[0]
    W = tmp[n:] if tmp.shape[0] > 3 * n else np.empty((2 * n + 1, n))
    sandwich(F, P, Q, tmp[:n], W)


@njit(cache=True)
def predict(x, P, F, G, u, Q, tmp):
    """x <- F x + G u (eq. 4.1); P <- F P F' + Q (eq. 4.2). ``tmp``: :func:`scratch`."""
    xn = tmp[0]                                # scratch row, free until F P below
    mulv(F, x, xn, None, False)
    mulv(G, u, xn, xn, False)
    x[:] = xn
    propagate(F, P, Q, tmp)


@njit(cache=True)
def workspace_size(n: int, m: int) -> int:
    """Scratch floats that :func:`update_ws` needs for n states and m measurements."""
    return 3 * n * m + 4 * n * n + 2 * n + m * m + m


# The LAPACK routines np.linalg.inv calls in numba (getrf, then getri: numba's own bindings of
# scipy's LAPACK), called on the update's scratch by :func:`inverse`
_GETRF = _LAPACK().numba_xxgetrf(types.float64)
_GETRI = _LAPACK().numba_ez_xxgetri(types.float64)
_DOUBLE = ord('d')


@njit(cache=True)
def inverse(S, Sinv, ipiv) -> None:
    """Sinv <- S^-1, column-major (m^2 floats; ``ipiv``: m int32), by the LAPACK calls of
    np.linalg.inv: its bits and its errors (LinAlgError on a non-finite or singular S), without
    the two arrays it allocates per call."""
    m = S.shape[0]
    for i in range(m):
        for j in range(m):
            if not math.isfinite(S[i, j]):
                raise np.linalg.LinAlgError('Array must not contain infs or NaNs.')
            Sinv[j * m + i] = S[i, j]
    r = _GETRF(_DOUBLE, m, m, Sinv.ctypes, m, ipiv.ctypes)
    if r == 0:
        r = _GETRI(_DOUBLE, m, Sinv.ctypes, m, ipiv.ctypes)
    if r != 0:
        raise np.linalg.LinAlgError('Matrix is singular to machine precision.')


@njit(cache=True)
def update(x, P, H, R, z, y, S):
    """Joseph-form update (eq. 4.4-4.6); writes the innovation y = z - H x and its covariance
    S = H P H' + R; returns the NIS y' S^-1 y. x and P are updated in place."""
    n = x.shape[0]
    m = z.shape[0]
    return update_ws(x, P, H, R, z, y, S, np.empty(workspace_size(n, m)))


@njit(cache=True)
def update_ws(x, P, H, R, z, y, S, ws):
    """:func:`update` with preallocated scratch ``ws`` (>= workspace_size(n, m) floats)."""
    return update_gated(x, P, H, R, z, y, S, ws, x.shape[0], 0.0, -1, 0.0)


@njit(cache=True)
def update_gated(x, P, H, R, z, y, S, ws, i_frozen, gate, i_moved, moved_gate):
    """:func:`update_ws`; when any innovation's |y_j| / sqrt(S_jj) exceeds ``gate`` (> 0),
    the gain rows of the states i_frozen .. n-1 are zeroed: those states are not
    updated by this sample, their covariance stays consistent (the Joseph form holds for any
    gain). Used to keep slow parameter states out of a fast transient the model cannot
    explain (core.estimator.adapt). The gain row of state ``i_moved`` (>= 0) is zeroed when a
    later measurement's (j >= 1) normalised innovation exceeds ``moved_gate`` (> 0): the
    position sensor's offset is not updated by the sample on which the pressures show that the
    piston moved (a load step compresses the oil: C_eq x10 under 5 kN, 0.33 mm in one tick,
    44 um of it taken for sensor offset before)."""
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
    o += n
    W = ws[o:o + (2 * n + 1) * n].reshape((2 * n + 1, n))     # sandwich's scratch
    o += (2 * n + 1) * n
    Sinv = ws[o:o + m * m]                     # S^-1, column-major
    ipiv = ws[o + m * m:o + m * m + m].view(np.int32)
    mul(P, H, PHt, None, False, True, False)
    mulv(H, x, y, z, True)                     # y = z - H x
    mul(H, PHt, S, R, False, False, False)     # S = R + H P H'
    inverse(S, Sinv, ipiv)
    for i in range(n):                         # K = P H' S^-1
        for j in range(m):
            s = 0.0
            for k in range(m):
                s += PHt[i, k] * Sinv[j * m + k]
            K[i, j] = s
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
            nis += y[i] * Sinv[j * m + i] * y[j]
    mulv(K, y, dx, None, False)
    for i in range(n):
        x[i] += dx[i]
    # Joseph form: P = (I - K H) P (I - K H)' + K R K'
    for i in range(n):
        for j in range(n):
            IKH[i, j] = 1.0 if i == j else 0.0
    mul(K, H, IKH, IKH, True, False, False)
    mul(K, R, KR, None, False, False, False)
    sandwich(IKH, P, None, T, W)               # I - K H is I but in H's columns
    mul(KR, K, P, P, False, True, True)
    return nis


def warm_up():
    """Compile (or load from cache) both kernels, so the first real tick is not slow."""
    x = np.zeros(3)
    P = np.eye(3)
    F = np.eye(3)
    G = np.zeros((3, 1))
    predict(x, P, F, G, np.zeros(1), np.eye(3), scratch(3))
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
