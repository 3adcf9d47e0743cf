"""Estimator tuning derived from the plant family and the sensor model (issue 15), not tuned
at the nominal plant: what scripts/tune_estimator computes and writes to the TUNED table of
core/estimator/params.py (the one home of these defaults).

Inputs: the Table 4.5 family (config/qft_spec.yaml, family.*), the robustness box beyond it
(issue 15: C_eq x0.05..15, D_p x0.75..1.05, beta x0.6..1.5, sensor noise x1..2) and the
position-sensor model (config/plant.yaml plant.sensors.*, = the filter's R).

- Adaptive states (core.estimator.adapt; state augmentation, Simon 2006 sec. 7.4):
  lambda = C/C_0 - 1, delta = D_p/D_p0 - 1, kappa = beta_0/beta - 1.
  p0 = the variance of the correction over the Table 4.5 family with log-uniform multipliers
  (the prior: a plant is anywhere in the thesis' family; the box's variance, twice as large
  for lambda, measured 0.251 instead of 0.247 worst nominal RMSE ratio); range (projection,
  Simon 2006 sec. 7.5) = the box's correction range widened by ``margin`` of its span on
  each side (plants beyond the family must still be reachable); q (random walk
  per step) = (rho sigma_family)^2 Ts / T_memory: the parameters are constant for a plant but
  leakage and bulk modulus drift with temperature and entrained air; the filter may move a
  fraction rho of the family spread within its memory T_memory (Bar-Shalom et al. 2001
  sec. 6.2: random-walk process noise sized by the change expected over the time of
  interest); the displacement is geometry and does not drift (q = 0, a constant parameter).
  T_memory = 1e4 s (oil warm-up scale), rho = 0.1. Measured (nominal 1 Hz sine, seeds 1-4,
  goal 0.25): worst RMSE ratio 0.249 with 1e4 s, 0.255 with 1e3 s, 0.27 with 1e2 s; the
  leakiest plants (C_eq x10) would want a shorter memory (0.57 at 1e2 s, 0.62 at 1e3 s).
- Leakage paths (issue 15): lambda scales the cross-port C_x = C_p + C_c, epsilon the per-port
  C_r; the box's leak_split s moves leakage between them with C_eq = C_x + C_r/2 kept (eq.
  3.22): C_r x C_eq s, C_x x C_eq (C_eq0 - s C_r0/2)/C_x0. Table 4.5 varies C_eq only (s = 1):
  both variances are C_eq's, the ranges cover the box's products.
- Friction phi (F_c, F_s x (1 + phi)): Table 4.5 keeps the friction of Table 3.7, so its
  variance is the box's (log-uniform friction multiplier), not zero: the friction is as
  uncertain as the random family says.
- Sensor error band: the position sensor's Gauss-Markov offset b has sigma_gm (Fig. 4.6);
  at the box's largest noise scale, over ``T_op`` s of operation on every plant of the grid, the
  Gauss-Markov process gives about T_op 2 pi f_c independent samples per plant; the band
  k sigma with k from a two-sided false-alarm probability ``p_fa`` over all of them. The
  offset state is projected to +-(k + 1) sigma_gm (the estimate never stays further from the
  measurement, whatever the model says), and the monitor's DISAGREE band is k sigma_d of its
  low-passed disagreement z - x_hat (b plus the low-passed white noise).
- No dead zone on lambda (tried and removed, issue 44): lambda learning only while a unit
  lambda error moves the piston by at least 2 mm/s (|p_A - p_B| > 9 bar) took the nominal RMSE
  ratio to 0.88, because lambda's variance then never shrinks during light-load motion and its
  column keeps the position uncertain.
- Sensor jump step: a jump moves the reading within one sample; the innovation increment of
  noise alone has sigma sqrt(2) sigma_white (at the largest noise scale); jump_step = k that.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from ..qft.family_box import load_box
from .adapt import lowpass_alpha
from .params import DRIFTING

@dataclass
class Inputs:
    """Family ranges (multipliers), sensor model (SI), choices."""

    family: dict                       # name -> (lo, hi) multipliers of Table 4.5
    box: dict = field(default_factory=load_box)   # config/campaigns/family_random.yaml
    Ts: float = 1e-3
    position_sigma: float = 1e-5       # white noise sigma [m]
    gm_sigma: float = 2e-5             # Gauss-Markov sigma [m]
    gm_corner: float = 1.0             # [Hz]
    n_plants: int = 270
    T_op: float = 60.0                 # [s] of nominal operation without a false alarm
    p_fa: float = 0.01                 # over all plants of the grid
    margin: float = 0.25               # projection range widening, fraction of the span
    rho: float = 0.1                   # fraction of the family spread ...
    T_memory: float = 1.0e4            # ... the adaptive states may move within this [s]
    drifting: tuple = DRIFTING         # the states with a random walk (the others: q = 0)
    monitor_lowpass: float = 5.0       # [Hz]
    jump_k: float = 5.0
    A_p: float = 2.572e-3              # [m^2] piston area
    C_x: float = 2.0e-12               # [m^3/(s Pa)] C_p + C_c (cross-port) of the nominal plant
    C_r: float = 3.6e-12               # [m^3/(s Pa)] C_r (per port) of the nominal plant


def log_uniform_moments(lo: float, hi: float, f=lambda m: m):
    """Mean and variance of f(m) for m log-uniform on [lo, hi] (numerically)."""
    m = np.geomspace(lo, hi, 20001)
    v = f(m)
    return float(np.mean(v)), float(np.var(v))


def correction(name: str, lo: float, hi: float):
    """(f, correction range) of the adaptive state for multiplier range [lo, hi]."""
    f = {'C_eq': lambda m: m - 1.0, 'C_x': lambda m: m - 1.0, 'C_r': lambda m: m - 1.0,
         'D_p': lambda m: m - 1.0, 'friction': lambda m: m - 1.0,
         'beta': lambda m: 1.0 / m - 1.0}[name]
    a, b = f(np.float64(lo)), f(np.float64(hi))
    return f, (min(a, b), max(a, b))


def derive(inp: Inputs) -> dict:
    """The estimator.* values (dotted keys without the 'estimator.' prefix) and a report."""
    out, notes = {}, []
    c_eq0 = inp.C_x + 0.5 * inp.C_r
    split = inp.box.get('leak_split', (1.0, 1.0))[:2]
    k_x = [(c_eq0 - sp * 0.5 * inp.C_r) / inp.C_x for sp in split]     # C_x per C_eq
    box = dict(inp.box)
    box['C_x'] = (inp.box['C_eq'][0] * min(k_x), inp.box['C_eq'][1] * max(k_x))
    box['C_r'] = (inp.box['C_eq'][0] * split[0], inp.box['C_eq'][1] * split[1])
    fam = dict(inp.family, C_x=inp.family['C_eq'], C_r=inp.family['C_eq'],
               friction=inp.box['friction'][:2])
    for name, key in (('C_x', 'leakage'), ('C_r', 'external_leakage'), ('D_p', 'displacement'),
                      ('beta', 'compliance'), ('friction', 'friction')):
        lo = min(fam[name][0], box[name][0])
        hi = max(fam[name][1], box[name][1])
        f, (c_lo, c_hi) = correction(name, lo, hi)
        _, var = log_uniform_moments(*fam[name], f)
        span = c_hi - c_lo
        r_lo = max(c_lo - inp.margin * span, -0.99)
        r_hi = c_hi + inp.margin * span
        q = (inp.rho ** 2) * var * inp.Ts / inp.T_memory if key in inp.drifting else 0.0
        out[f'model.p0_{key}'] = var
        if key in inp.drifting:
            out[f'model.q_{key}'] = q
        out[f'model.{key}_range'] = [r_lo, r_hi]
        notes.append(f'{key}: {name} x{lo:g}..{hi:g} -> correction {c_lo:+.3f}..{c_hi:+.3f}, '
                     f'sigma over Table 4.5 {math.sqrt(var):.4f}; '
                     f'range [{r_lo:+.3f}, {r_hi:+.3f}], '
                     f'q {q:.3g}/step')
    noise = inp.box['noise'][1]
    s_gm, s_w = inp.gm_sigma * noise, inp.position_sigma * noise
    n_ind = inp.T_op * 2.0 * math.pi * inp.gm_corner * inp.n_plants
    k = float(norm.isf(inp.p_fa / (2.0 * n_ind)))
    alpha = lowpass_alpha(inp.monitor_lowpass, inp.Ts)
    s_d = math.sqrt(s_gm ** 2 + s_w ** 2 * alpha / (2.0 - alpha))
    out['model.offset_bound'] = (k + 1.0) * s_gm
    out['monitor.band'] = k * s_d
    out['monitor.lowpass'] = inp.monitor_lowpass
    out['fault.jump_step'] = inp.jump_k * math.sqrt(2.0) * s_w
    notes.append(f'sensor at noise x{noise:g}: sigma_gm {s_gm * 1e6:.1f} um, white '
                 f'{s_w * 1e6:.1f} um; {n_ind:.3g} independent Gauss-Markov samples in '
                 f'{inp.T_op:g} s x {inp.n_plants} plants, p_fa {inp.p_fa:g} -> k = {k:.2f}; '
                 f'offset bound {out["model.offset_bound"] * 1e6:.0f} um, DISAGREE band '
                 f'{out["monitor.band"] * 1e6:.0f} um, jump step '
                 f'{out["fault.jump_step"] * 1e6:.0f} um')
    return {'values': out, 'notes': notes}
