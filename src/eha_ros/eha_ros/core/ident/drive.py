"""Drive identification, thesis sec. 3.6.1 (Fig. 3.36): the plant's own velocity PI, current PI,
motor and shaft (eq. 4.71, 3.34, 3.13-3.14, 3.17) replayed with the recorded speed references.

The replay runs the plant's kernels (integrator.channel: drive and motor of one couple;
integrator.shaft: eq. 3.17 solved for the new speed; drive.delay_push: the delay FIFO) with
the measured load pressure p_A - p_B as the pump's reaction torque, so the drive is fitted
apart from the hydraulics. What the data determines: the speed response fixes Kp_w and Ki_w
(given J_eq: the torque the PI asks for is Kp_w e + Ki_w int e, whatever k_T), the measured
current fixes k_T (i = torque / k_T), and the delay is profiled over whole ticks (a command
answering state k reaches the drive at k + 1 + delay ticks). J_eq, b_eq, the current loop and
the low-pass keep their nominal values (the datasheet's; they trade off against the gains).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from ..plant import layout as L
from ..plant.drive import delay_push
from ..plant.integrator import channel as couple
from ..plant.integrator import shaft
from ..plant.parameters import PlantParams, leakage_table, pack
from .fit import GROUP, Estimate, least_squares_fit

SETTLE = 0.3            # [s] left out at the start: the replay's drive states start at rest
SMOOTH = 15             # [ticks] Savitzky-Golay window (cubic) on the measured p_A - p_B: the
                        # pressure sensors' noise would otherwise be a torque the replay's PI
                        # answers with current (passes the sweep's 15 Hz and its harmonics)
MAX_DELAY = 12          # [ticks] delays tried
FITTED = ('Kp_w', 'Ki_w', 'k_T')
CHI2_95 = 3.841         # one degree of freedom: the delay's profile interval
MODEL_ERROR = {'Kp_w': 0.005, 'Ki_w': 0.015, 'k_T': 0.005}
                        # relative half-widths added to the intervals: the replay sees p_A - p_B
                        # only at the ticks (smoothed); on the plant's own recordings that leaves
                        # biases of 0.1-0.4 % on Kp_w and k_T and 0 to -1.3 % on Ki_w (twelve
                        # plants, docs/identification.md)


@njit(cache=True)
def replay(P, T, c, w_ref, p_d, w0, delay, nsub, w_out, i_out):
    """Couple c's drive, motor and shaft over the ticks of w_ref (command of tick k applied
    from k + 1, through ``delay`` ticks of FIFO), the load pressure p_d per tick interpolated
    over the sub-steps; writes the speed and current at each tick into w_out, i_out."""
    S = np.zeros(L.NSTATE)
    U = np.zeros(L.NIN)
    b = L.S_CH + c * L.NCH
    S[b + L.C_W] = w0
    S[b + L.C_FV] = 1.0
    U[L.U_EN0 + c] = 1.0
    U[L.U_VT0 + c] = 1.0
    U[L.U_LEAK0] = U[L.U_LEAK1] = 1.0
    ring = np.zeros(max(delay, 1))
    head = np.zeros(1)
    every = int(P[L.P_DRIVE_EVERY])
    w_out[0] = w0
    i_out[0] = 0.0
    for k in range(len(w_ref) - 1):
        U[L.U_WREF] = delay_push(ring, head, delay, w_ref[k])
        for j in range(nsub):
            pd0 = p_d[k] + (p_d[k + 1] - p_d[k]) * j / nsub
            pd1 = p_d[k] + (p_d[k + 1] - p_d[k]) * (j + 1) / nsub
            torque, f, _, _ = couple(S, P, U, c, j % every == 0, pd0, T)
            a, g = shaft(S[b + L.C_W], torque, f, pd0, P)
            S[b + L.C_W] = a - g * pd1
        w_out[k + 1] = S[b + L.C_W]
        i_out[k + 1] = S[b + L.C_I]


def simulate(p: PlantParams, rec, delay: int) -> tuple[np.ndarray, np.ndarray]:
    """Motor speed and current of the replay of ``rec`` (a drive Recording) with plant p."""
    from scipy.signal import savgol_filter
    c = int(rec.channel[0])
    w, i = np.empty(rec.n), np.empty(rec.n)
    p_d = savgol_filter(rec.p_d, SMOOTH, 3)
    replay(pack(p), leakage_table(p), c, np.ascontiguousarray(rec.command), p_d,
           float(rec.motor_speed[0, c]), int(delay), p.substeps, w, i)
    return w, i


def _with(p: PlantParams, x) -> PlantParams:
    return dataclasses.replace(p, **{n: float(v) * getattr(p, n) for n, v in zip(FITTED, x)})


def identify(rec, p: PlantParams, log=print) -> dict:
    """Fit Kp_w, Ki_w, k_T at whole-tick delays, walking from the nominal delay downhill; keep
    the best delay, its interval the delays whose cost rises less than chi2(1, 95 %).

    Residuals: speed and current errors, each block divided by its RMS at a first fit (so each
    counts by its own noise). Returns estimates, the fit, the delay profile and the replayed
    signals (nominal and identified)."""
    from ..config.cli import UsageError
    if len(set(rec.channel.tolist())) > 1:
        raise UsageError(f'{rec.path}: the active channel changes during the drive experiment')
    use = rec.recorded & (np.arange(rec.n) * rec.Ts >= SETTLE)
    w_m, i_m = rec.speed[use], rec.current[use]
    n = len(w_m)
    blocks = [slice(0, n), slice(n, 2 * n)]
    scale = [np.std(w_m) or 1.0, np.std(i_m) or 1.0]

    def residual_for(delay):
        def residual(x):
            w, i = simulate(_with(p, x), rec, delay)
            return np.concatenate([(w[use] - w_m) / scale[0], (i[use] - i_m) / scale[1]])
        return residual

    groups = np.tile(np.arange(n) // GROUP, 2)         # a speed and its current together

    def solve(delay, x0, most=400):
        return least_squares_fit(residual_for(delay), x0, FITTED, [0.05] * 3, [20.0] * 3,
                                 groups, most)

    d0 = min(p.delay_ticks, MAX_DELAY)
    first = solve(d0, np.ones(3), 8)         # rough: only the blocks' weights come from it
    r = residual_for(d0)(first.x)
    scale = [scale[0] * max(np.sqrt(np.mean(r[blocks[0]] ** 2)), 1e-12),
             scale[1] * max(np.sqrt(np.mean(r[blocks[1]] ** 2)), 1e-12)]
    fits = {d0: solve(d0, first.x)}
    cost = {}

    def at(d, start):
        if d not in fits:
            fits[d] = solve(d, fits[start].x)
        cost[d] = fits[d].residual_rms ** 2 * fits[d].n
        return cost[d]

    at(d0, d0)
    for step in (-1, 1):                    # downhill from the nominal delay, both ways
        d = d0 + step
        while 0 <= d <= MAX_DELAY and at(d, d - step) < cost[d - step]:
            d += step
    best = min(cost, key=cost.get)
    fit = fits[best]
    unit = cost[best] / max(fit.n - 3, 1) * fit.inflation
    lo = hi = best                          # profile interval, widened while inside chi2(1)
    while lo > 0 and (at(lo - 1, lo) - cost[best]) / unit <= CHI2_95:
        lo -= 1
    while hi < MAX_DELAY and (at(hi + 1, hi) - cost[best]) / unit <= CHI2_95:
        hi += 1
    Ts = rec.Ts
    est = {f'drive.{n}' if n != 'k_T' else 'motor.k_T':
           fit.estimate(n, getattr(p, n), getattr(p, n), floor=MODEL_ERROR[n]) for n in FITTED}
    est['drive.delay'] = Estimate(best * Ts, lo * Ts, hi * Ts, p.delay, lo == hi,
                                  '' if lo == hi else
                                  f'delays {lo}-{hi} ticks fit the data alike')
    ident = _with(p, fit.x)
    ident = dataclasses.replace(ident, delay=best * Ts)
    w_nom, i_nom = simulate(p, rec, p.delay_ticks)
    w_id, i_id = simulate(ident, rec, best)
    log(f'identify: drive: delay {best} ticks, Kp_w x{fit.x[0]:.3f}, Ki_w x{fit.x[1]:.3f}, '
        f'k_T x{fit.x[2]:.3f} ({sum(f.nfev for f in fits.values())} replays, '
        f'{sum(f.wall_s for f in fits.values()):.1f} s)')
    rmse = {m: float(np.sqrt(np.mean((w[use] - w_m) ** 2))) for m, w in
            (('nominal', w_nom), ('identified', w_id))}
    maxe = {m: float(np.max(np.abs(w[use] - w_m))) for m, w in
            (('nominal', w_nom), ('identified', w_id))}
    return {'estimates': est, 'fit': fit, 'delay_cost': cost, 'use': use,
            'signals': {'t': rec.t - rec.t[0], 'command': rec.command, 'measured': rec.speed,
                        'nominal': w_nom, 'identified': w_id, 'current': rec.current,
                        'current_nominal': i_nom, 'current_identified': i_id},
            'speed_rmse_rad_s': rmse, 'speed_max_error_rad_s': maxe}
