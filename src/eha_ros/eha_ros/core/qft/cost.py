"""PSO cost functions: velocity loop eqs. 4.68-4.70, position loop eq. 4.75 + 4.70, plus a
closed-loop eigenvalue penalty over the WHOLE family (robust stability, not only at the design
frequencies). Parameters are log10 of the controller constants; all batched over particles."""
from __future__ import annotations

import numpy as np

from . import bounds as qb
from .family import I_X, C_row, TorqueFamily, CascadePlants, torque_responses
from .freqresp import feedback, max_real_eig
from ..controller.lti import Zpk, position_controller, velocity_controller

W_DENSE = np.logspace(-2, np.log10(3000.0), 240)


def _Ws_excess_db(L, Ws):
    """Eq. 4.70 over the family: max_r,w |L/(1+L)| in dB above W_s (>= 0); L (P, N, F)."""
    T = np.abs(L / (1 + L)).max(axis=(1, 2))
    return np.maximum(0.0, qb.db(T) - qb.db(Ws))


def _eig_penalty(A_batch, weight):
    """weight * (1 + max Re) if any closed-loop eigenvalue has Re >= 0, else 0."""
    mr = max_real_eig(A_batch)
    return np.where(mr >= -1e-9, weight * (1.0 + np.minimum(mr, 1e6)), 0.0), mr


def velocity_ctrl(x, k_T):
    K1, K2, K3 = 10 ** np.asarray(x, float)
    return velocity_controller(K1, K2, K3, k_T)


def position_ctrl(x, K, pairs=3):
    """G of eq. 4.74 from x = log10 [z_1..z_n, p_1..p_n, (wz, zeta_z, wp, zeta_p) per
    second-order section]; n = pairs."""
    v = 10 ** np.asarray(x, float)
    bq = v[2 * pairs:].reshape(-1, 4)
    return position_controller(K, v[:pairs], v[pairs:2 * pairs], [tuple(b) for b in bq])


def position_box(spec):
    """(lo, hi) of the log10 position parameters: z_i, p_i in [zp_min, zp_max]; each
    second-order section's wz, wp in the same range and zeta_z, zeta_p in [zeta_min, zeta_max]."""
    n, m = spec['position.pairs'], spec['position.biquads']
    zp = np.log10([spec['position.zp_min'], spec['position.zp_max']])
    ze = np.log10([spec['position.zeta_min'], spec['position.zeta_max']])
    lo = np.r_[np.full(2 * n, zp[0]), np.tile([zp[0], ze[0], zp[0], ze[0]], m)]
    hi = np.r_[np.full(2 * n, zp[1]), np.tile([zp[1], ze[1], zp[1], ze[1]], m)]
    return lo, hi


def drop_state(A, idx):
    """Remove one state (the unobservable position integrator of the velocity loop)."""
    keep = [i for i in range(A.shape[-1]) if i != idx]
    return A[..., keep, :][..., :, keep]


class VelocityCost:
    """J = sum viol_dB (4.68) + sum_{w >= w_e} max(0, |L| - g - T_g) (4.69)
    + Ws_weight * J_s (4.70, family, dense grid) + eigenvalue penalty."""

    def __init__(self, fam: TorqueFamily, spec, bset: qb.BoundSet):
        self.fam, self.spec, self.b = fam, spec, bset
        self.P0 = torque_responses(fam, bset.w)[0][-1]
        self.Pd = torque_responses(fam, W_DENSE)[0]                # (N+1, Fd)
        self.effort = bset.w >= spec['velocity.effort_w_min']
        A, B, _ = fam.all_A()
        self.A, self.B = A, B
        self.Cw = np.broadcast_to(C_row(1, A.shape[1]), (A.shape[0], A.shape[1]))

    def controllers(self, X):
        return [velocity_ctrl(x, self.fam.k_T_nominal) for x in np.atleast_2d(X)]

    def __call__(self, X, detail=False):
        X = np.atleast_2d(X)
        ctrls = self.controllers(X)
        Gd = np.array([c.freq(self.b.w) for c in ctrls])         # (P, F)
        L0 = self.P0[None] * Gd
        viol = qb.violation_db(self.b.merged, L0)
        lo, _, _ = qb.lookup(self.b.merged, L0)
        with np.errstate(divide='ignore', invalid='ignore'):
            over = qb.db(np.abs(L0)) - qb.db(lo)
        soft = np.where(self.effort & (viol == 0) & np.isfinite(over),
                        np.maximum(0.0, over - self.spec['velocity.Tg_db']), 0.0)
        Gdense = np.array([c.freq(W_DENSE) for c in ctrls])
        js = _Ws_excess_db(self.Pd[None] * Gdense[:, None, :], self.spec['velocity.Ws'])
        Acl = np.concatenate([drop_state(feedback(self.A, self.B, self.Cw, c.ss())[0], I_X)[None]
                              for c in ctrls])
        pen, mr = _eig_penalty(Acl.reshape(-1, *Acl.shape[2:]), self.spec['pso.stability_penalty'])
        pen = pen.reshape(len(ctrls), -1).max(axis=1)
        J = viol.sum(1) + soft.sum(1) + self.spec['pso.Ws_weight'] * js + pen
        if detail:
            return dict(J=J, viol=viol, soft=soft, Js=js, max_real=mr.reshape(len(ctrls), -1).max(1))
        return J


class PositionCost:
    """J = m1 sum viol_dB (hard, 4.75) + m2 sum_{effort w} |L0| dB (soft: lower gain is
    cheaper) + Ws_weight * J_s (4.70 on the family, dense grid) + eigenvalue penalty; every
    response includes the loop delay (casc.P_omega; Pade approximant for the eigenvalues)."""

    def __init__(self, casc: CascadePlants, spec, bset: qb.BoundSet):
        self.c, self.spec, self.b = casc, spec, bset
        self.P0 = casc.P_omega(bset.w)[-1]
        self.Pd = casc.P_omega(W_DENSE)
        ew = np.asarray(spec['position.effort_freqs'], float)
        self.effort = np.isin(np.round(bset.w, 9), np.round(ew, 9))
        self.K = spec['position.K']
        self.pairs = spec['position.pairs']
        # closed-loop eigenvalues with a Pade approximant of the loop delay
        self.Ae, self.Be, self.Cx = casc.delayed_ss()

    def controllers(self, X):
        return [position_ctrl(x, self.K, self.pairs) for x in np.atleast_2d(X)]

    def __call__(self, X, detail=False):
        X = np.atleast_2d(X)
        ctrls = self.controllers(X)
        Gd = np.array([c.freq(self.b.w) for c in ctrls])
        L0 = self.P0[None] * Gd
        viol = qb.violation_db(self.b.merged, L0)
        soft = np.where(self.effort, qb.db(np.abs(L0)), 0.0)
        Gdense = np.array([c.freq(W_DENSE) for c in ctrls])
        js = _Ws_excess_db(self.Pd[None] * Gdense[:, None, :], self.spec['position.Ws'])
        Acl = np.concatenate([feedback(self.Ae, self.Be, self.Cx, c.ss())[0][None]
                              for c in ctrls])
        pen, mr = _eig_penalty(Acl.reshape(-1, *Acl.shape[2:]), self.spec['pso.stability_penalty'])
        pen = pen.reshape(len(ctrls), -1).max(axis=1)
        J = self.spec['position.m1'] * viol.sum(1) + self.spec['position.m2'] * soft.sum(1) + \
            self.spec['pso.Ws_weight'] * js + pen
        if detail:
            return dict(J=J, viol=viol, soft=soft, Js=js, max_real=mr.reshape(len(ctrls), -1).max(1))
        return J


def x_of_velocity(G: Zpk, k_T):
    """log10 [K1, K2, K3] of an eq. 4.65 controller (for evaluating the thesis' G_v)."""
    K3 = -min(G.poles)
    K1 = G.gain * k_T / K3
    K2 = -G.zeros[0] * K1
    return np.log10([K1, K2, K3])
