"""Chinniah's friction estimators (thesis 4.1.2, appendix C.1-C.3): friction model eq. 4.8,
a 3-state filter for alpha_3 (eqs. 4.15-4.22) and a 4-state filter for alpha_1, alpha_2 with
alpha_3 as an input (eqs. 4.23-4.29), run as the iterative pair the thesis describes.

Both are pseudo-linear Kalman filters as in the appendix code: the transition matrix is
evaluated at the current velocity estimate and used for state and covariance alike, and the
pressure difference enters as a known input (eq. 4.19). Measurements are position and
velocity (H = [I 0]). Differences from the printed text, all following appendix C:
- eq. 4.16's phi_22 "1 - X_3 k T_s/m_p" is garbled; C.2 uses phi = [1 Ts 0; 0 1 -Ts sign(x2)/m;
  0 0 1], i.e. alpha_3 enters as a force -alpha_3 sign(xdot).
- eq. 4.26 prints +alpha_3 sign(x2); friction opposes motion, C.3 uses -alpha_3 sign(x2).
- Iterative structure: the 3-state filter also takes the latest alpha_1, alpha_2 of the 4-state
  filter as known inputs (zero until it has them), so alpha_3 does not absorb the quadratic
  and linear friction terms (with them ignored it is biased by their cycle average).
Units: x m, xdot m/s, alpha_1 N s^2/m^2, alpha_2 N s/m, alpha_3 N, dP Pa.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernels

# Table 4.1 and appendix C (Chinniah's actuator, not the EHA)
ALPHA_TABLE_4_1 = (2.1e4, -1450.0, 46.0)
M_APPENDIX_C = 20.0            # kg
A_APPENDIX_C = 5.05e-4         # m^2
TS_APPENDIX_C = 1e-4           # s


def friction(xdot: float, a1: float, a2: float, a3: float) -> float:
    """Eq. 4.8: F_f = a1 sign(xdot) xdot^2 + a2 xdot + a3 sign(xdot)."""
    s = float(np.sign(xdot))
    return a1 * s * xdot * xdot + a2 * xdot + a3 * s


class Chinniah3:
    """3-state filter [x, xdot, alpha_3] (eqs. 4.15-4.22; R, P0, Q of 4.20-4.22 by default)."""

    def __init__(self, m: float, A: float, Ts: float, R=(1e-9, 1e-3), P0=(1e9, 1e9, 1e9),
                 Q=(1e-9, 1e-12, 1e-4)):
        self.m, self.A, self.Ts = m, A, Ts
        self.F = np.array([[1.0, Ts, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        self.G = np.array([[0.0], [1.0], [0.0]])                      # eq. 4.18
        self.H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        self.R, self.Q = np.diag(R), np.diag(Q)
        self.P = np.diag(np.asarray(P0, float))
        self.x = np.zeros(3)
        self._u, self._tmp = np.zeros(1), kernels.scratch(3)
        self.y, self.S = np.zeros(2), np.zeros((2, 2))

    def step(self, z_pos: float, z_vel: float, dP: float, a1: float = 0.0, a2: float = 0.0):
        """Update with [x, xdot] then predict one Ts with dP (Pa) and known alpha_1, alpha_2."""
        nis = kernels.update(self.x, self.P, self.H, self.R, np.array((z_pos, z_vel)), self.y,
                             self.S)
        v = self.x[1]
        s = math.copysign(1.0, v) if v != 0.0 else 0.0
        self.F[1, 2] = -self.Ts * s / self.m                          # eq. 4.16 (C.2)
        self._u[0] = (dP * self.A - a1 * s * v * v - a2 * v) * self.Ts / self.m   # eq. 4.19
        kernels.predict(self.x, self.P, self.F, self.G, self._u, self.Q, self._tmp)
        return nis

    @property
    def alpha3(self) -> float:
        return float(self.x[2])


class Chinniah4:
    """4-state filter [x, xdot, alpha_1, alpha_2] with alpha_3 as an input (eqs. 4.23-4.29)."""

    def __init__(self, m: float, A: float, Ts: float, R=(1e-12, 1e-3),
                 P0=(1e9, 1e9, 1e9, 1e9), Q=(1e-12, 1e-7, 1e-7, 1e-4)):
        self.m, self.A, self.Ts = m, A, Ts
        self.F = np.eye(4)
        self.F[0, 1] = Ts
        self.G = np.array([[0.0], [1.0], [0.0], [0.0]])              # eq. 4.25
        self.H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
        self.R, self.Q = np.diag(R), np.diag(Q)
        self.P = np.diag(np.asarray(P0, float))
        self.x = np.zeros(4)
        self._u, self._tmp = np.zeros(1), kernels.scratch(4)
        self.y, self.S = np.zeros(2), np.zeros((2, 2))

    def step(self, z_pos: float, z_vel: float, dP: float, a3: float):
        nis = kernels.update(self.x, self.P, self.H, self.R, np.array((z_pos, z_vel)), self.y,
                             self.S)
        v = self.x[1]
        s = math.copysign(1.0, v) if v != 0.0 else 0.0
        self.F[1, 2] = -s * self.Ts * v * v / self.m                  # eq. 4.23
        self.F[1, 3] = -self.Ts * v / self.m
        self._u[0] = (self.A * dP - a3 * s) * self.Ts / self.m        # eq. 4.26 (C.3 sign)
        kernels.predict(self.x, self.P, self.F, self.G, self._u, self.Q, self._tmp)
        return nis

    @property
    def alpha1(self) -> float:
        return float(self.x[2])

    @property
    def alpha2(self) -> float:
        return float(self.x[3])


class ChinniahEstimator:
    """The iterative pair: alpha_3 from the 3-state filter feeds the 4-state filter, whose
    alpha_1, alpha_2 feed the 3-state filter back (after ``feedback_delay`` s)."""

    def __init__(self, m: float = M_APPENDIX_C, A: float = A_APPENDIX_C,
                 Ts: float = TS_APPENDIX_C, feedback_delay: float = 0.2, **kw):
        self.f3 = Chinniah3(m, A, Ts)
        self.f4 = Chinniah4(m, A, Ts)
        self.Ts = Ts
        self._k, self._k_fb = 0, int(round(feedback_delay / Ts))

    def step(self, z_pos: float, z_vel: float, dP: float):
        fb = self._k >= self._k_fb
        a1 = self.f4.alpha1 if fb else 0.0
        a2 = self.f4.alpha2 if fb else 0.0
        self.f3.step(z_pos, z_vel, dP, a1, a2)
        self.f4.step(z_pos, z_vel, dP, self.f3.alpha3)
        self._k += 1

    @property
    def alphas(self) -> tuple:
        return self.f4.alpha1, self.f4.alpha2, self.f3.alpha3


class ChinniahJoint:
    """All of eqs. 4.10-4.14 in one pseudo-linear filter: [x, xdot, alpha_1, alpha_2, alpha_3].

    The thesis splits this into the 3-state/4-state pair because of weak observability; on a
    sine the three friction regressors (sign(v) v^2, v, sign(v)) are strongly correlated, and
    the split pair ignores those correlations (alpha_3 ends 10-20 % off on seeds of the 4 Hz,
    3 mm test), while the joint filter carries them in P (within ~6 %). R and P0 as eq. 4.20/
    4.21; Q of the coefficients small (slowly varying friction)."""

    def __init__(self, m: float = M_APPENDIX_C, A: float = A_APPENDIX_C,
                 Ts: float = TS_APPENDIX_C, R=(1e-9, 1e-3), P0=(1e9,) * 5,
                 Q=(1e-12, 1e-7, 1e-7, 1e-7, 1e-7)):
        self.m, self.A, self.Ts = m, A, Ts
        self.F = np.eye(5)
        self.F[0, 1] = Ts
        self.G = np.zeros((5, 1))
        self.G[1, 0] = 1.0
        self.H = np.eye(2, 5)
        self.R, self.Q = np.diag(R), np.diag(Q)
        self.P = np.diag(np.asarray(P0, float))
        self.x = np.zeros(5)
        self._u, self._tmp = np.zeros(1), kernels.scratch(5)
        self.y, self.S = np.zeros(2), np.zeros((2, 2))

    def step(self, z_pos: float, z_vel: float, dP: float):
        nis = kernels.update(self.x, self.P, self.H, self.R, np.array((z_pos, z_vel)), self.y,
                             self.S)
        v = self.x[1]
        s = math.copysign(1.0, v) if v != 0.0 else 0.0
        self.F[1, 2] = -self.Ts * s * v * v / self.m                  # eq. 4.11
        self.F[1, 3] = -self.Ts * v / self.m
        self.F[1, 4] = -self.Ts * s / self.m
        self._u[0] = self.A * dP * self.Ts / self.m
        kernels.predict(self.x, self.P, self.F, self.G, self._u, self.Q, self._tmp)
        return nis

    @property
    def alphas(self) -> tuple:
        return float(self.x[2]), float(self.x[3]), float(self.x[4])


@dataclass
class RigData:
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    dP: np.ndarray
    z_pos: np.ndarray
    z_vel: np.ndarray


def simulate_rig(duration: float = 2.0, Ts: float = TS_APPENDIX_C, amplitude: float = 3e-3,
                 freq: float = 4.0, alphas=ALPHA_TABLE_4_1, m: float = M_APPENDIX_C,
                 A: float = A_APPENDIX_C, pos_var: float = 1e-10, vel_var: float = 0.01,
                 dp_sigma: float = 0.0, seed: int = 0) -> RigData:
    """Simulated data with known friction (sec. 4.1.2): the piston follows a sine; the
    pressure difference is what eq. 4.9 with the friction of eq. 4.8 needs for that motion;
    white noise on position (variance 1e-10 m^2), velocity (0.01 (m/s)^2) and optionally on
    the pressure (0.316 bar in the thesis' robustness check)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration / Ts))) * Ts
    w = 2.0 * math.pi * freq
    x = amplitude * np.sin(w * t)
    v = amplitude * w * np.cos(w * t)
    acc = -amplitude * w * w * np.sin(w * t)
    a1, a2, a3 = alphas
    s = np.sign(v)
    ff = a1 * s * v * v + a2 * v + a3 * s
    dP = (m * acc + ff) / A + dp_sigma * rng.standard_normal(len(t))
    return RigData(t, x, v, dP, x + math.sqrt(pos_var) * rng.standard_normal(len(t)),
                   v + math.sqrt(vel_var) * rng.standard_normal(len(t)))
