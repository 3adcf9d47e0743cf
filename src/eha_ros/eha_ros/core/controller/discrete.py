"""Continuous controller -> discrete state space at Ts (Tustin, optional prewarp) and its runtime.

Tustin (bilinear) maps the stable left half plane onto the unit disc, keeps the order, has no
aliasing of the controller's poles and, prewarped at the loop crossover, matches the
continuous controller's gain and phase exactly there; the remaining phase error below the
crossover is what the tests bound (controller node: margins within 1 dB / 5 deg).
The state-space form (from a cascade realisation of the zeros/poles) stays well conditioned
where polynomial coefficients of the same order would not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


def tustin(A, B, C, D, Ts: float, prewarp_w: float | None = None):
    """Bilinear transform of (A, B, C, D); prewarp_w (rad/s) makes it exact at that frequency.

    With T' = 2 tan(w Ts/2)/w (T' = Ts without prewarp):
    Ad = (I - A T'/2)^-1 (I + A T'/2), Bd = (I - A T'/2)^-1 B T'/... in the form that keeps
    y[k] = C x[k] + D u[k] (a proper discrete realisation with direct feed-through).
    """
    A, B, C, D = (np.atleast_2d(np.asarray(m, float)) for m in (A, B, C, D))
    n = A.shape[0]
    T = Ts if not prewarp_w else 2.0 * math.tan(prewarp_w * Ts / 2.0) / prewarp_w
    I = np.eye(n)
    M = np.linalg.inv(I - A * T / 2.0)
    Ad = M @ (I + A * T / 2.0)
    Bd = M @ B * T
    Cd = C @ M
    Dd = D + C @ M @ B * T / 2.0
    return Ad, Bd, Cd, Dd


def freqresp_z(Ad, Bd, Cd, Dd, w, Ts: float) -> np.ndarray:
    """Discrete frequency response at e^{j w Ts} for angular frequencies w (rad/s)."""
    w = np.atleast_1d(np.asarray(w, float))
    n = Ad.shape[0]
    out = np.empty(len(w), complex)
    for i, wi in enumerate(w):
        z = np.exp(1j * wi * Ts)
        out[i] = (Cd @ np.linalg.solve(z * np.eye(n) - Ad, Bd))[0, 0] + Dd[0, 0]
    return out


@njit(cache=True)
def ss_output(cd, dd, x, u):
    """y = C x + D u of a SISO state space (sum in index order)."""
    s = 0.0
    for i in range(x.shape[0]):
        s += cd[i] * x[i]
    return s + dd * u


@njit(cache=True)
def ss_advance(Ad, bd, x, u, tmp):
    """x <- A x + B u in place (``tmp`` n scratch)."""
    n = x.shape[0]
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += Ad[i, j] * x[j]
        tmp[i] = s + bd[i] * u
    for i in range(n):
        x[i] = tmp[i]


@njit(cache=True)
def ss_step(Ad, bd, cd, dd, x, u, tmp):
    """y[k] = C x + D u, then x <- A x + B u in place (``tmp`` n scratch); returns y[k]."""
    y = ss_output(cd, dd, x, u)
    ss_advance(Ad, bd, x, u, tmp)
    return y


@dataclass
class DiscreteSS:
    """x[k+1] = Ad x[k] + Bd u[k], y[k] = Cd x[k] + Dd u[k] (SISO), one call per tick."""

    Ad: np.ndarray
    Bd: np.ndarray
    Cd: np.ndarray
    Dd: np.ndarray

    def __post_init__(self):
        self.n = self.Ad.shape[0]
        self.x = np.zeros(self.n)
        self._bd = self.Bd[:, 0].copy()
        self._cd = self.Cd[0].copy()
        self._dd = float(self.Dd[0, 0])
        self._ad = np.ascontiguousarray(self.Ad, dtype=float)
        self._tmp = np.zeros(self.n)
        # compile (or load from cache) now, not on a node's first tick; state untouched
        ss_step(self._ad, self._bd, self._cd, self._dd, self.x.copy(), 0.0, self._tmp)

    @classmethod
    def from_continuous(cls, abcd, Ts: float, prewarp_w: float | None = None) -> 'DiscreteSS':
        return cls(*tustin(*abcd, Ts, prewarp_w))

    def output(self, u: float) -> float:
        """y[k] for input u[k] without advancing the state."""
        return ss_output(self._cd, self._dd, self.x, float(u))

    def update(self, u: float) -> float:
        """y[k] and advance the state with u[k] (compiled, shared with core.sim.closed_loop)."""
        return ss_step(self._ad, self._bd, self._cd, self._dd, self.x, float(u), self._tmp)

    def reset(self):
        self.x[:] = 0.0

    def steady_state(self, u: float):
        """Put the state at the equilibrium for a constant input u (needs no pole at z = 1)."""
        self.x[:] = np.linalg.solve(np.eye(self.n) - self.Ad, self._bd * u)   # in place:
        # the compiled kernels hold this array

    def dc_gain(self) -> float:
        return float(self._cd @ np.linalg.solve(np.eye(self.n) - self.Ad, self._bd)) + self._dd
