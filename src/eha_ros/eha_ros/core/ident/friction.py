"""Piston friction, thesis sec. 3.6.3 (Fig. 3.40-3.42, Table 3.7): eq. 3.33's F_c, F_s, v_s
and mu fitted to the force the chamber pressures give, A_p (p_A - p_B) - F_L - m_p a (eq. 3.32),
against the piston velocity, the curve being the plant's own (core.plant.friction).

Velocity and acceleration are Savitzky-Golay derivatives of the measured position (cubic, WINDOW
ticks: the sensor's 10 um noise becomes about 0.3 mm/s), and the force is smoothed by the same
filter: the chamber pressures carry the hydraulic resonance (about 760 Hz, above the 500 Hz
Nyquist frequency of the ticks, so it shows aliased), which is not friction. Where that
oscillation is large (the local RMS of the force's high-pass above RINGING times its quiet
level, the QUIET percentile over the recording) the samples are left out: the friction there is
an average over the oscillation, not the force at the smoothed velocity, and the average rounds
the curve most where it bends. The oscillation is the friction's own doing: past the static peak
eq. 3.33 falls with speed (down to about 3 v_s), a negative damping that excites the mode, so
the samples the ringing spoils are those that place F_c and v_s. Samples slower than V_MIN are
left out: there the piston sticks and the pressure force is whatever the loop holds, not the
velocity's friction (eq. 3.33 is regularised at v_s/10 and says nothing about sticking).

A parameter the fit drives onto its bound (mu, when the clean samples stop at low speed: the
viscous term is then a few tens of newtons the Coulomb level absorbs) is not determined by the
data: it is held at its nominal value and the others are fitted again without it, their
intervals widened by how far they move when the held one is set anywhere in HELD_RANGE of its
nominal value (refits at both ends). The curve then is what the data showed given the held one,
not a mix of a fit of four and nominal values.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..plant.friction import friction
from .fit import Estimate, least_squares_fit

WINDOW = 21             # [ticks] Savitzky-Golay window of the position derivatives
V_MIN = 0.004           # [m/s] slower samples are left out (sticking)
FITTED = ('F_c', 'F_s', 'v_s', 'mu')
STRIBECK = 2            # core.plant.friction's model code for eq. 3.33
BINS = 60               # velocity bins of the figure's averages
MODEL_ERROR = {'F_c': 0.06, 'F_s': 0.06, 'v_s': 0.06, 'mu': 0.18}
                        # relative half-widths added to the intervals: the filter rounds the
                        # Stribeck hump (v_s +5 %, F_c -2 % on the plant's own recordings); mu
                        # carries what is left of the ringing's average (up to +14 % on twelve
                        # plants, docs/identification.md: mu v is a sixth of the force)
HELD_RANGE = (0.5, 2.0)  # multipliers of a held parameter's nominal value the intervals of the
                        # others cover (issue 43's family: mu and v_s x0.5-x2)
MIN_SAMPLES = 500       # fewer usable samples: nothing is fitted
QUIET = 10              # [%] percentile of the force's ringing taken as its quiet level
RINGING = 1.5           # samples ringing above this x the quiet level are left out (3 x the
                        # median, as first shipped: F_c -13 %, v_s -15 %, mu +33 % with
                        # intervals missing the truth; the median rises on a plant that rings
                        # over much of its recording)


@njit(cache=True)
def curve(v, F_c, F_s, v_s, mu):
    """Eq. 3.33 at every velocity of v (core.plant.friction.friction)."""
    out = np.empty(len(v))
    for k in range(len(v)):
        out[k] = friction(v[k], STRIBECK, F_c, F_s, v_s, mu)[0]
    return out


def force_velocity(rec, p) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Piston velocity [m/s], friction force from the pressures [N] and the samples used."""
    from scipy.signal import savgol_filter
    v = savgol_filter(rec.position, WINDOW, 3, deriv=1, delta=rec.Ts)
    a = savgol_filter(rec.position, WINDOW, 3, deriv=2, delta=rec.Ts)
    raw = p.A_p * rec.p_d - rec.load
    smooth = savgol_filter(raw, WINDOW, 3)
    force = smooth - p.m_p * a
    ringing = np.sqrt(savgol_filter((raw - smooth) ** 2, WINDOW, 0))
    edge = np.zeros(rec.n, bool)
    edge[WINDOW:-WINDOW] = True
    valid = rec.recorded & edge
    keep = valid & (np.abs(v) >= V_MIN) & \
        (ringing <= RINGING * np.percentile(ringing[valid], QUIET))
    return v, force, keep


def identify(rec, p, log=print) -> dict:
    """Fit eq. 3.33 (multipliers of the nominal F_c, F_s, v_s, mu); estimates, fit and the
    figure's data (samples, binned means)."""
    v, force, keep = force_velocity(rec, p)
    vk, fk = v[keep], force[keep]
    if len(vk) < MIN_SAMPLES:
        return _unidentified(p, f'{len(vk)} usable samples (moving faster than {V_MIN} m/s '
                                f'without ringing): expected at least {MIN_SAMPLES}')
    nominal = np.array([getattr(p, n) for n in FITTED])
    groups = np.nonzero(keep)[0] // 250

    def residual(x):
        c = x * nominal
        return curve(vk, c[0], c[1], c[2], c[3]) - fk

    def multipliers(xf, free: list, held: dict) -> np.ndarray:
        """All four multipliers: ``xf`` for ``free``, the others at ``held`` (name -> x)."""
        x = np.array([held.get(n, 1.0) for n in FITTED])
        x[[FITTED.index(n) for n in free]] = xf
        return x

    def fit_free(free: list, held: dict):
        """Fit the multipliers of ``free``, the others at ``held``."""
        return least_squares_fit(lambda xf: residual(multipliers(xf, free, held)),
                                 np.ones(len(free)), free, [1e-3] * len(free),
                                 [50.0] * len(free), groups)

    free, held = list(FITTED), {}
    fit = fit_free(free, held)
    while fit.at_bound and len(free) > len(fit.at_bound):
        held.update({n: 1.0 for n in fit.at_bound})
        free = [n for n in free if n not in held]
        fit = fit_free(free, held)
    spread = np.zeros(len(free))
    if held and not fit.at_bound:
        for m in HELD_RANGE:            # the free ones' shift over the held one's range
            other = fit_free(free, {n: m for n in held})
            spread = np.maximum(spread, np.abs(other.x - fit.x) / np.abs(fit.x))
    note = f'{", ".join(held)} held at nominal (fit ended on its bound)' if held else ''
    est = {f'friction.{n}': fit.estimate(
        n, getattr(p, n), getattr(p, n), note=note,
        floor=float(np.hypot(MODEL_ERROR[n], spread[free.index(n)])))
        for n in free}
    for n in held:
        est[f'friction.{n}'] = Estimate(
            getattr(p, n), None, None, getattr(p, n), False,
            f'not determined by the data: the fit drove it to its bound; held at nominal, '
            f'{", ".join(free)} fitted again')
    c = multipliers(fit.x, free, held) * nominal
    log(f'identify: friction: F_c {c[0]:.0f} N, F_s {c[1]:.0f} N, v_s {c[2] * 1e3:.1f} mm/s, '
        f'mu {c[3]:.0f} N s/m ({len(vk)} samples up to {np.max(np.abs(vk)):.3f} m/s, force '
        f'residual {fit.residual_rms:.0f} N)')
    edges = np.linspace(-np.max(np.abs(vk)), np.max(np.abs(vk)), BINS + 1)
    idx = np.digitize(vk, edges) - 1
    full = [(idx == b).sum() for b in range(BINS)]
    centres = [vk[idx == b].mean() for b in range(BINS) if full[b] >= 5]
    means = [fk[idx == b].mean() for b in range(BINS) if full[b] >= 5]
    return {'estimates': est, 'fit': fit, 'values': dict(zip(FITTED, c.tolist())), 'held': held,
            'data': {'velocity': vk, 'force': fk, 'bin_velocity': np.array(centres),
                     'bin_force': np.array(means)},
            'force_rmse_n': {'identified': fit.residual_rms,
                             'nominal': float(np.sqrt(np.mean(residual(np.ones(4)) ** 2)))}}


def _unidentified(p, why: str) -> dict:
    est = {f'friction.{n}': Estimate(getattr(p, n), None, None, getattr(p, n), False,
                                     f'not determined by the data: {why}') for n in FITTED}
    return {'estimates': est, 'fit': None, 'values': {n: getattr(p, n) for n in FITTED},
            'data': None, 'force_rmse_n': None}
