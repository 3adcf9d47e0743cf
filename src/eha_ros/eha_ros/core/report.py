"""Run outputs under out/<run>/: atomic writes of JSON and CSV, run folder naming, Bode plot."""
from __future__ import annotations

import csv
import datetime
import json
import os

import numpy as np


def run_dir(base: str = 'out', name: str | None = None) -> str:
    """A folder out/<name or timestamp>; an existing one is reused only while it holds no
    summary.json (so a run never overwrites another run's report)."""
    stamp = name or datetime.datetime.now().strftime('run-%Y%m%d-%H%M%S')
    path = os.path.join(base, stamp)
    i = 1
    while os.path.exists(os.path.join(path, 'summary.json')) or \
            (os.path.exists(path) and not os.path.isdir(path)):
        path = os.path.join(base, f'{stamp}-{i}')
        i += 1
    os.makedirs(path, exist_ok=True)
    return path


def write_json(path: str, data, sort_keys: bool = False) -> None:
    """Atomic: write a temporary file then rename, so readers never see half a file."""
    os.makedirs(os.path.dirname(path) or '.', exist_ok=True)
    tmp = path + '.tmp'
    with open(tmp, 'w') as fh:
        json.dump(data, fh, indent=2, default=_jsonable, sort_keys=sort_keys)
        fh.write('\n')
    os.replace(tmp, path)


def write_csv(path: str, columns: dict) -> None:
    """Columns of equal length to CSV (atomic)."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    tmp = path + '.tmp'
    with open(tmp, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(names)
        for row in data:
            w.writerow([f'{v:.9g}' for v in row])
    os.replace(tmp, path)


def _jsonable(obj):
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(type(obj))


def bode_png(path: str, points: list[dict], model=None, title: str = '') -> None:
    """Measured gain/phase points with an optional model overlay (freqs_hz, gain_db, phase_deg)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from .sweep.analysis import unwrap_deg
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
    fig.tight_layout()
    tmp = path + '.tmp.png'
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)
