"""Frequency-response analysis of sweep data (appendix B.2): gain/phase per frequency, coherence,
chirp H1 estimate, bandwidth, phase at 7 Hz."""
from __future__ import annotations

import math
from dataclasses import dataclass, asdict

import numpy as np


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


def bandwidth_hz(freqs, gains_db, level_db: float = -3.0):
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
