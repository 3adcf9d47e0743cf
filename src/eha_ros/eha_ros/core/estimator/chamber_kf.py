"""Chamber-pressure Kalman filter: eq. 4.35 with p_D split into the two chamber pressures of
eq. 3.20-3.21 and the boost circuit of Fig. 3.12 (check valves from the accumulator).

Why: in the boost circuit the low-pressure chamber sits on its check valve at the accumulator
pressure minus the cracking pressure, so while the piston moves only the high-pressure chamber
compresses (half the hydraulic capacitance of eq. 4.35's p_D row is wrong by a factor of 2)
and its port leakage C_r (p - p_acc) runs against p_acc, not against the other chamber (eq.
4.35 lumps it into C_eq p_D and misses C_r times the cracking pressure, a flow whose sign flips
with the load: a triangular position error at every reversal). Only during a load reversal
are both chambers free. With both pressures measured, a linear model per valve state
(check valve of A / of B open or shut) follows all three phases.

Continuous model (states x [m], xdot [m/s], p_A, p_B [Pa gauge]; inputs omega [rad/s], F_L [N],
1; s_A, s_B in {0, 1}: check valve open)::

    x'    = xdot
    xdot' = (A_p (p_A - p_B) - b xdot + F_L) / m_p
    p_A'  = beta/V_d ( D_p omega - A_p xdot - C_x (p_A - p_B) - C_r (p_A - p_acc)
                       + s_A K_c (p_c - p_A))
    p_B'  = beta/V_d (-D_p omega + A_p xdot + C_x (p_A - p_B) - C_r (p_B - p_acc)
                       + s_B K_c (p_c - p_B))

C_x = C_p + C_c (cross-port and cross-piston leakage), C_r per-port leakage to the accumulator
circuit (eq. 3.15), K_c the check-valve conductance, p_c = p_acc - crack - band/2 where its
flow line crosses zero. The valve state is taken from the prior pressure estimate: open below
p_c, where the linear flow is an inflow (a threshold at the cracking pressure would let the
line's reverse flow between p_c and p_acc - crack hold a free chamber on its valve); the
four (F, G) pairs are ZOH-discretised once. Optional states as in
:class:`~.model_kf.ModelKF`: the sensor's Gauss-Markov offset b and an external force F_d.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernels
from .model_kf import MeasuredKF, friction_estimate, zoh


@dataclass(frozen=True)
class Circuit:
    """Constants of the chamber model (SI units, pressures gauge)."""

    A_p: float
    m_p: float
    b: float
    beta: float
    V_d: float
    C_x: float
    C_r: float
    D_p: float
    K_c: float
    p_acc: float
    crack: float
    band: float

    @property
    def p_c(self) -> float:
        """Zero-flow pressure of the check valve's linear flow line."""
        return self.p_acc - self.crack - 0.5 * self.band


def continuous(c: Circuit, s_a: bool, s_b: bool, gm_corner_hz: float | None = None):
    """(A, B) for check-valve states s_a, s_b; states [x, xdot, p_A, p_B (, b)], inputs
    [omega, F_L, 1]."""
    n = 4 if gm_corner_hz is None else 5
    k = c.beta / c.V_d
    A = np.zeros((n, n))
    B = np.zeros((n, 3))
    A[0, 1] = 1.0
    A[1, 1] = -c.b / c.m_p
    A[1, 2], A[1, 3] = c.A_p / c.m_p, -c.A_p / c.m_p
    B[1, 1] = 1.0 / c.m_p
    for i, sign, s in ((2, 1.0, s_a), (3, -1.0, s_b)):
        j = 5 - i                                   # the other chamber
        A[i, 1] = -sign * k * c.A_p
        A[i, i] = -k * (c.C_x + c.C_r + (c.K_c if s else 0.0))
        A[i, j] = k * c.C_x
        B[i, 0] = sign * k * c.D_p
        B[i, 2] = k * (c.C_r * c.p_acc + (c.K_c * c.p_c if s else 0.0))
    if gm_corner_hz is not None:
        A[4, 4] = -2.0 * math.pi * gm_corner_hz
    return A, B


class ChamberKF(MeasuredKF):
    """Discrete Kalman filter of the chamber model (predict eq. 4.1-4.2, Joseph update
    eq. 4.4-4.6), measurements position (+ b) and, when given, p_A and p_B.

    ``q_diag``/``p0_diag``: per-step process noise and initial variances of x, xdot and each
    chamber pressure; ``R_pos`` the white position noise variance, ``R_p`` one pressure
    sensor's variance or None for position-only updates; ``gm`` = (sigma_m, corner_hz) adds
    the sensor's Gauss-Markov offset; ``q_load`` (N^2 per step) adds an external force state.
    """

    def __init__(self, c: Circuit, Ts: float, q_diag, p0_diag, R_pos: float,
                 R_p: float | None = None, gm: tuple | None = None, F_s: float = 800.0,
                 v_eps: float = 3e-3, q_load: float | None = None, p0_load: float = 1e8):
        self.c, self.Ts, self.F_s, self.v_eps = c, Ts, F_s, v_eps
        self.friction_uses_pressure = False
        corner = None if gm is None else gm[1]
        n_lin = 4 if gm is None else 5
        n = n_lin + (q_load is not None)
        self.n, self._n_lin = n, n_lin
        q = list(q_diag)[:3] + [list(q_diag)[2]]
        p0 = list(p0_diag)[:3] + [list(p0_diag)[2]]
        if gm is not None:
            sigma, fc = gm
            a = math.exp(-2.0 * math.pi * fc * Ts)
            q.append(sigma ** 2 * (1.0 - a * a))
            p0.append(sigma ** 2)
        self.i_leak = None                          # no leakage-correction state here
        self.i_load = None
        if q_load is not None:
            self.i_load = len(q)
            q.append(q_load)
            p0.append(p0_load)
        # (F, G) per check-valve state, index 2 s_a + s_b
        self.modes = []
        for s_a in (False, True):
            for s_b in (False, True):
                A, B = continuous(c, s_a, s_b, corner)
                Fl, Gl = zoh(A, B, Ts)
                F = np.eye(n)
                F[:n_lin, :n_lin] = Fl
                G = np.zeros((n, 3))
                G[:n_lin] = Gl
                if self.i_load is not None:
                    F[:n_lin, self.i_load] = Gl[:, 1]     # F_d held over Ts like F_L
                self.modes.append((F, G))
        self.F, self.G = self.modes[0]
        self.mode = 0
        self.Q = np.diag(np.asarray(q, float))
        self.P0 = np.diag(np.asarray(p0, float))
        self._measurements(n, None if gm is None else 4, R_pos, (2, 3), R_p)
        self.u = np.zeros(3)
        self.u[2] = 1.0
        self.reset()

    def reset(self, position: float = 0.0, p_a: float | None = None,
              p_b: float | None = None):
        self.x = np.zeros(self.n)
        self.x[0] = position
        self.x[2] = self.c.p_acc if p_a is None else p_a
        self.x[3] = self.c.p_acc if p_b is None else p_b
        self.P = self.P0.copy()

    def valve_mode(self) -> int:
        """Index into :attr:`modes` of the check-valve state the prior pressures give:
        2 s_A + s_B, a valve open below p_c."""
        p_c = self.c.p_c
        return 2 * int(self.x[2] < p_c) + int(self.x[3] < p_c)

    def predict(self, omega: float, p_D: float | None = None, w_friction: float | None = None):
        """One Ts with the motor speed and the friction estimate of eq. 4.36 (from the
        measured p_D, or the filter's own, when friction_uses_pressure; its sign from
        w_friction, default omega) held over the period; the check-valve states come from the
        prior chamber pressures."""
        self.u[0] = omega
        pd = (self.x[2] - self.x[3]) if p_D is None else p_D
        w = omega if w_friction is None else w_friction
        self.u[1] = friction_estimate(w, pd if self.friction_uses_pressure else None,
                                      self.c.A_p, self.c.D_p, self.F_s, self.v_eps)
        self.mode = self.valve_mode()
        self.F, self.G = self.modes[self.mode]
        kernels.predict(self.x, self.P, self.F, self.G, self.u, self.Q, self._tmp)

    def pressure_z(self, p_a: float, p_b: float) -> tuple:
        return (p_a, p_b)

    @property
    def pressure_diff(self) -> float:
        return float(self.x[2] - self.x[3])
