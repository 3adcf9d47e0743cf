"""QFT bounds on the nominal open loop L0 = P0 G (Table 4.7, eqs. 4.56, 4.64 and analogues).

Reparametrisation: the thesis grids the controller phase phi in -360:5:0 and plots at
psi0 = phi + theta0; here the grid is put directly on the phase of L0 (psi in -360:5:0), the
same bound shifted by theta0, so every frequency shares one Nichols phase axis. For a plant
r the template point is q_r = P_r/P0 = p e^{j theta}, and L_r = l p e^{j(psi + theta)}.

Each spec gives, per (frequency, phase, plant), a quadratic a l^2 + b l + c >= 0 (a > 0):
- robust stability |L/(1+L)| <= W (4.51/4.52): a = p^2 (1 - 1/W^2), b = 2 p cos, c = 1
- sensitivity |1/(1+L)| <= delta (4.57/4.58, 4.64): a = p^2, b = 2 p cos, c = 1 - 1/delta^2
- stiffness |P_d/(1+L)| <= |M| (4.59/4.60): sensitivity form with delta_r = |M|/|P_d,r|
and tracking (4.61-4.63) is the classical spread bound max_r|T_r| / min_r|T_r| <= |T_up|/|T_low|,
found on a gain grid and refined by bisection. A bound is a lower gain (L0 above) and/or a
forbidden gain interval (L0 outside); merging takes the largest lower bound and the hull of
the forbidden intervals over plants and specs (conservative).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..config.cli import UsageError

DB = 20.0


def db(x):
    with np.errstate(divide='ignore', invalid='ignore'):
        return DB * np.log10(x)


@dataclass
class Bound:
    """Bound of one spec (or merged) on L0: arrays (F, K) of linear gains.

    lo: L0 magnitude must be >= lo (0: none; inf: cannot be met).
    fb_lo, fb_hi: L0 magnitude must not lie in (fb_lo, fb_hi) (nan: none).
    """

    w: np.ndarray
    phase_deg: np.ndarray
    lo: np.ndarray
    fb_lo: np.ndarray
    fb_hi: np.ndarray
    names: tuple = ()

    def merged_with(self, other: 'Bound') -> 'Bound':
        return merge([self, other])


@dataclass
class BoundSet:
    """Per-spec bounds at the design frequencies and their merge (what the PSO cost uses)."""

    w: np.ndarray
    phase_deg: np.ndarray
    specs: dict = field(default_factory=dict)     # name -> Bound on the full w axis
    merged: Bound | None = None


def phase_grid(step_deg: float) -> np.ndarray:
    n = int(round(360.0 / step_deg))
    return np.linspace(-360.0, 0.0, n + 1)


def _quadratic(a, b, c):
    """Solutions of a l^2 + b l + c >= 0, a > 0 -> (lo, fb_lo, fb_hi) arrays."""
    disc = b * b - 4 * a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    r1 = (-b - sq) / (2 * a)
    r2 = (-b + sq) / (2 * a)
    has = disc > 0
    lower = has & (r1 <= 0) & (r2 > 0)
    forbid = has & (r1 > 0)
    lo = np.where(lower, r2, 0.0)
    fb_lo = np.where(forbid, r1, np.nan)
    fb_hi = np.where(forbid, r2, np.nan)
    return lo, fb_lo, fb_hi


def _reduce_plants(lo, fb_lo, fb_hi, axis=-1):
    """Most restrictive over plants: max lower bound, hull of the forbidden intervals."""
    fl = np.min(np.where(np.isnan(fb_lo), np.inf, fb_lo), axis=axis)
    fh = np.max(np.where(np.isnan(fb_hi), -np.inf, fb_hi), axis=axis)
    return (np.max(lo, axis=axis), np.where(np.isinf(fl), np.nan, fl),
            np.where(np.isinf(fh), np.nan, fh))


def _nanhull(a, b, fn):
    both = np.stack([a, b])
    out = fn(np.where(np.isnan(both), np.inf if fn is np.min else -np.inf, both), axis=0)
    return np.where(np.isinf(out), np.nan, out)


def merge(bounds) -> Bound:
    """Most restrictive combination of bounds given on the same (w, phase) axes."""
    b0 = bounds[0]
    lo = b0.lo.copy()
    fl, fh = b0.fb_lo.copy(), b0.fb_hi.copy()
    names = tuple(b0.names)
    for b in bounds[1:]:
        lo = np.maximum(lo, b.lo)
        fl = _nanhull(fl, b.fb_lo, np.min)
        fh = _nanhull(fh, b.fb_hi, np.max)
        names += tuple(b.names)
    # a lower bound inside a forbidden interval moves to its top; an interval below lo vanishes
    inside = ~np.isnan(fl) & (lo > fl)
    lo = np.where(inside & (lo < fh), fh, lo)
    fl = np.where(inside, np.nan, fl)
    fh = np.where(inside, np.nan, fh)
    return Bound(b0.w, b0.phase_deg, lo, fl, fh, names)


def quad_bound(name, w, phase_deg, q, kind, level) -> Bound:
    """Stability ('stab', level = W) or sensitivity-type ('sens', level = delta, shape (N, F)
    or (F,)) bound from template ratios q = P_r/P0, shape (N, F). Vectorised over
    (F, K, N)."""
    p = np.abs(q).T[:, None, :]                                  # (F, 1, N)
    th = np.angle(q).T[:, None, :]
    psi = np.deg2rad(phase_deg)[None, :, None]                   # (1, K, 1)
    cos = np.cos(psi + th)
    if kind == 'stab':
        a = p * p * (1 - 1 / level ** 2)
        c = np.ones_like(a)
    else:
        d = np.broadcast_to(np.asarray(level, float).T if np.ndim(level) == 2 else
                            np.asarray(level, float)[:, None], (q.shape[1], q.shape[0]))
        a = p * p
        c = 1 - 1 / d[:, None, :] ** 2
        a, c = np.broadcast_arrays(a, c)
    lo, fl, fh = _quadratic(a, 2 * p * cos, c)
    lo, fl, fh = _reduce_plants(lo, fl, fh)
    return merge([Bound(np.asarray(w), phase_deg, lo, fl, fh, (name,))])


def _spread_db(l, psi, p, th):
    """Spread max_r |T_r| / min_r |T_r| in dB; l, psi (..., 1), p, th (..., N)."""
    L = l * p * np.exp(1j * (psi + th))
    T = np.abs(L / (1 + L))
    return db(np.max(T, axis=-1) / np.min(T, axis=-1))


def tracking_bound(name, w, phase_deg, q, allowed_db, lgrid_db=(-80.0, 200.0, 4.0),
                   refine=14) -> Bound:
    """Tracking spread bound (4.61-4.63): violating L0 gains on a grid -> lower bound (if the
    lowest grid gain violates) or forbidden interval between the lowest and highest violating
    gains; both edges refined by bisection. allowed_db (F,) = 20 log(|T_up|/|T_low|)."""
    lg = 10 ** (np.arange(lgrid_db[0], lgrid_db[1] + 1e-9, lgrid_db[2]) / DB)
    F, K = len(w), len(phase_deg)
    lo = np.zeros((F, K))
    fl = np.full((F, K), np.nan)
    fh = np.full((F, K), np.nan)
    psi = np.deg2rad(phase_deg)
    for f in range(F):
        if allowed_db[f] <= 0:
            lo[f] = np.inf
            continue
        p = np.abs(q[:, f])
        th = np.angle(q[:, f])
        L = lg[None, :, None] * p * np.exp(1j * (psi[:, None, None] + th))   # (K, G, N)
        T = np.abs(L / (1 + L))
        spread = db(np.max(T, -1) / np.min(T, -1))                          # (K, G)
        bad = spread > allowed_db[f]
        anyb = bad.any(axis=1)
        idx = np.arange(len(lg))
        vmax = np.where(bad, idx, -1).max(axis=1)
        vmin = np.where(bad, idx, len(lg)).min(axis=1)

        def bisect(lo_i, hi_i, bad_low):
            """Edge between grid lo_i and hi_i (bad at the low end if bad_low)."""
            a = np.log(lg[np.clip(lo_i, 0, len(lg) - 1)])
            b = np.log(lg[np.clip(hi_i, 0, len(lg) - 1)])
            for _ in range(refine):
                m = 0.5 * (a + b)
                s = _spread_db(np.exp(m)[:, None], psi[:, None], p[None, :], th[None, :])
                isbad = s > allowed_db[f]
                go_up = isbad if bad_low else ~isbad
                a = np.where(go_up, m, a)
                b = np.where(go_up, b, m)
            return np.exp(0.5 * (a + b))

        top = vmax >= len(lg) - 1
        upper_edge = bisect(vmax, vmax + 1, True)
        lower_edge = bisect(vmin - 1, vmin, False)
        as_lower = anyb & (vmin == 0)
        as_forbid = anyb & (vmin > 0)
        lo[f] = np.where(as_lower, np.where(top, np.inf, upper_edge), 0.0)
        fl[f] = np.where(as_forbid, lower_edge, np.nan)
        fh[f] = np.where(as_forbid, np.where(top, np.inf, upper_edge), np.nan)
        # a forbidden interval reaching the grid top is a lower bound that cannot be met
        lo[f] = np.where(as_forbid & top, np.inf, lo[f])
    return merge([Bound(np.asarray(w), phase_deg, lo, fl, fh, (name,))])


def _on_axis(b: Bound, w_all) -> Bound:
    """Embed a bound given on a subset of frequencies into the full design axis."""
    F, K = len(w_all), len(b.phase_deg)
    lo = np.zeros((F, K))
    fl = np.full((F, K), np.nan)
    fh = np.full((F, K), np.nan)
    for i, wi in enumerate(b.w):
        j = int(np.argmin(np.abs(w_all - wi)))
        lo[j], fl[j], fh[j] = b.lo[i], b.fb_lo[i], b.fb_hi[i]
    return Bound(np.asarray(w_all), b.phase_deg, lo, fl, fh, b.names)


def velocity_bounds(spec, P_iw_fn) -> BoundSet:
    """Velocity-loop bounds (4.52, 4.58) for L_v0 = G_v P_iw,0. P_iw_fn(w) -> (N+1, F),
    nominal last."""
    w = spec.velocity_freqs
    ph = phase_grid(spec['bounds.phase_step_deg'])
    P = P_iw_fn(w)
    q = P[:-1] / P[-1]
    bs = BoundSet(w, ph)
    bs.specs['stability'] = quad_bound('stability', w, ph, q, 'stab', spec['velocity.Ws'])
    bs.specs['sensitivity'] = quad_bound('sensitivity', w, ph, q, 'sens',
                                         np.abs(spec.S_v(w)))
    bs.merged = merge(list(bs.specs.values()))
    return bs


def position_bounds(spec, P_omega, P_d, w=None) -> BoundSet:
    """Position-loop bounds (4.51, 4.57, 4.59, 4.61) for L0 = G P_omega,0.

    P_omega, P_d: functions w -> (N+1, F) (nominal last) or precomputed on w."""
    w = spec.position_freqs if w is None else w
    ph = phase_grid(spec['bounds.phase_step_deg'])
    Pw = P_omega(w) if callable(P_omega) else P_omega
    Pd = P_d(w) if callable(P_d) else P_d
    q = Pw[:-1] / Pw[-1]
    bs = BoundSet(w, ph)

    def sub(key):
        f = np.asarray(spec[key], float)
        idx = np.array([int(np.argmin(np.abs(w - v))) for v in f])
        return idx

    i = sub('position.stab_freqs')
    bs.specs['stability'] = _on_axis(quad_bound('stability', w[i], ph, q[:, i], 'stab',
                                                spec['position.Ws']), w)
    i = sub('position.sens_freqs')
    bs.specs['sensitivity'] = _on_axis(quad_bound('sensitivity', w[i], ph, q[:, i], 'sens',
                                                  np.abs(spec.S_p(w[i]))), w)
    i = sub('position.stiff_freqs')
    delta = np.abs(spec.M(w[i]))[None, :] / np.abs(Pd[:-1, i])
    bs.specs['stiffness'] = _on_axis(quad_bound('stiffness', w[i], ph, q[:, i], 'sens', delta), w)
    i = sub('position.track_freqs')
    allowed = db(np.abs(spec.T_up(w[i])) / np.abs(spec.T_low(w[i])))
    allowed = np.where(allowed > 0, allowed + 2 * spec['position.track_tol_db'], allowed)
    bs.specs['tracking'] = _on_axis(tracking_bound('tracking', w[i], ph, q[:, i], allowed), w)
    bs.merged = merge(list(bs.specs.values()))
    return bs


def check_feasible(bs: BoundSet, spec=None, loop='position'):
    """Raise UsageError naming the first frequency where no L0 gain at any phase satisfies the
    merged bound (lower bound infinite at every phase)."""
    m = bs.merged
    for f, wf in enumerate(bs.w):
        if np.all(np.isinf(m.lo[f])):
            bad = [n for n, b in bs.specs.items() if np.all(np.isinf(b.lo[f]))]
            names = bad or list(bs.specs)
            detail = []
            if 'tracking' in bad and spec is not None:
                a = float(db(np.abs(spec.T_up(wf)) / np.abs(spec.T_low(wf))))
                if a <= 0:
                    detail.append(f'tracking: |T_up|/|T_low| = {a:.2f} dB <= 0, T_up below T_low')
                else:
                    detail.append(f'tracking: no loop gain up to 200 dB meets the allowed spread '
                                  f'{a:.3g} dB')
            for n in bad:
                if n != 'tracking':
                    detail.append(f'{n}: no finite loop gain meets it')
            raise UsageError(f'infeasible specification at {wf:g} rad/s: {" and ".join(names)} '
                             f'cannot be met together ({loop} loop; '
                             f'{"; ".join(detail) or "empty merged bound at every phase"})')


def phase_resolution_db(b: Bound) -> np.ndarray:
    """Worst change of the bound gain between adjacent phase-grid points, dB, per frequency
    (lower bound and forbidden-interval edges; infinite/none entries ignored)."""
    out = np.zeros(len(b.w))
    for arr in (b.lo, b.fb_lo, b.fb_hi):
        with np.errstate(invalid='ignore'):
            d = db(arr)
            diff = np.abs(np.diff(d, axis=1))
        diff = np.where(np.isfinite(diff), diff, 0.0)
        out = np.maximum(out, diff.max(axis=1))
    return out


def lookup(b: Bound, L0: np.ndarray):
    """Conservative bound at the phase of L0 (F,) or (P, F): max of the two neighbouring
    grid lower bounds, hull of their forbidden intervals. Returns (lo, fb_lo, fb_hi)."""
    ph = np.rad2deg(np.angle(L0))
    ph = np.where(ph > 0, ph - 360.0, ph)                        # (-360, 0]
    step = b.phase_deg[1] - b.phase_deg[0]
    k = np.clip(np.floor((ph - b.phase_deg[0]) / step).astype(int), 0, len(b.phase_deg) - 2)
    fi = np.broadcast_to(np.arange(len(b.w)), L0.shape)
    lo = np.maximum(b.lo[fi, k], b.lo[fi, k + 1])
    fl = _nanhull(b.fb_lo[fi, k], b.fb_lo[fi, k + 1], np.min)
    fh = _nanhull(b.fb_hi[fi, k], b.fb_hi[fi, k + 1], np.max)
    return lo, fl, fh


def violation_db(b: Bound, L0: np.ndarray) -> np.ndarray:
    """Bound violation of L0 at each design frequency in dB (0 = satisfied)."""
    lo, fl, fh = lookup(b, L0)
    m = db(np.abs(L0))
    with np.errstate(invalid='ignore'):
        v = np.maximum(0.0, db(lo) - m)
        v = np.where(np.isinf(lo), 1e3, v)
        inside = (m > db(fl)) & (m < db(fh))
        v = v + np.where(inside, np.minimum(m - db(fl), db(fh) - m), 0.0)
    return np.nan_to_num(v, nan=0.0)


def margin_db(b: Bound, L0: np.ndarray) -> np.ndarray:
    """Signed distance of L0 to its bound at each design frequency in dB: > 0 violation (as
    violation_db), < 0 slack to the nearest bound edge; -100 where no bound applies."""
    lo, fl, fh = lookup(b, L0)
    m = db(np.abs(L0))
    with np.errstate(invalid='ignore', divide='ignore'):
        low = np.where(lo > 0, np.where(np.isinf(lo), 1e3, db(lo) - m), -100.0)
        d_lo, d_hi = m - db(fl), db(fh) - m
        inside = (d_lo > 0) & (d_hi > 0)
        fb = np.where(inside, np.minimum(d_lo, d_hi), -np.minimum(np.abs(d_lo), np.abs(d_hi)))
        fb = np.where(np.isnan(fl), -100.0, fb)
    return np.maximum(low, fb)
