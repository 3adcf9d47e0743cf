"""Estimator tuning derived from the plant family, not tuned at the nominal plant: what
scripts/tune_estimator computes and writes to the TUNED table of core/estimator/params.py (the
one home of these defaults).

Inputs: the Table 4.5 family (config/qft_spec.yaml, family.*) and the robustness box beyond it
(issue 15: config/campaigns/family_random.yaml, C_eq x0.05..15, D_p x0.75..1.05, beta
x0.6..1.5, ...).

- Adaptive states (core.estimator.adapt; state augmentation, Simon 2006 sec. 7.4):
  lambda = C/C_0 - 1, delta = D_p/D_p0 - 1, kappa = beta_0/beta - 1.
  p0 = the variance of the correction over the Table 4.5 family with log-uniform multipliers
  (the prior: a plant is anywhere in the thesis' family; the box's variance, twice as large
  for lambda, measured 0.251 instead of 0.247 worst nominal RMSE ratio); range (projection,
  Simon 2006 sec. 7.5) = the box's correction range widened by ``margin`` of its span on
  each side (plants beyond the family must still be reachable). The drifting ones random-walk
  by p0 Ts / estimator.model.drift_time per step (core.estimator.params.drift_q; Bar-Shalom
  et al. 2001 sec. 6.2: random-walk process noise sized by the change expected over the time
  of interest).
- Leakage paths (issue 15): lambda scales the cross-port C_x = C_p + C_c, epsilon the per-port
  C_r; the box's leak_split s moves leakage between them with C_eq = C_x + C_r/2 kept (eq.
  3.22): C_r x C_eq s, C_x x C_eq (C_eq0 - s C_r0/2)/C_x0. Table 4.5 varies C_eq only (s = 1):
  both variances are C_eq's, the ranges cover the box's products.
- Friction phi (F_c, F_s x (1 + phi)): Table 4.5 keeps the friction of Table 3.7, so its
  variance is the box's (log-uniform friction multiplier), not zero: the friction is as
  uncertain as the random family says.
- No dead zone on lambda (tried and removed, issue 44): lambda learning only while a unit
  lambda error moves the piston by at least 2 mm/s (|p_A - p_B| > 9 bar) took the nominal RMSE
  ratio to 0.88, because lambda's variance then never shrinks during light-load motion and its
  column keeps the position uncertain.
- The sensor's bands (offset bound, DISAGREE band, jump step) are not tuned: they follow from
  plant.sensors at run time (core.estimator.sensor_band).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..qft.family_box import load_box


@dataclass
class Inputs:
    """Family ranges (multipliers), the nominal plant's leakage (SI), choices."""

    family: dict                       # name -> (lo, hi) multipliers of Table 4.5
    box: dict = field(default_factory=load_box)   # config/campaigns/family_random.yaml
    margin: float = 0.25               # projection range widening, fraction of the span
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
        out[f'model.p0_{key}'] = var
        out[f'model.{key}_range'] = [r_lo, r_hi]
        notes.append(f'{key}: {name} x{lo:g}..{hi:g} -> correction {c_lo:+.3f}..{c_hi:+.3f}, '
                     f'sigma over Table 4.5 {math.sqrt(var):.4f}; '
                     f'range [{r_lo:+.3f}, {r_hi:+.3f}]')
    return {'values': out, 'notes': notes}
