"""Prefilter F(s) = (s/a + 1)/((s/b + 1)(s/c + 1)) (eq. 4.77 structure) so that
T_low <= |F T_r| <= T_up on every plant (eq. 4.61) on a dense grid, with the nominal -3 dB
bandwidth >= the spec and (given the discrete closed-loop step responses) the step overshoot
and 2 % settling time within the spec on every plant; tuned by a seeded differential evolution
on log10 [a, b, c]."""
from __future__ import annotations

import numpy as np

from . import bounds as qb
from ..controller.lti import prefilter


def band_grid(spec, n=200):
    return np.logspace(np.log10(min(spec['position.track_freqs'])),
                       np.log10(spec['prefilter.w_max']), n)


def bandwidth(H, w):
    """-3 dB bandwidth (rad/s) of each row of |H| (DC gain 1): first crossing of 1/sqrt 2,
    log-interpolated; inf if none on the grid."""
    m = qb.db(np.abs(np.atleast_2d(H))) + 3.0103
    out = np.full(m.shape[0], np.inf)
    for i, row in enumerate(m):
        k = np.nonzero(row < 0)[0]
        if len(k) and k[0] > 0:
            j = k[0]
            t = row[j - 1] / (row[j - 1] - row[j])
            out[i] = 10 ** (np.log10(w[j - 1]) + t * (np.log10(w[j]) - np.log10(w[j - 1])))
        elif len(k):
            out[i] = w[0]
    return out


def tracking_margin_db(F_resp, T, spec, w):
    """Worst distance (dB, > 0 inside) of |F T_r| from the band [T_low, T_up] (+ tolerance)."""
    tol = spec['position.track_tol_db']
    m = qb.db(np.abs(F_resp[None] * T))
    up = qb.db(np.abs(spec.T_up(w))) + tol - m
    low = m - qb.db(np.abs(spec.T_low(w))) + tol
    return float(np.minimum(up, low).min())


def step_metrics(y, Ts, band=0.02):
    """Overshoot (%) and settling time (s, inf if not settled within the record) of unit-step
    responses y (P, K) sampled at t = k Ts (final value 1)."""
    y = np.atleast_2d(y)
    os_pct = 100.0 * np.maximum(0.0, y.max(axis=1) - 1.0)
    out = np.abs(y - 1.0) > band
    last = np.where(out.any(axis=1), y.shape[1] - 1 - np.argmax(out[:, ::-1], axis=1), -1)
    ts = (last + 1) * Ts
    ts = np.where(last >= y.shape[1] - 1, np.inf, ts)
    return os_pct, ts


def filtered_steps(F, y_T, Ts, prewarp_w=0.0):
    """Step responses of F T from the closed-loop step responses y_T (P, K): the Tustin F (shared
    controller/discrete.py) filters them (SISO LTI systems commute)."""
    from scipy.signal import lfilter, ss2tf
    from ..controller.discrete import tustin
    Ad, Bd, Cd, Dd = tustin(*F.ss(), Ts, prewarp_w or None)
    b, a = ss2tf(Ad, Bd, Cd, Dd)
    return lfilter(b[0], a, y_T, axis=-1)


def step_penalty(y, spec):
    """Relative excess of the worst overshoot and settling time over the spec (0 if met)."""
    os_pct, ts = step_metrics(y, spec['digital.Ts'], spec['digital.settling_band'])
    ts = np.minimum(ts, spec['digital.horizon'])
    return max(0.0, os_pct.max() - spec['digital.overshoot_max_pct']) / \
        max(spec['digital.overshoot_max_pct'], 1.0) + \
        max(0.0, ts.max() - spec['digital.settling_max']) / spec['digital.settling_max']


def design_prefilter(spec, T_family, T_nominal_fine, w_fine, seed=0, maxiter=60, y_T=None):
    """T_family: closed loops G P/(1 + G P) of all plants on band_grid(spec); nominal closed
    loop on w_fine for the bandwidth; y_T: discrete closed-loop unit-step responses (P, K) of
    the plants (optional: adds the step overshoot/settling excess to the objective).
    Returns (Zpk, info dict)."""
    from scipy.optimize import differential_evolution
    w = band_grid(spec, T_family.shape[1])
    bw_min = 2 * np.pi * spec['prefilter.bandwidth_min_hz']
    lo, hi = np.log10(spec['prefilter.corner_min']), np.log10(spec['prefilter.corner_max'])

    def cost(x):
        F = prefilter(*(10 ** x))
        marg = tracking_margin_db(F.freq(w), T_family, spec, w)
        bw = bandwidth(F.freq(w_fine) * T_nominal_fine, w_fine)[0]
        short = max(0.0, np.log10(bw_min) - np.log10(bw))
        J = -min(marg, 1.0) + 100.0 * max(0.0, -marg) + 100.0 * short
        if y_T is not None:
            J += 10.0 * step_penalty(filtered_steps(F, y_T, spec['digital.Ts'],
                                                    spec['digital.prewarp_w']), spec)
        return J

    r = differential_evolution(cost, [(lo, hi)] * 3, seed=seed, maxiter=maxiter, popsize=12,
                               polish=True, tol=1e-8)
    F = prefilter(*(10 ** r.x))
    marg = tracking_margin_db(F.freq(w), T_family, spec, w)
    bw = bandwidth(F.freq(w_fine) * T_nominal_fine, w_fine)[0]
    info = dict(margin_db=marg, bandwidth_nominal_hz=bw / (2 * np.pi),
                corners=[float(v) for v in 10 ** r.x], cost=float(r.fun))
    if y_T is not None:
        os_pct, ts = step_metrics(filtered_steps(F, y_T, spec['digital.Ts'],
                                                 spec['digital.prewarp_w']),
                                  spec['digital.Ts'], spec['digital.settling_band'])
        info.update(step_overshoot_worst_pct=float(os_pct.max()), step_settling_worst_s=float(ts.max()))
    return F, info
