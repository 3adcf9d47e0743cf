"""Plots of a sweep's result: Bode points over the linear model, dynamic stiffness against
the eq. 4.60 bound (PNG files written atomically by core.io.report.save_png)."""
from __future__ import annotations

from ..io.report import save_png
from .analysis import unwrap_deg


def stiffness_png(path: str, rows: list[dict], title: str = '') -> None:
    """Measured |F_L|/|x| per frequency (kN/mm) against the eq. 4.60 bound where given."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    f = [r['freq_hz'] for r in rows]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.semilogx(f, [r['stiffness_kn_per_mm'] for r in rows], 'o-', color='C0', label='measured')
    if rows and all('bound_kn_per_mm' in r for r in rows):
        ax.semilogx(f, [r['bound_kn_per_mm'] for r in rows], 'k--', lw=1.5,
                    label='1/|M| (eq. 4.60)')
    ax.set_ylim(bottom=0)
    ax.set_xlabel('frequency [Hz]')
    ax.set_ylabel('|F_L|/|x| [kN/mm]')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend()
    ax.set_title(title)
    save_png(fig, path)


def bode_png(path: str, points: list[dict], model=None, title: str = '') -> None:
    """Measured gain/phase points with an optional model overlay (freqs_hz, gain_db, phase_deg)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    f = [p['freq_hz'] for p in points]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    if model is not None:
        ax1.semilogx(model[0], model[1], 'k-', lw=1, label='linear model')
        ax2.semilogx(model[0], model[2], 'k-', lw=1)
    ax1.semilogx(f, [p['gain_db'] for p in points], 'o-', color='C0', label='measured')
    ax2.semilogx(f, unwrap_deg([p['phase_deg'] for p in points]), 'o-', color='C0')
    ax1.axhline(-3, color='C3', ls=':', lw=1, label='-3 dB')
    ax1.set_ylabel('gain [dB]')
    ax2.set_ylabel('phase [deg]')
    ax2.set_xlabel('frequency [Hz]')
    ax1.grid(True, which='both', alpha=0.3)
    ax2.grid(True, which='both', alpha=0.3)
    ax1.legend()
    ax1.set_title(title)
    save_png(fig, path)
