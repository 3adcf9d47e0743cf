"""Compiled Kalman filter steps shared by the filters: predict (eq. 4.1-4.2) and a Joseph-form
update (eq. 4.4-4.6) with innovation and NIS, for small dense matrices (n <= 8, m <= 3).

The arrays are updated in place so that one filter step allocates nothing but the m x m
inverse; filterpy's KalmanFilter computes the same (its update() is the Joseph form too) and is
used as the reference in the tests.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def predict(x, P, F, G, u, Q, tmp):
    """x <- F x + G u (eq. 4.1); P <- F P F' + Q (eq. 4.2). ``tmp`` is n x n scratch."""
    n = x.shape[0]
    xn = np.empty(n)
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += F[i, j] * x[j]
        for j in range(u.shape[0]):
            s += G[i, j] * u[j]
        xn[i] = s
    x[:] = xn
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += F[i, k] * P[k, j]
            tmp[i, j] = s
    for i in range(n):
        for j in range(i, n):
            s = Q[i, j]
            for k in range(n):
                s += tmp[i, k] * F[j, k]
            P[i, j] = s
            P[j, i] = s


@njit(cache=True)
def update(x, P, H, R, z, y, S):
    """Joseph-form update (eq. 4.4-4.6); writes the innovation y = z - H x and its covariance
    S = H P H' + R; returns the NIS y' S^-1 y. x and P are updated in place."""
    n = x.shape[0]
    m = z.shape[0]
    PHt = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            s = 0.0
            for k in range(n):
                s += P[i, k] * H[j, k]
            PHt[i, j] = s
    for i in range(m):
        s = z[i]
        for k in range(n):
            s -= H[i, k] * x[k]
        y[i] = s
        for j in range(m):
            s = R[i, j]
            for k in range(n):
                s += H[i, k] * PHt[k, j]
            S[i, j] = s
    Si = np.linalg.inv(S)
    K = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            s = 0.0
            for k in range(m):
                s += PHt[i, k] * Si[k, j]
            K[i, j] = s
    nis = 0.0
    for i in range(m):
        for j in range(m):
            nis += y[i] * Si[i, j] * y[j]
    for i in range(n):
        s = 0.0
        for j in range(m):
            s += K[i, j] * y[j]
        x[i] += s
    # Joseph form: P = (I - K H) P (I - K H)' + K R K'
    IKH = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = 1.0 if i == j else 0.0
            for k in range(m):
                s -= K[i, k] * H[k, j]
            IKH[i, j] = s
    T = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += IKH[i, k] * P[k, j]
            T[i, j] = s
    KR = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            s = 0.0
            for k in range(m):
                s += K[i, k] * R[k, j]
            KR[i, j] = s
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for k in range(n):
                s += T[i, k] * IKH[j, k]
            for k in range(m):
                s += KR[i, k] * K[j, k]
            P[i, j] = s
            P[j, i] = s
    return nis


def warm_up():
    """Compile (or load from cache) both kernels, so the first real tick is not slow."""
    x = np.zeros(3)
    P = np.eye(3)
    F = np.eye(3)
    G = np.zeros((3, 1))
    predict(x, P, F, G, np.zeros(1), np.eye(3), np.empty((3, 3)))
    update(x, P, np.eye(1, 3), np.eye(1), np.zeros(1), np.zeros(1), np.zeros((1, 1)))


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
