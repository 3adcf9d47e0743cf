"""Figures (matplotlib, Agg): Nichols chart with bounds and L0 (Fig. 4.42), closed-loop family
Bode with T_up/T_low (Fig. 4.43), PSO convergence (Fig. 4.30)."""
from __future__ import annotations

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from . import bounds as qb  # noqa: E402


def nichols(path, bset, L0_fn, title):
    """Merged bounds per design frequency (solid: lower, dashed: forbidden interval) and the
    nominal open loop L0 on a dense grid with the design frequencies marked."""
    fig, ax = plt.subplots(figsize=(9, 7))
    cmap = plt.get_cmap('tab10')
    b = bset.merged
    for f, w in enumerate(bset.w):
        c = cmap(f % 10)
        lo = qb.db(b.lo[f])
        ok = np.isfinite(lo)
        if ok.any():
            ax.plot(b.phase_deg[ok], lo[ok], '-', color=c, label=f'{w:g} rad/s')
        fl, fh = qb.db(b.fb_lo[f]), qb.db(b.fb_hi[f])
        ok = np.isfinite(fl)
        if ok.any():
            ax.plot(b.phase_deg[ok], fl[ok], '--', color=c)
            ax.plot(b.phase_deg[ok], fh[ok], '--', color=c)
    wd = np.logspace(np.log10(bset.w.min()) - 0.5, np.log10(bset.w.max()) + 1, 800)
    L = L0_fn(wd)
    ph = np.rad2deg(np.angle(L))
    ph = np.where(ph > 0, ph - 360, ph)
    ax.plot(ph, qb.db(np.abs(L)), 'k.', ms=1.5, label='L0 (nominal)')
    Lm = L0_fn(bset.w)
    phm = np.rad2deg(np.angle(Lm))
    phm = np.where(phm > 0, phm - 360, phm)
    for f in range(len(bset.w)):
        ax.plot(phm[f], qb.db(abs(Lm[f])), 'o', color=cmap(f % 10), mec='k')
    ax.set_xlim(-360, 0)
    ax.set_ylim(-60, 160)
    ax.set_xlabel('open-loop phase (deg)')
    ax.set_ylabel('open-loop gain (dB)')
    ax.set_title(title)
    ax.grid(True)
    ax.legend(fontsize=7, loc='upper right')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def closed_loop_bode(path, w, FT, spec, title):
    """|F T_r| of every plant (grey) with T_up/T_low (eq. 4.62/4.63), frequency in Hz."""
    fig, ax = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    hz = w / (2 * np.pi)
    ax[0].semilogx(hz, qb.db(np.abs(FT)).T, color='0.6', lw=0.5)
    ax[0].semilogx(hz, qb.db(np.abs(FT[-1])), 'k', lw=1.5, label='nominal')
    ax[0].semilogx(hz, qb.db(np.abs(spec.T_up(w))), 'r--', label='T_up')
    ax[0].semilogx(hz, qb.db(np.abs(spec.T_low(w))), 'b--', label='T_low')
    ax[0].axhline(-3.01, color='g', lw=0.8, ls=':', label='-3 dB')
    ax[0].axvline(spec['prefilter.bandwidth_min_hz'], color='g', lw=0.8)
    ax[0].set_ylim(-40, 6)
    ax[0].set_ylabel('|F T| (dB)')
    ax[0].legend(fontsize=8)
    ax[0].grid(True, which='both')
    ax[0].set_title(title)
    ax[1].semilogx(hz, np.rad2deg(np.unwrap(np.angle(FT), axis=1)).T, color='0.6', lw=0.5)
    ax[1].set_ylabel('phase (deg)')
    ax[1].set_xlabel('frequency (Hz)')
    ax[1].grid(True, which='both')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def convergence(path, histories: dict):
    """Best cost per PSO iteration for each optimisation."""
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for name, h in histories.items():
        h = np.asarray(h)
        ax.plot(np.arange(len(h)), h, label=name)
    ax.set_xlabel('iteration')
    ax.set_ylabel('best cost')
    ax.set_yscale('symlog', linthresh=1e-2)
    ax.grid(True)
    ax.legend()
    ax.set_title('PSO convergence (Table 4.8)')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def steps(path, results: dict, spec):
    """Nominal discrete step responses of F T (name -> analyse() dict) with the spec limits."""
    fig, ax = plt.subplots(figsize=(8, 5))
    a = 1e3 * spec['digital.step']
    for name, r in results.items():
        ax.step(np.asarray(r['step_nominal_t']), 1e3 * np.asarray(r['step_nominal_y']),
                where='post', label=f'{name}: {r["step_overshoot_pct"]:.2g} % overshoot, '
                f'{r["step_settling_s"]:.3g} s settling')
    band = spec['digital.settling_band']
    ax.axhline(a * (1 + spec['digital.overshoot_max_pct'] / 100), color='r', ls=':', label='overshoot limit')
    for v in (a * (1 - band), a * (1 + band)):
        ax.axhline(v, color='g', ls='--', lw=0.8)
    ax.axvline(spec['digital.settling_max'], color='g', ls=':', label='settling limit')
    ax.set_xlim(0, min(1.0, spec['digital.horizon']))
    ax.set_xlabel('time (s)')
    ax.set_ylabel('position (mm)')
    ax.set_title(f'digital loop at Ts = {spec["digital.Ts"]:g} s, nominal plant, {a:g} mm step')
    ax.grid(True)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
