"""Uncertain plant family of Table 4.5 (log-spaced grid, 270 plants) and the cascade plants.

P_iw = omega/i_ref and P_i = x/i_ref from eq. 3.35 (torque-mode plant, linear.torque_abcd);
P_omega = x/omega_ref and P_d = x/F_L of each plant's OWN closed velocity loop (eq. 3.42 with
the designed G_v), built in state space so uncertainty propagates through the cascade.
P_omega carries the digital loop delay e^{-j w T_d} (T_d = 1.5 Ts + drive delay: one sample
from measurement to applied command, ZOH ~ Ts/2, drive FIFO); the load path P_d does not.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..plant import linear
from ..plant.parameters import PlantParams
from .freqresp import feedback, pad, ss_freqresp
from ..controller.lti import Zpk, pade_delay

NAMES = ('C_eq', 'D_p', 'beta', 'k_T', 'k_E')
I_W, I_X, I_V, I_P = 1, 2, 3, 4  # state indices of omega, x, xdot, p_D in eq. 3.35


def scaled_params(base: dict, scale) -> dict:
    """Plant parameter dict with Table 4.5 multipliers [C_eq, D_p, beta, k_T, k_E] applied
    (C_eq scales C_p, C_c and C_r together)."""
    c, d, b, kt, ke = (float(v) for v in scale)
    out = dict(base)
    for key in ('plant.pump.C_p', 'plant.cylinder.C_c', 'plant.pump.C_r'):
        out[key] = base[key] * c
    out['plant.pump.D_p'] = base['plant.pump.D_p'] * d
    out['plant.fluid.beta'] = base['plant.fluid.beta'] * b
    out['plant.motor.k_T'] = base['plant.motor.k_T'] * kt
    out['plant.motor.k_E'] = base['plant.motor.k_E'] * ke
    return out


def grid_scales(spec) -> np.ndarray:
    """(N, 5) multipliers: log-spaced grids of Table 4.5 (sizes from the spec), C_eq slowest."""
    axes = []
    for name in NAMES:
        lo, hi = spec[f'family.{name}_range']
        n = spec[f'family.{name}_n']
        axes.append(np.geomspace(lo, hi, n) if n > 1 else np.array([np.sqrt(lo * hi)]))
    return np.array(list(itertools.product(*axes)), float)


@dataclass
class TorqueFamily:
    """Torque-mode plants (eq. 3.35) of the family; index 0..N-1, plus the nominal P0."""

    scales: np.ndarray      # (N, 5)
    A: np.ndarray           # (N, 6, 6)
    B: np.ndarray           # (N, 6)     i_ref input
    B_load: np.ndarray      # (N, 6)     F_L input (-1/m_p on xdot, eq. 3.23)
    A0: np.ndarray
    B0: np.ndarray
    B0_load: np.ndarray
    k_T_nominal: float
    D_p_over_A_p: float
    drive_delay: float = 0.0    # plant.drive.delay [s] of the nominal plant file

    @property
    def n(self) -> int:
        return self.A.shape[0]

    def all_A(self):
        """Family plus nominal (nominal last) for batched evaluation."""
        return (np.concatenate([self.A, self.A0[None]]), np.concatenate([self.B, self.B0[None]]),
                np.concatenate([self.B_load, self.B0_load[None]]))


def _abcd(params: dict):
    A, B, _, _ = linear.torque_abcd(params)
    p = PlantParams.from_dict(params)
    bl = np.zeros(6)
    bl[I_V] = -1.0 / p.m_p
    return A, B[:, 0], bl


def build_family(plant: dict, spec) -> TorqueFamily:
    """All grid plants and the nominal plant, each from linear.torque_abcd (eq. 3.35)."""
    scales = grid_scales(spec)
    mats = [_abcd(scaled_params(plant, s)) for s in scales]
    A0, B0, BL0 = _abcd(scaled_params(plant, spec['family.nominal_scale']))
    p0 = PlantParams.from_dict(plant)
    return TorqueFamily(scales, np.array([m[0] for m in mats]), np.array([m[1] for m in mats]),
                        np.array([m[2] for m in mats]), A0, B0, BL0, p0.k_T, p0.D_p / p0.A_p,
                        float(plant['plant.drive.delay']))


def C_row(idx: int, n: int) -> np.ndarray:
    c = np.zeros(n)
    c[idx] = 1.0
    return c


@dataclass
class CascadePlants:
    """Position-loop plants: closed velocity loop per family member (nominal last)."""

    A: np.ndarray            # (N+1, n, n)
    B_ref: np.ndarray        # (N+1, n)   omega_ref input
    B_load: np.ndarray       # (N+1, n)   F_L input
    C_x: np.ndarray          # (n,)       position output
    C_w: np.ndarray          # (n,)       motor speed output
    delay: float = 0.0       # position-loop delay T_d [s] on omega_ref (not in A)
    C_p: np.ndarray | None = None   # (n,)  load pressure p_D output
    leak_gain: float = 0.0   # K_c (rad/s per Pa): omega_ref += K_c p_D, delayed as omega_ref

    def _pressure_loop(self, w):
        """1 - K_c P_pw of a fixed leakage compensation omega_ref += K_c p_D (the
        controller's, core.controller.stepper.control, with its leakage estimate frozen):
        P_pw = p_D/omega_ref with the delay."""
        e = np.exp(-1j * w * self.delay)[None]
        return 1.0 - self.leak_gain * ss_freqresp(self.A, self.B_ref, self.C_p, w) * e

    def P_omega(self, w):
        """x/omega_ref (eq. 3.42 with the designed G_v) times e^{-j w T_d}, (N+1, F); with
        the leakage compensation x/v of omega_ref = v + K_c p_D: P_w / (1 - K_c P_pw)."""
        w = np.atleast_1d(np.asarray(w, float))
        P = ss_freqresp(self.A, self.B_ref, self.C_x, w) * np.exp(-1j * w * self.delay)[None]
        if self.leak_gain:
            P = P / self._pressure_loop(w)
        return P

    def delayed_ss(self, order: int = 4):
        """(A, B_ref, C_x) with a Pade approximant of the delay at the omega_ref input
        (for closed-loop eigenvalues; frequency responses use the exact e^{-j w T_d})."""
        if self.delay <= 0 and not self.leak_gain:
            return self.A, self.B_ref, np.broadcast_to(self.C_x, self.A.shape[:2])
        Ad, Bd, Cd, Dd = pade_delay(self.delay, order).ss() if self.delay > 0 else (
            np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.ones((1, 1)))
        N, n, _ = self.A.shape
        m = Ad.shape[0]
        A = np.zeros((N, n + m, n + m))
        A[:, :n, :n] = self.A
        A[:, :n, n:] = self.B_ref[:, :, None] * Cd[0][None, None, :]
        A[:, n:, n:] = Ad
        B = np.concatenate([self.B_ref * Dd[0, 0], np.broadcast_to(Bd[:, 0], (N, m))], axis=1)
        if self.leak_gain:          # the delay's input is v + K_c p_D
            A[:, :, :n] += self.leak_gain * B[:, :, None] * self.C_p[None, None, :n]
        return A, B, np.broadcast_to(pad(self.C_x, m), (N, n + m))

    def P_d(self, w):
        """x/F_L of the same closed velocity loop, (N+1, F); with the leakage compensation
        P_d + P_w K_c P_pd / (1 - K_c P_pw)."""
        P = ss_freqresp(self.A, self.B_load, self.C_x, w)
        if self.leak_gain:              # P_pd = p_D/F_L
            w = np.atleast_1d(np.asarray(w, float))
            P = P + self.P_omega(w) * self.leak_gain * ss_freqresp(self.A, self.B_load,
                                                                   self.C_p, w)
        return P


def velocity_loop_plants(fam: TorqueFamily, Gv: Zpk, delay: float = 0.0,
                         leak_gain: float = 0.0) -> CascadePlants:
    """Close each plant's velocity loop (speed feedback, i_ref = G_v (omega_ref - omega));
    delay: position-loop delay T_d [s] carried by P_omega; leak_gain: a fixed leakage
    compensation K_c (CascadePlants)."""
    A, B, BL = fam.all_A()
    n = A.shape[1]
    Cw = np.broadcast_to(C_row(I_W, n), (A.shape[0], n))
    Acl, Br, (Bl,) = feedback(A, B, Cw, Gv.ss(), extra_B=(BL,))
    m = Acl.shape[1] - n
    return CascadePlants(Acl, Br, Bl, pad(C_row(I_X, n), m), pad(C_row(I_W, n), m), float(delay),
                         pad(C_row(I_P, n), m), float(leak_gain))


def torque_responses(fam: TorqueFamily, w):
    """(P_iw, P_ix) of all plants (nominal last), each (N+1, F): omega/i_ref and x/i_ref."""
    A, B, _ = fam.all_A()
    n = A.shape[1]
    return ss_freqresp(A, B, C_row(I_W, n), w), ss_freqresp(A, B, C_row(I_X, n), w)
