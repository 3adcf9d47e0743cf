"""Leakage, thesis sec. 3.6.3 (Fig. 3.44): the motor speed that holds the piston against a
constant load gives the flow the chambers lose, D_p omega = C_L (p_A - p_B) (eq. 3.15, 3.20-3.22).

Held loads put the unloaded chamber on its boost check valve (core.sim.linear.operating_leakage),
so C_L is the LOADED leakage C_p + C_c + C_r: the loaded chamber loses its whole external
leakage. eq. 3.22's C_eq = C_p + C_c + C_r/2 needs the split, which held loads cannot tell (the
light-load regime where both chambers stay above the check valves ends at |F_L| = 2 A_p
p_crack, about 150 N, under the friction): C_eq is reported with config/plant.yaml's split
assumed (C_p, C_c, C_r scaled together), the split itself as not identified. The check valve
is the plant's (conductance K past its crack p_c): with both chambers' balances (eq. 3.20-3.21 at
v = 0) the held flow is :func:`held_flow`, C_L dp less C_r (C_r dp + K p_c)/(2 C_r + K).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .fit import Estimate, least_squares_fit

HOLD_MIN = 1.0          # [s] a load held this long is a level
SETTLE = 0.5            # share of each hold left out at its start (the transient)
LOADED = 5.0            # a level counts when |dp|/2 exceeds this x the check valve's crack
MODEL_ERROR = 0.01      # relative half-width added to the interval: the loop's slow motions
                        # (the position sensor's drift) and the valves' smooth opening band;
                        # biases up to 0.3 % on the plant's own recordings


def held_flow(C_pc: float, C_r: float, K: float, crack: float, dp: np.ndarray) -> np.ndarray:
    """Pump flow D_p omega [m^3/s] that holds p_A - p_B = dp at v = 0 with the unloaded chamber
    on its check valve: chamber balances (eq. 3.15, 3.20-3.21) with C_pc = C_p + C_c, the
    check flow K (p_acc - p_crack - p_low) added to them eliminating p_low."""
    mag = np.abs(dp)
    q = (C_pc + C_r) * mag - C_r * (C_r * mag + K * crack) / (2.0 * C_r + K)
    return np.sign(dp) * q


def levels(rec, p) -> list[tuple[int, int, float]]:
    """Steady windows (start, stop, load [N]) of the held loads that load one chamber."""
    f = rec.load
    change = np.nonzero(np.abs(np.diff(f)) > 1.0)[0] + 1
    bounds = np.concatenate([[0], change, [rec.n]])
    out = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if (b - a) * rec.Ts >= HOLD_MIN and abs(f[a]) / p.A_p / 2 > LOADED * p.check_crack:
            out.append((int(a + SETTLE * (b - a)), int(b), float(f[a])))
    return out


def identify(rec, p, log=print) -> dict:
    """C_L from the held levels; C_eq and the scaled split; the figure's data."""
    win = levels(rec, p)
    signals = {'t': rec.t - rec.t[0], 'load': rec.load, 'speed': rec.speed, 'p_d': rec.p_d,
               'windows': [(a, b) for a, b, _ in win]}
    c_l_nom = p.C_p + p.C_c + p.C_r
    if not win:
        why = (f'no load held {HOLD_MIN:g} s that puts a chamber on its check valve '
               f'(|F_L| > {2 * LOADED * p.check_crack * p.A_p:.0f} N)')
        est = {k: Estimate(v, None, None, v, False, f'not determined by the data: {why}')
               for k, v in (('C_eq', p.C_eq), ('pump.C_p', p.C_p), ('cylinder.C_c', p.C_c),
                            ('pump.C_r', p.C_r))}
        return {'estimates': est, 'fit': None, 'levels': [], 'signals': signals,
                'scale': 1.0}
    idx = np.concatenate([np.arange(a, b) for a, b, _ in win])
    idx = idx[rec.recorded[idx]]
    q = p.D_p * rec.speed[idx]
    dp = rec.p_d[idx]
    unit = c_l_nom * np.std(dp)

    def residual(x):
        return (held_flow(x[0] * (p.C_p + p.C_c), x[0] * p.C_r, p.check_K, p.check_crack, dp)
                - q) / unit

    group = np.searchsorted(np.array([a for a, _, _ in win]), idx, side='right') * 100000 + \
        (idx // 250)
    fit = least_squares_fit(residual, [1.0], ['C_L'], [1e-3], [1e3], group)
    s = float(fit.x[0])
    split = 'split of config/plant.yaml assumed (C_p : C_c : C_r kept)'
    est = {'C_eq': fit.estimate('C_L', p.C_eq, p.C_eq, note=split, floor=MODEL_ERROR)}
    for key, attr in (('pump.C_p', 'C_p'), ('cylinder.C_c', 'C_c'), ('pump.C_r', 'C_r')):
        e = fit.estimate('C_L', getattr(p, attr), getattr(p, attr), floor=MODEL_ERROR)
        est[key] = dataclasses.replace(
            e, identified=False, note='not determined by the data: held loads give only the '
                                      'loaded sum C_p + C_c + C_r; scaled with it (split of '
                                      'config/plant.yaml assumed)')
    est['C_loaded'] = fit.estimate('C_L', c_l_nom, c_l_nom, floor=MODEL_ERROR,
                                   note='C_p + C_c + C_r: the leakage of a held load')
    per_level = []
    for a, b, load in win:
        use = np.arange(a, b)
        per_level.append({'load_n': load, 'p_d_pa': float(np.mean(rec.p_d[use])),
                          'motor_speed_rad_s': float(np.mean(rec.speed[use])),
                          'leakage_m3_s_pa': float(np.mean(p.D_p * rec.speed[use]) /
                                                   np.mean(rec.p_d[use]))})
    log(f'identify: leakage: C_p + C_c + C_r x{s:.3f} of nominal ({len(win)} held levels), '
        f'C_eq {s * p.C_eq:.3g} m^3/(s Pa)')
    return {'estimates': est, 'fit': fit, 'levels': per_level, 'signals': signals, 'scale': s}
