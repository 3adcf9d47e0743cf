"""Minimax refinement of the position controller on the dense verification grid (SLSQP, epigraph).

The PSO cost (eq. 4.75 + 4.70) scores bound violations at the design frequencies only; the
report judges every plant on the dense grid. This local step starts at the PSO best and
minimises t subject to: every spec excess in dB <= t on the dense grid, over the whole family
(max|T| - W_s, eq. 4.51; |P_d S| - |M| up to the band edge or the highest stiffness frequency,
4.59/4.60; |S| - |S spec| up to the band edge, 4.57; tracking spread max|T|/min|T| - |T_up|/|T_low|
up to prefilter.w_max, 4.61; the signed distance of L0 to the merged bounds at the design
frequencies, so the report's bound check passes too) and every closed-loop eigenvalue (Pade
delay) left of -zp_min/2.
t < 0 is the margin by which the worst spec is met."""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from . import bounds as qb
from .family import CascadePlants
from .freqresp import feedback, max_real_eig
from .verify import dense_grid, family_worst


class DenseExcess:
    """Worst excess over the family, in dB, of each position-loop spec per grid frequency."""

    def __init__(self, casc: CascadePlants, spec, bset: qb.BoundSet | None = None):
        self.b = bset
        self.P0b = None if bset is None else casc.P_omega(bset.w)[-1]
        w = dense_grid(spec)
        band = 2 * np.pi * spec['verify.band_max_hz']
        self.w = w
        self.st = w <= max(band, max(spec['position.stiff_freqs']))
        self.se = w <= band
        self.tr = (w >= min(spec['position.track_freqs'])) & (w <= spec['prefilter.w_max'])
        self.Pw, self.Pd = casc.P_omega(w), casc.P_d(w)
        self.M = np.abs(spec.M(w))
        self.Sspec = np.abs(spec.S_p(w))
        allowed = qb.db(np.abs(spec.T_up(w)) / np.abs(spec.T_low(w)))
        self.allowed = allowed + 2 * spec['position.track_tol_db']
        self.Ws = spec['position.Ws']
        self.Ae, self.Be, self.Cx = casc.delayed_ss()

    def parts(self, G) -> dict:
        f = family_worst(self.Pw, self.Pd, G.freq(self.w))
        out = {
            'Ws': qb.db(f['T_max'] / self.Ws),
            'stiffness': qb.db(f['PdS_max'] / self.M)[self.st],
            'sensitivity': qb.db(f['S_max'] / self.Sspec)[self.se],
            'tracking': (qb.db(f['T_max'] / f['T_min']) - self.allowed)[self.tr],
        }
        if self.b is not None:
            out['bounds'] = qb.margin_db(self.b.merged, self.P0b * G.freq(self.b.w))
        return out

    def __call__(self, G) -> np.ndarray:
        return np.concatenate(list(self.parts(G).values()))

    def max_real(self, G) -> float:
        return float(max_real_eig(feedback(self.Ae, self.Be, self.Cx, G.ss())[0]).max())


def refine(ctrl, x0, lo, hi, excess: DenseExcess, eig_max: float, maxiter=200, progress=None):
    """SLSQP on (x, t): min t, excess(ctrl(x)) <= t, max Re eig <= eig_max, lo <= x <= hi.
    Returns (x, worst excess dB); never a point worse than x0 or with a slower/unstable loop.
    progress(k, t) after each SLSQP iteration."""
    x0 = np.clip(np.asarray(x0, float), lo, hi)
    e0 = float(excess(ctrl(x0)).max())
    r = minimize(lambda v: v[-1], np.r_[x0, e0], method='SLSQP',
                 bounds=list(zip(np.r_[lo, -100.0], np.r_[hi, 100.0])),
                 constraints=[{'type': 'ineq', 'fun': lambda v: v[-1] - excess(ctrl(v[:-1]))},
                              {'type': 'ineq', 'fun': lambda v: eig_max - excess.max_real(ctrl(v[:-1]))}],
                 options=dict(maxiter=maxiter, ftol=1e-7),
                 callback=None if progress is None else _counter(progress))
    x = np.clip(r.x[:-1], lo, hi)
    e = float(excess(ctrl(x)).max())
    if e < e0 and excess.max_real(ctrl(x)) <= eig_max:
        return x, e
    return x0, e0


def _counter(progress):
    k = [0]

    def cb(v):
        k[0] += 1
        progress(k[0], float(v[-1]))
    return cb
