"""Frequency-response analysis of sweep data (appendix B.2): gain/phase per frequency, coherence,
chirp H1 estimate, bandwidth, phase at 7 Hz."""
from __future__ import annotations

import math
from dataclasses import dataclass, asdict

import numpy as np


BANDWIDTH_DB = -3.0       # the closed-loop bandwidth: the first frequency below this gain


@dataclass
class Point:
    freq_hz: float
    gain_db: float
    phase_deg: float
    coherence: float

    def as_dict(self):
        return asdict(self)


def _dft_bin(x: np.ndarray, f: float, Ts: float) -> complex:
    """Complex amplitude of x at frequency f over whole periods (the FFT bin, appendix B.2)."""
    n = np.arange(len(x))
    return 2.0 / len(x) * np.sum(x * np.exp(-2j * np.pi * f * n * Ts))


def sine_point(u: np.ndarray, y: np.ndarray, f: float, Ts: float, settle_periods: int = 2) -> Point:
    """Gain and phase of y against u at f, skipping settle periods; per-period coherence.

    Coherence: magnitude-squared coherence at f across the analysed periods (each period one
    segment), |sum U_k* Y_k|^2 / (sum |U_k|^2 sum |Y_k|^2): 1 for a noise-free linear response.
    """
    per = 1.0 / (f * Ts)                   # samples per period (may be fractional)
    n_periods = int(len(u) / per)
    if n_periods - settle_periods < 1:
        raise ValueError(f'{f} Hz: {n_periods} periods recorded, need more than {settle_periods}')
    start = int(round(settle_periods * per))
    stop = int(round(n_periods * per))
    U = _dft_bin(u[start:stop] - np.mean(u[start:stop]), f, Ts)
    Y = _dft_bin(y[start:stop] - np.mean(y[start:stop]), f, Ts)
    H = Y / U
    cross, pu, py = 0j, 0.0, 0.0
    for k in range(settle_periods, n_periods):
        a, b = int(round(k * per)), int(round((k + 1) * per))
        uk = _dft_bin(u[a:b] - np.mean(u[a:b]), f, Ts)
        yk = _dft_bin(y[a:b] - np.mean(y[a:b]), f, Ts)
        cross += np.conj(uk) * yk
        pu += abs(uk) ** 2
        py += abs(yk) ** 2
    coh = abs(cross) ** 2 / (pu * py) if pu > 0 and py > 0 else 0.0
    return Point(float(f), float(20 * np.log10(abs(H))), float(np.degrees(np.angle(H))), float(coh))


def unwrap_deg(phases) -> np.ndarray:
    return np.degrees(np.unwrap(np.radians(np.asarray(phases, dtype=float))))


def chirp_h1(u: np.ndarray, y: np.ndarray, Ts: float, nperseg: int = 4096):
    """H1 = S_uy / S_uu and coherence by Welch averaging (scipy.signal)."""
    from scipy import signal
    f, Puu = signal.welch(u, fs=1 / Ts, nperseg=nperseg)
    _, Puy = signal.csd(u, y, fs=1 / Ts, nperseg=nperseg)
    _, coh = signal.coherence(u, y, fs=1 / Ts, nperseg=nperseg)
    return f, Puy / np.where(Puu > 0, Puu, np.nan), coh


def bandwidth_hz(freqs, gains_db, level_db: float = BANDWIDTH_DB):
    """First frequency where the gain falls below level_db (log-interpolated); None if never."""
    freqs, gains = np.asarray(freqs, float), np.asarray(gains_db, float)
    below = np.nonzero(gains < level_db)[0]
    if below.size == 0:
        return None
    i = below[0]
    if i == 0:
        return float(freqs[0])
    f0, f1, g0, g1 = freqs[i - 1], freqs[i], gains[i - 1], gains[i]
    r = (level_db - g0) / (g1 - g0)
    return float(10 ** (math.log10(f0) + r * (math.log10(f1) - math.log10(f0))))


def value_at(freqs, values, f: float):
    """Log-frequency interpolation of a quantity at f; None outside the measured range."""
    freqs = np.asarray(freqs, float)
    if f < freqs.min() or f > freqs.max():
        return None
    return float(np.interp(math.log10(f), np.log10(freqs), np.asarray(values, float)))


def summarize(points: list[Point]) -> dict:
    """bandwidth_hz, phase_at_7hz_deg, peak gain from sweep points (sorted by frequency)."""
    pts = sorted(points, key=lambda p: p.freq_hz)
    f = [p.freq_hz for p in pts]
    g = [p.gain_db for p in pts]
    ph = unwrap_deg([p.phase_deg for p in pts])
    peak = int(np.argmax(g)) if pts else None
    return {
        'bandwidth_hz': bandwidth_hz(f, g) if pts else None,
        'phase_at_7hz_deg': value_at(f, ph, 7.0) if pts else None,
        'peak_gain_db': float(g[peak]) if pts else None,
        'peak_gain_freq_hz': float(f[peak]) if pts else None,
        'points': [p.as_dict() for p in pts],
    }


def stiffness_kn_per_mm(point: Point) -> float:
    """|F_L|/|x| in kN/mm from the gain of x against the load force (m/N, in dB)."""
    return float(10 ** (-point.gain_db / 20.0) / 1e6)


def stiffness_bound(config_dir: str | None = None):
    """f_hz -> 1/|M(j 2 pi f)| in kN/mm, the stiffness bound of eq. 4.60 (config/qft_spec.yaml)."""
    from ..qft.spec import configured_spec
    spec = configured_spec(config_dir)
    return lambda f_hz: float(1.0 / abs(spec.M(2 * math.pi * float(f_hz))) / 1e6)


def stiffness_summary(points: list[Point], bound=None) -> dict:
    """Per-frequency |F_L|/|x| of a load sweep (kN/mm), with the eq. 4.60 bound when given,
    the smallest ratio to it and whether every frequency meets it."""
    pts = sorted(points, key=lambda p: p.freq_hz)
    rows = []
    for p in pts:
        row = {'freq_hz': p.freq_hz, 'stiffness_kn_per_mm': stiffness_kn_per_mm(p)}
        if bound is not None:
            row['bound_kn_per_mm'] = bound(p.freq_hz)
        rows.append(row)
    ratio = [r['stiffness_kn_per_mm'] / r['bound_kn_per_mm'] for r in rows
             if 'bound_kn_per_mm' in r]
    return {'stiffness': rows,
            'stiffness_min_kn_per_mm': min((r['stiffness_kn_per_mm'] for r in rows), default=None),
            'stiffness_min_ratio_to_bound': min(ratio) if ratio else None,
            'stiffness_meets_bound': bool(ratio) and min(ratio) >= 1.0}


# load force step while holding 0 (positive F_L pushes towards negative x, eq. 3.23); peak |x|
# after it, mean |x| over [t_step + steady[0], t_step + steady[1]]: the campaigns' load_step
# scenario (core.sim.scenarios.KINDS) and the sweep node's load_step mode
LOAD_STEP = dict(force=5e3, t_step=0.5, duration=5.0, steady=[3.5, 4.5])


def load_step_figures(s, p, Ts):
    """Peak |x| after the load step; steady error over the window (target 0): of what the
    position sensor reports without its white noise, truth + its Gauss-Markov offset (held,
    nothing observes that offset, so no estimator can be charged for it), and of the truth
    alone (``steady_error_truth_m``)."""
    t, x = s['t'], s['truth']
    after = t >= p['t_step'] - 1e-9
    ta = t[after] - p['t_step']
    win = (ta >= p['steady'][0]) & (ta <= p['steady'][1])
    x0 = float(np.mean(x[(t < p['t_step']) & (t >= p['t_step'] - 0.2)]))
    return {'peak_deviation_m': float(np.max(np.abs(x[after] - x0))),
            'steady_error_m': float(abs(np.mean(s['sensor_lf'][after][win]))),
            'steady_error_truth_m': float(abs(np.mean(x[after][win]))),
            'estimate_error_m': float(abs(np.mean(s['estimate'][after][win] - x[after][win])))}
