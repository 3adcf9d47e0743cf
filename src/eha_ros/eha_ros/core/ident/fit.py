"""Nonlinear least squares with intervals: scipy.optimize.least_squares, the covariance from
its Jacobian at the optimum, and the verdict whether the data determines each parameter.

The covariance is the cluster-robust sandwich (J^T J)^-1 (sum_g J_g^T r_g r_g^T J_g) (J^T J)^-1
over groups g of neighbouring samples (Liang & Zeger 1986): samples of a 1 kHz recording are
not independent (model error and the loop's slow motions make neighbours alike), and the
sandwich does not assume they are; it is never taken below the classical s^2 (J^T J)^-1.
A parameter is *identified* when its 95 % interval's half-width is at most REL_HALF_WIDTH of
its value and its correlation with every other fitted parameter stays below MAX_CORRELATION;
otherwise the data cannot pin it (too little excitation, or it trades off against another).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence

import numpy as np

Z95 = 1.959964              # two-sided 95 % quantile of the normal distribution
REL_HALF_WIDTH = 0.2        # identified: 95 % half-width <= 20 % of |value| ...
MAX_CORRELATION = 0.98      # ... and |rho| with any other fitted parameter below this
GROUP = 250                 # [samples] default cluster: 0.25 s of a 1 kHz recording


@dataclass
class Estimate:
    """One parameter as identification.json reports it (SI units)."""
    value: float
    ci_low: float | None
    ci_high: float | None
    nominal: float
    identified: bool
    note: str = ''

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class Fit:
    """A least-squares solution: parameters x (names), covariance, correlations, residuals."""
    names: list
    x: np.ndarray
    cov: np.ndarray
    residual_rms: float
    n: int
    inflation: float            # robust / classical variance, mean over the parameters
    at_bound: list              # names of parameters the solution left on a bound
    nfev: int
    wall_s: float
    corr: np.ndarray = field(init=False)

    def __post_init__(self):
        sd = np.sqrt(np.clip(np.diag(self.cov), 0.0, None))
        with np.errstate(invalid='ignore', divide='ignore'):
            self.corr = self.cov / np.outer(sd, sd)
        self.corr[~np.isfinite(self.corr)] = 0.0

    @property
    def sd(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    def estimate(self, name: str, nominal: float, scale: float = 1.0, note: str = '',
                 floor: float = 0.0) -> Estimate:
        """Parameter ``name`` times ``scale`` (a multiplier fit's unit) with its 95 % interval
        and the identification verdict of the module docstring; ``floor``: a relative half-width
        of known model error added in quadrature."""
        i = self.names.index(name)
        value = self.x[i] * scale
        half = math.hypot(Z95 * self.sd[i] * abs(scale), floor * value)
        others = [abs(self.corr[i, j]) for j in range(len(self.names)) if j != i]
        rho = max(others, default=0.0)
        ok = math.isfinite(half) and half <= REL_HALF_WIDTH * abs(value) and \
            rho < MAX_CORRELATION and not self.at_bound
        why = note
        if self.at_bound:
            why = (f'not determined by the data: the fit ended on the bound of '
                   f'{", ".join(self.at_bound)} (the interval assumes a free optimum)')
        elif not ok:
            why = (f'95 % half-width {half / abs(value) * 100:.0f} % of the value'
                   if abs(value) > 0 else 'value zero') if rho < MAX_CORRELATION else \
                f'correlation {rho:.3f} with another fitted parameter'
            why = f'not determined by the data: {why}' + (f'; {note}' if note else '')
        return Estimate(float(value), float(value - half), float(value + half), float(nominal),
                        bool(ok), why)

    def summary(self) -> dict:
        """JSON-ready: the fit's figures and the correlation matrix by name."""
        return {'parameters': list(self.names), 'x': self.x.tolist(),
                'sd': self.sd.tolist(), 'correlation': self.corr.round(4).tolist(),
                'residual_rms': self.residual_rms, 'samples': self.n,
                'variance_inflation': self.inflation, 'at_bound': self.at_bound,
                'evaluations': self.nfev,
                'wall_s': self.wall_s}


def least_squares_fit(residual: Callable[[np.ndarray], np.ndarray], x0: Sequence[float],
                      names: Sequence[str], lower: Sequence[float], upper: Sequence[float],
                      groups: np.ndarray | None = None, max_nfev: int = 400) -> Fit:
    """Minimise sum residual(x)^2 within bounds (trust-region reflective, 2-point Jacobian);
    x is best scaled near 1 (multipliers of nominal values). ``groups``: the cluster of each
    residual (default: runs of GROUP samples); ``max_nfev``: evaluations at most (a rough
    first solution)."""
    from scipy.optimize import least_squares
    t0 = time.perf_counter()
    res = least_squares(residual, np.asarray(x0, float), bounds=(lower, upper), method='trf',
                        x_scale='jac', xtol=1e-8, ftol=1e-9, gtol=1e-9, max_nfev=max_nfev)
    J, r = res.jac, res.fun
    n, p = len(r), len(res.x)
    if groups is None:
        groups = np.arange(n) // GROUP
    cov, inflation = covariance(J, r, groups)
    evaluations = res.nfev + (res.njev or 0) * p        # the 2-point Jacobian's too
    bound = [nm for nm, a in zip(names, res.active_mask) if a != 0]
    return Fit(list(names), res.x.copy(), cov, math.sqrt(float(r @ r) / n), n, inflation,
               bound, evaluations, time.perf_counter() - t0)


def covariance(J: np.ndarray, r: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, float]:
    """Cluster-robust covariance of the module docstring, each variance at least the classical
    one; and the inflation, the mean ratio of the two variances (>= 1)."""
    n, p = J.shape
    inv = _inverse(J)
    classical = inv * (float(r @ r) / max(n - p, 1))
    g = np.unique(groups, return_inverse=True)[1]
    scores = np.zeros((g.max() + 1, p))
    np.add.at(scores, g, J * r[:, None])
    ok = np.isfinite(np.diag(inv)) & (np.diag(classical) > 0)
    if not ok.any():
        return classical, 1.0
    sub = np.ix_(ok, ok)
    robust = inv[sub] @ (scores[:, ok].T @ scores[:, ok]) @ inv[sub]
    ratio = np.diag(robust) / np.diag(classical[sub])
    k = np.sqrt(np.maximum(1.0, 1.0 / np.maximum(ratio, 1e-300)))
    cov = classical.copy()
    cov[sub] = robust * np.outer(k, k)
    return cov, float(np.mean(np.maximum(ratio, 1.0)))


def _inverse(J: np.ndarray) -> np.ndarray:
    """(J^T J)^-1 through the SVD of the column-scaled Jacobian; a parameter in a direction the
    residuals do not see (singular value below 1e-9 of the largest) gets infinite variance."""
    norm = np.linalg.norm(J, axis=0)
    safe = np.where(norm > 0.0, norm, 1.0)
    _, s, vt = np.linalg.svd(J / safe, full_matrices=False)
    keep = s > 1e-9 * s[0] if s.size and s[0] > 0 else np.zeros(len(s), bool)
    cov = (vt[keep].T / s[keep] ** 2) @ vt[keep] / np.outer(safe, safe)
    blind = (norm == 0.0) | np.any(np.abs(vt[~keep]) > 0.1, axis=0)
    cov[blind, :] = cov[:, blind] = 0.0
    cov[blind, blind] = np.inf
    return cov
