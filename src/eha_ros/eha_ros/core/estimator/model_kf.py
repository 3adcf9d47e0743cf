"""Model-based position Kalman filter of eq. 4.35, driven by the measured motor speed and the
friction estimate of eq. 4.36, ZOH-discretised at Ts from the plant parameters.

Continuous model: :func:`.hydromech.load_pressure` (eq. 4.35 with its corrections: row
2's sign, F_L along +x, the p_D leakage factor k_L of estimator.model.pd_leakage, default eq.
3.22's k_L = 2), states x [m], xdot [m/s], p_D [Pa], inputs omega [rad/s], F_L [N]. F and G are
computed here with the matrix exponential of the augmented matrix (the printed discrete
matrices 4.41/4.42 are not a ZOH of 4.35 with Table 3.8: negative diagonal).

F_L is eq. 4.36's friction estimate F_L = -sign(xdot) min(|p_D A_p|, F_s) (F_s = 800 N), a
force opposing the motion. How it is evaluated (choices, see
:func:`.friction.friction_estimate`): sign(xdot) is taken from the measured motor speed (the
estimator passes its 50 Hz low-pass, model.friction_lowpass, so speed-command chatter does not
flip it), saturated over a small pump-flow band v_eps (the pump drives the piston, xdot ~ D_p
omega / A_p, eq. 3.22 at steady state), and p_D, if used, is the measured load pressure
(estimator.model.friction_pressure; otherwise |F_L| = F_s while moving). Evaluating it from the
filter's own xdot and p_D states, held over Ts, is an explicit feedback A_p p_D[k-1] across the
~760 Hz hydraulic mode and made the discrete model chatter (tried: the estimate's error was 3x
the raw sensor's); a hard sign kicked the p_D state at every reversal.

Optional states beyond eq. 4.35 (see :class:`ModelKF`): the position sensor's low-frequency
Gauss-Markov component b (thesis Fig. 4.6, stage sensor_offset), b' = -2 pi f_c b + w,
measured as z = x + b + v, so that the filter leans on the motor-speed model at low frequency
instead of following the sensor's slow wander; and a leakage-coefficient correction dC
(stage leak_state).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from ..plant.hydromech import HydroMech, load_pressure
from . import kernels


def continuous(h: HydroMech, gm_corner_hz: float | None = None):
    """(A, B) of eq. 4.35 (corrected, :func:`.hydromech.load_pressure`); states
    [x, xdot, p_D (, b)], inputs [omega, F_L]: with ``gm_corner_hz`` the sensor's Gauss-Markov
    offset b' = -2 pi f_c b."""
    A, B = load_pressure(h, 3 if gm_corner_hz is None else 4)
    if gm_corner_hz is not None:
        A[3, 3] = -2.0 * math.pi * gm_corner_hz
    return A, B


def zoh(A: np.ndarray, B: np.ndarray, Ts: float):
    """Zero-order-hold discretisation: expm([[A, B], [0, 0]] Ts) = [[F, G], [0, I]]."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * Ts)
    return E[:n, :n].copy(), E[:n, n:].copy()


LEAK_UNIT = 1e-12      # m^3/(s Pa): unit of the leakage-coefficient correction state


class MeasuredKF(kernels.StateView):
    """Measurement side shared by the model filters: position (+ pressures) update, the
    innovation of a rejected sample, the external-force state. Subclasses set x, P, H, R
    (and H1, R1 for position only), y, S, _y1, _S1, with_pressure, i_load and
    :meth:`pressure_z`."""

    def pressure_z(self, p_a: float, p_b: float) -> tuple:
        """The pressure entries of the measurement vector."""
        raise NotImplementedError

    def _measurements(self, n: int, i_gm, R_pos: float, pressure_states, R_p):
        """H, R: the position (+ the sensor offset state i_gm), then one row per pressure
        state when R_p is given; H1, R1 position only; update buffers."""
        self.with_pressure = R_p is not None
        self.i_moved, self.moved_gate = -1, 0.0     # kernels.update_gated: set_moved_gate
        rows = list(pressure_states) if self.with_pressure else []
        m = 1 + len(rows)
        self.H = np.zeros((m, n))
        self.H[0, 0] = 1.0
        if i_gm is not None:
            self.H[0, i_gm] = 1.0
        for r, i in enumerate(rows, 1):
            self.H[r, i] = 1.0
        self.R = np.diag(np.asarray([R_pos] + [R_p] * len(rows), float))
        self.H1, self.R1 = self.H[:1].copy(), self.R[:1, :1].copy()
        self.Hp, self.Rp = self.H[1:].copy(), self.R[1:, 1:].copy()    # pressures only
        self._tmp = kernels.scratch(n)
        self._ws = np.empty(kernels.workspace_size(n, 3))
        self.y = np.zeros(m)
        self.S = np.zeros((m, m))
        self._y1, self._S1 = np.zeros(1), np.zeros((1, 1))

    def update(self, z_pos: float, p_a: float | None = None, p_b: float | None = None):
        """Measurement update (eq. 4.4-4.6, Joseph form) with the position, and the
        pressures when configured and given. Returns (position innovation, its variance S_00,
        NIS of the whole measurement, measurement dimension)."""
        f0, gate = getattr(self, 'i_frozen', self.n), getattr(self, 'adapt_gate', 0.0)
        if self.with_pressure and p_a is not None:
            z = np.array((z_pos,) + self.pressure_z(p_a, p_b))
            nis = kernels.update_gated(self.x, self.P, self.H, self.R, z, self.y, self.S,
                                       self._ws, f0, gate, self.i_moved, self.moved_gate)
            return float(self.y[0]), float(self.S[0, 0]), float(nis), len(z)
        nis = kernels.update_gated(self.x, self.P, self.H1, self.R1, np.array((z_pos,)),
                                   self._y1, self._S1, self._ws, f0, gate, -1, 0.0)
        return float(self._y1[0]), float(self._S1[0, 0]), float(nis), 1

    def set_moved_gate(self, i_state: int, gate: float) -> None:
        """State ``i_state`` (the sensor offset) is not updated from a sample whose pressure
        innovation exceeds ``gate`` (normalised; 0: off): see kernels.update_gated."""
        self.i_moved, self.moved_gate = int(i_state), float(gate)

    def update_pressures(self, p_a: float, p_b: float) -> float:
        """Update with the pressures alone (the position sensor isolated: its sample is not
        used, but the pressures still hold the hydraulic states); returns the NIS."""
        if not self.with_pressure:
            return 0.0
        z = np.array(self.pressure_z(p_a, p_b))
        m = len(z)
        self.Rp[:] = self.R[1:, 1:]                 # R may be rescaled (noise_level)
        y, S = np.zeros(m), np.zeros((m, m))
        return float(kernels.update_gated(self.x, self.P, self.Hp, self.Rp, z, y, S, self._ws,
                                          getattr(self, 'i_frozen', self.n), 0.0, -1, 0.0))

    def innovation_only(self, z_pos: float):
        """Position innovation and its variance without updating (for a rejected sample)."""
        y = z_pos - float(self.H[0] @ self.x)
        return y, float(self.H[0] @ self.P @ self.H[0] + self.R[0, 0])

    @property
    def load_force(self) -> float:
        """Estimated external force F_d along +x (N), 0 without the state."""
        return 0.0 if self.i_load is None else float(self.x[self.i_load])


class ModelKF(MeasuredKF):
    """Discrete Kalman filter of eq. 4.35 (predict eq. 4.1-4.2, Joseph update eq. 4.4-4.6).

    States [x, xdot, p_D] then, optionally, the sensor's Gauss-Markov offset b (``gm`` =
    (sigma_m, corner_hz)) and a leakage-coefficient correction dC in LEAK_UNIT
    (``q_leak`` its random-walk variance per step, ``p0_leak`` its initial variance): the
    boost check valves make the effective leakage of the nonlinear circuit differ from the
    linear C_eq and depend on the operating point, and a 0.1 mm/s flow error is already
    25 um of position over a quarter period at 1 Hz. dC enters the p_D row of eq. 4.35 as
    -2 beta/V_d dC p_D; its ZOH column is that of a unit input scaled by the held p_D.

    With ``q_load`` (N^2 per step) an external force F_d on the piston (random walk, e.g. an
    aerodynamic hinge load) is a state: the measured load pressure then balances F_d instead
    of accelerating the model piston, so a static load does not bias the position estimate.

    ``q_diag``/``p0_diag``: per-step process noise and initial variances of x, xdot, p_D;
    ``R_pos`` the white position noise variance, ``R_pd`` that of p_D = p_A - p_B (twice one
    sensor's) or None for position-only measurements.
    """

    def __init__(self, h: HydroMech, Ts: float, q_diag, p0_diag, R_pos: float,
                 R_pd: float | None = None, gm: tuple | None = None,
                 F_s: float = 800.0, v_eps: float = 3e-3, q_leak: float | None = None,
                 p0_leak: float = 1.0, q_load: float | None = None, p0_load: float = 1e8):
        self.h, self.Ts, self.F_s, self.v_eps = h, Ts, F_s, v_eps
        self.friction_uses_pressure = True
        A, B = continuous(h, None if gm is None else gm[1])
        F3, G = zoh(A, B, Ts)
        n = A.shape[0] + (q_leak is not None) + (q_load is not None)
        self.n = n
        self._n_lin = A.shape[0]
        self.F = np.eye(n)
        self.F[:A.shape[0], :A.shape[0]] = F3
        self.G = np.zeros((n, 2))
        self.G[:A.shape[0]] = G
        q = list(q_diag)[:3]
        p0 = list(p0_diag)[:3]
        if gm is not None:
            sigma, fc = gm
            a = math.exp(-2.0 * math.pi * fc * Ts)
            q.append(sigma ** 2 * (1.0 - a * a))     # discrete GM: stationary variance sigma^2
            p0.append(sigma ** 2)
        self.i_leak = None
        if q_leak is not None:
            Bl = np.zeros((A.shape[0], 1))
            Bl[2, 0] = -2.0 * h.beta / h.V_d * LEAK_UNIT
            self._g_leak = zoh(A, Bl, Ts)[1][:, 0]     # ZOH column of a unit correction
            self.i_leak = len(q)
            q.append(q_leak)
            p0.append(p0_leak)
        self.i_load = None
        if q_load is not None:
            # external force F_d [N] (random walk), held over Ts like F_L: its F column is
            # the ZOH column of the force input
            self.i_load = len(q)
            self.F[:A.shape[0], self.i_load] = G[:, 1]
            q.append(q_load)
            p0.append(p0_load)
        self.Q = np.diag(np.asarray(q, float))
        self.P0 = np.diag(np.asarray(p0, float))
        self._measurements(n, None if gm is None else 3, R_pos, (2,), R_pd)
        self.u = np.zeros(2)
        self.reset()

    def reset(self, position: float = 0.0, p_a: float | None = None,
              p_b: float | None = None):
        """Initial state at ``position`` with p_D = p_a - p_b (0 without pressures)."""
        kernels.refill(self, 'x', np.zeros(self.n))
        self.x[0] = position
        self.x[2] = 0.0 if p_a is None else p_a - p_b
        kernels.refill(self, 'P', self.P0)

    def predict(self, omega: float, p_D: float | None = None, w_friction: float | None = None):
        """One Ts with the motor speed and the measured p_D (friction estimate of eq. 4.36,
        leakage correction) held over the period (ZOH); p_D None: no pressure sensors, the
        filter's own p_D is used for the leakage term. w_friction: the speed whose sign the
        friction takes (default omega; the estimator passes a low-pass of it). The compiled
        tick's prediction (stepper.predict_filter)."""
        from .stepper import predict_filter
        predict_filter(self, False, omega, p_D, w_friction)

    def pressure_z(self, p_a: float, p_b: float) -> tuple:
        return (p_a - p_b,)                 # p_D

    @property
    def pressure_diff(self) -> float:
        return float(self.x[2])

    @property
    def leak_correction(self) -> float:
        """Estimated leakage correction dC (m^3/(s Pa)), 0 without the state."""
        return 0.0 if self.i_leak is None else float(self.x[self.i_leak]) * LEAK_UNIT
