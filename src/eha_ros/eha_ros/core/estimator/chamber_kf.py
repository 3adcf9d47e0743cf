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

Continuous model: :func:`.hydromech.chamber` (eq. 3.20-3.21 with the check valves of Fig.
3.12; states x [m], xdot [m/s], p_A, p_B [Pa gauge]; inputs omega [rad/s], F_L [N], 1; s_A, s_B
in {0, 1}: check valve open, below its zero-flow pressure p_c). The valve state is taken from
the prior pressure estimate: open below p_c, where the linear flow is an inflow (a threshold at
the cracking pressure would let the line's reverse flow between p_c and p_acc - crack hold a
free chamber on its valve), and shut where the tick's flows would lift the chamber above p_c
with it shut (a check valve passes no reverse flow), unless the measured pressure puts the
chamber clearly below p_c (stepper.valve_state); the four (F, G) pairs are ZOH-discretised
once. Optional states as in :class:`~.model_kf.ModelKF`: the sensor's Gauss-Markov offset b
and an external force F_d; and the adaptive relative leakage, displacement and compliance
corrections lambda, delta, kappa, an EKF with the leakage Jacobian
(:func:`.hydromech.leak_sensitivity`), with the estimate projection of :mod:`.adapt` (issue
15: the loop must hold on every plant of Table 4.5).
"""
from __future__ import annotations

import math

import numpy as np

from ..plant import hydromech as hm
from ..plant.hydromech import Circuit, leak_sensitivity
from . import adapt, kernels
from .model_kf import MeasuredKF, zoh


def continuous(c: Circuit, s_a: bool, s_b: bool, gm_corner_hz: float | None = None):
    """(A, B) of :func:`.hydromech.chamber` for check-valve states s_a, s_b; states
    [x, xdot, p_A, p_B (, b)], inputs [omega, F_L, 1]: with ``gm_corner_hz`` the sensor's
    Gauss-Markov offset b' = -2 pi f_c b."""
    A, B = hm.chamber(c, s_a, s_b, 4 if gm_corner_hz is None else 5)
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
                 v_eps: float = 3e-3, q_load: float | None = None, p0_load: float = 1e8,
                 leakage: tuple | None = None, displacement: tuple | None = None,
                 compliance: tuple | None = None, offset_bound: float = 0.0,
                 adapt_gate: float = 0.0,
                 friction: tuple | None = None,
                 friction_scale: tuple | None = None, external: tuple | None = None,
                 flow: bool = False):
        """``leakage``/``displacement``/``compliance``: (q per step, p0, lo, hi) of the relative
        corrections lambda/delta/kappa (:mod:`.adapt`), None: not a state; ``offset_bound``
        [m]: projection bound of the sensor offset b (0: none); ``adapt_gate``: no update of
        lambda, delta, kappa from a sample whose normalised position innovation exceeds it (0:
        always); ``friction``: (F_c, F_s, v_s, alpha, v_rest, n_rest, q_rest) of the Stribeck
        friction input and its rest regime (adapt.friction_input; None: eq. 4.36 with F_s,
        v_eps);
        ``friction_scale``: (q, p0, lo, hi) of the friction scale phi, None: not a state;
        ``external``: (q, p0, lo, hi) of the external-leakage correction epsilon (C_r x
        (1 + epsilon); lambda then scales C_x only), None: lambda scales both paths;
        ``flow``: the unmodelled flow v_f as a state (adapt.flow_noise; Stribeck friction
        only: it opens at rest)."""
        self.c, self.Ts, self.F_s, self.v_eps = c, Ts, F_s, v_eps
        self.friction_uses_pressure = False
        corner = None if gm is None else gm[1]
        n_lin = 4 if gm is None else 5
        self._n_lin = n_lin
        if friction is None:
            friction_scale = None                  # phi scales the Stribeck curve only
        if leakage is None:
            external = None                        # epsilon splits lambda's paths
        q, p0 = self._layout(q_diag, p0_diag, gm, q_load, p0_load, flow and friction is not None,
                             leakage, displacement, compliance, friction_scale, external)
        n = len(q)
        self.n = n
        self.i_gm = 4 if gm is not None else -1
        self.offset_bound = float(offset_bound)
        self.edge = 0                               # adaptive states on a bound (last update)
        params = [i for i in (self.i_leakage, self.i_displacement, self.i_compliance,
                              self.i_friction, self.i_external_leakage) if i >= 0]
        self.i_frozen = min(params) if params else n     # the adaptive states are the last
        self.adapt_gate = float(adapt_gate)
        self._discretise(corner)
        self.F, self.G = (a.copy() for a in self.modes[0])   # this tick's pair, copied in
        self.mode = 0
        self.Q = np.diag(np.asarray(q, float))
        self.P0 = np.diag(np.asarray(p0, float))
        self._measurements(n, None if gm is None else 4, R_pos, (2, 3), R_p)
        self.u = np.zeros(3)
        self.u[2] = 1.0
        self.fk = None if friction is None else self._friction_constants(friction)
        # the largest pressure difference friction alone can hold (adapt.flow_noise): the
        # static friction at the top of the friction state's range
        F_top = friction[1] if friction is not None else F_s
        self.dp_friction = F_top * (1.0 + self.friction_range[1]) / c.A_p
        self.reset()

    def _layout(self, q_diag, p0_diag, gm, q_load, p0_load, flow, leakage, displacement,
                compliance, friction_scale, external):
        """The state vector: x, xdot, p_A, p_B (, b, F_d, v_f), then the adaptive states;
        sets their indexes (i_*, -1: not a state) and ranges; returns the per-step process
        noise and the initial variance of each state."""
        Ts = self.Ts
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
        self.i_flow = -1
        if flow:                                    # unmodelled flow v_f, starts closed at 0
            self.i_flow = len(q)
            q.append(0.0)
            p0.append(0.0)
        # the adaptive states' indexes in x (-1: not a state) and ranges, named as their
        # estimator.model.* parameters
        self.i_leakage = self.i_displacement = self.i_compliance = -1
        self.i_friction = self.i_external_leakage = -1
        self.leakage_range = self.displacement_range = self.compliance_range = (0.0, 0.0)
        self.friction_range = self.external_leakage_range = (0.0, 0.0)
        self.c_Ts = self.c.V_d / (self.c.beta * Ts)
        for name, spec in (('leakage', leakage), ('displacement', displacement),
                           ('compliance', compliance), ('friction', friction_scale),
                           ('external_leakage', external)):
            if spec is not None:
                setattr(self, 'i_' + name, len(q))
                setattr(self, name + '_range', (float(spec[2]), float(spec[3])))
                q.append(spec[0])
                p0.append(spec[1])
        return q, p0

    def _discretise(self, corner):
        """(F, G) per check-valve state (:attr:`modes`, index 2 s_a + s_b), ZOH-discretised
        once, with the ZOH columns of a unit flow into A and B (:attr:`Lm`) and the leakage
        sensitivities of F (:attr:`Dm`: lambda's paths | epsilon's)."""
        c, Ts, n, n_lin = self.c, self.Ts, self.n, self._n_lin
        self.modes = []
        L = []                                      # ZOH columns of a unit flow into A, B
        D = []                                      # leakage sensitivity of the ZOH F: lambda's
        De = []                                     # and epsilon's paths
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
                Lq = np.zeros((n, 2))
                Lq[:n_lin] = zoh(A, hm.chamber_flow_columns(c, n_lin), Ts)[1]
                if self.i_flow >= 0:                      # A_p v_f into A, out of B
                    F[:n_lin, self.i_flow] = c.A_p * (Lq[:n_lin, 0] - Lq[:n_lin, 1])
                self.modes.append((F, G))
                L.append(Lq)
                split = self.i_external_leakage >= 0
                D.append(leak_sensitivity(c, A, Ts, n, 'x' if split else 'xr'))
                De.append(leak_sensitivity(c, A, Ts, n, 'r') if split else np.zeros((n, n)))
        self.Lm = np.vstack(L)                      # (4 n, 2), rows of mode m at m n
        self.Dm = np.hstack((np.vstack(D), np.vstack(De)))   # (4 n, 2 n): lambda | epsilon

    def _friction_constants(self, friction):
        """adapt.friction_input's constants: the circuit's, the Stribeck curve's and its rest
        regime's (``friction``), the adaptive states' indexes."""
        c = self.c
        fk = np.zeros(adapt.NFK)
        fk[adapt.FK_AP], fk[adapt.FK_DP] = c.A_p, c.D_p
        fk[adapt.FK_CX], fk[adapt.FK_CR], fk[adapt.FK_PACC] = c.C_x, c.C_r, c.p_acc
        (fk[adapt.FK_FC], fk[adapt.FK_FS], fk[adapt.FK_VS], fk[adapt.FK_ALPHA],
         fk[adapt.FK_VREST], fk[adapt.FK_NREST], fk[adapt.FK_QREST]) = friction
        fk[adapt.FK_ILAM], fk[adapt.FK_IDEL] = self.i_leakage, self.i_displacement
        fk[adapt.FK_IPHI] = self.i_friction
        fk[adapt.FK_IEPS] = self.i_external_leakage
        return fk

    def reset(self, position: float = 0.0, p_a: float | None = None,
              p_b: float | None = None):
        kernels.refill(self, 'x', np.zeros(self.n))
        self.x[0] = position
        self.x[2] = self.c.p_acc if p_a is None else p_a
        self.x[3] = self.c.p_acc if p_b is None else p_b
        kernels.refill(self, 'P', self.P0)
        kernels.refill(self, 'clipped', np.zeros(1))    # adapt.project: clipping updates in a row
        kernels.refill(self, 'p_last', np.zeros(4))     # adapt.pressure_increments
        self.p_last[:2] = self.x[2:4]
        kernels.refill(self, 'fs', np.zeros(adapt.NFS))  # adapt.friction_input state
        if self.fk is not None:             # at rest, as x[1] = 0 says (adapt.friction_input)
            self.fs[adapt.FS_N] = self.fk[adapt.FK_NREST]

    def predict(self, omega: float, p_D: float | None = None, w_friction: float | None = None):
        """One Ts with the motor speed and the piston friction held over the period: the
        Stribeck curve at the pump-flow velocity (adapt.friction_input), or, without
        ``friction``, eq. 4.36 (from the measured p_D, or the filter's own, when
        friction_uses_pressure; its sign from w_friction, default omega); the check-valve
        states come from the prior chamber pressures. The compiled tick's prediction
        (stepper.predict_filter)."""
        from .stepper import predict_filter
        predict_filter(self, True, omega, p_D, w_friction)

    def update(self, z_pos: float, p_a: float | None = None, p_b: float | None = None):
        """MeasuredKF.update, then the estimate projection of :func:`.adapt.project`."""
        out = super().update(z_pos, p_a, p_b)
        self.project()
        return out

    def project(self) -> int:
        self.edge = adapt.project(self.x, self.i_leakage, *self.leakage_range,
                                  self.i_displacement, *self.displacement_range,
                                  self.i_compliance, *self.compliance_range, self.i_friction,
                                  *self.friction_range, self.i_external_leakage,
                                  *self.external_leakage_range, self.i_gm, self.offset_bound,
                                  self.clipped, adapt.EDGE_TICKS)
        return self.edge

    @property
    def external_leakage_correction(self) -> float:
        """Estimated relative correction epsilon of the per-port leakage C_r (0 without)."""
        return float(self.x[self.i_external_leakage]) if self.i_external_leakage >= 0 else 0.0

    @property
    def friction_correction(self) -> float:
        """Estimated relative friction correction phi (plant friction / nominal - 1)."""
        return float(self.x[self.i_friction]) if self.i_friction >= 0 else 0.0

    @property
    def leakage_correction(self) -> float:
        """Estimated relative leakage correction lambda (plant leakage / nominal - 1; of C_x
        only when epsilon is a state)."""
        return float(self.x[self.i_leakage]) if self.i_leakage >= 0 else 0.0

    @property
    def compliance_correction(self) -> float:
        """Estimated relative compliance correction kappa (beta nominal / beta - 1)."""
        return float(self.x[self.i_compliance]) if self.i_compliance >= 0 else 0.0

    @property
    def displacement_correction(self) -> float:
        """Estimated relative displacement correction delta (D_p / nominal - 1)."""
        return float(self.x[self.i_displacement]) if self.i_displacement >= 0 else 0.0

    def pressure_z(self, p_a: float, p_b: float) -> tuple:
        return (p_a, p_b)

    @property
    def pressure_diff(self) -> float:
        return float(self.x[2] - self.x[3])
