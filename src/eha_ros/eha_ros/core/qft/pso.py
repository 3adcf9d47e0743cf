"""Particle swarm optimisation, eqs. 4.66-4.67 and Table 4.8 (seeded, vectorised cost).

V <- W V + C1 r1 (X_personal_best - X) + C2 r2 (X_global_best - X);  X <- X + V.
Deviation (stated): W = 0.9 with C1 = C2 = 2 diverges without a limit, so the velocity is
clamped to v_max_frac of each parameter range and positions are clipped to the bounds.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np


@dataclass
class PsoResult:
    x: np.ndarray
    cost: float
    history: list = field(default_factory=list)       # best cost per iteration
    mean_x: list = field(default_factory=list)        # swarm mean per iteration


def pso(cost: Callable[[np.ndarray], np.ndarray], lo, hi, particles=49, iterations=50,
        W=0.9, C1=2.0, C2=2.0, v_max_frac=0.2, seed=0, progress=None) -> PsoResult:
    """Minimise cost(X) -> (P,) over the box [lo, hi]; X is (P, D). progress(k, best) per
    iteration (k = 0 is the initial swarm)."""
    rng = np.random.default_rng(seed)
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    D = len(lo)
    vmax = v_max_frac * (hi - lo)
    X = lo + rng.random((particles, D)) * (hi - lo)
    V = (rng.random((particles, D)) * 2 - 1) * vmax
    f = np.asarray(cost(X), float)
    pbest, pcost = X.copy(), f.copy()
    g = int(np.argmin(pcost))
    res = PsoResult(pbest[g].copy(), float(pcost[g]), [float(pcost[g])], [X.mean(0)])
    if progress:
        progress(0, res.cost)
    for k in range(1, iterations + 1):
        r1 = rng.random((particles, D))
        r2 = rng.random((particles, D))
        V = W * V + C1 * r1 * (pbest - X) + C2 * r2 * (pbest[g] - X)
        V = np.clip(V, -vmax, vmax)
        X = np.clip(X + V, lo, hi)
        f = np.asarray(cost(X), float)
        better = f < pcost
        pbest[better] = X[better]
        pcost[better] = f[better]
        g = int(np.argmin(pcost))
        res.x, res.cost = pbest[g].copy(), float(pcost[g])
        res.history.append(res.cost)
        res.mean_x.append(X.mean(0))
        if progress:
            progress(k, res.cost)
    return res


def de_crosscheck(cost, lo, hi, seed=0, maxiter=30, popsize=10):
    """scipy differential_evolution on the same (vectorised) cost, for cross-checking PSO."""
    from scipy.optimize import differential_evolution
    r = differential_evolution(lambda xs: np.asarray(cost(np.atleast_2d(xs.T)), float),
                               list(zip(lo, hi)), seed=seed, maxiter=maxiter, popsize=popsize,
                               polish=False, vectorized=True, updating='deferred', tol=0.0)
    return np.asarray(r.x), float(r.fun), int(r.nfev)
