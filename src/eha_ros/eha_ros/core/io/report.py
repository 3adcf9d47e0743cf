"""Run outputs under out/<run>/: atomic writes of JSON and CSV, run folder naming, Bode plot."""
from __future__ import annotations

import csv
import datetime
import json
import os

import numpy as np


FINISHED = ('summary.json', 'stack.json')      # a folder holding one of these is a finished run


def run_dir(base: str = 'out', name: str | None = None) -> str:
    """A folder base/<name or timestamp>. ``name`` is one folder name (no path: a run stays
    under ``base``); a folder holding a finished run (FINISHED) is never reused: -1, -2, ...
    are appended. A bad name or a base that cannot be written is a UsageError (one line)."""
    from ..config.cli import UsageError
    if name is not None and (not name or name in ('.', '..') or os.sep in name
                             or (os.altsep and os.altsep in name)):
        raise UsageError(f'--name {name!r}: expected a plain folder name (no path), '
                         f'the run folder is created under {base}/')
    stamp = name or datetime.datetime.now().strftime('run-%Y%m%d-%H%M%S')
    path = os.path.join(base, stamp)
    i = 1
    while any(os.path.exists(os.path.join(path, f)) for f in FINISHED) or \
            (os.path.exists(path) and not os.path.isdir(path)):
        path = os.path.join(base, f'{stamp}-{i}')
        i += 1
    try:
        os.makedirs(path, exist_ok=True)
        probe = os.path.join(path, '.write-test')
        open(probe, 'w').close()
        os.remove(probe)
    except OSError as err:
        raise UsageError(f'cannot write the run folder {path}: {err.strerror or err}') from None
    return path


def write_json(path: str, data, sort_keys: bool = False, reserved: bool = False) -> None:
    """Atomic: write a temporary file then rename, so readers never see half a file.
    ``reserved``: the file was made by :func:`reserve_json`; when the disk is full (no room for
    the temporary file) the JSON is written over the reservation in place instead."""
    text = json.dumps(data, indent=2, default=_jsonable, sort_keys=sort_keys) + '\n'
    os.makedirs(os.path.dirname(path) or '.', exist_ok=True)
    tmp = path + '.tmp'
    try:
        with open(tmp, 'w') as fh:
            fh.write(text)
        os.replace(tmp, path)
    except OSError:
        if os.path.exists(tmp):
            os.remove(tmp)
        if not reserved:
            raise
        with open(path, 'r+b') as fh:         # blocks already allocated: no new space needed
            raw = text.encode()
            if len(raw) > os.fstat(fh.fileno()).st_size:
                raise
            fh.write(raw)
            fh.truncate()


def reserve_json(path: str, data, size: int = 1 << 18) -> None:
    """Write ``data`` as JSON padded with blanks to ``size`` bytes: the run's final JSON then
    has its disk space from the start (write_json(..., reserved=True)), full disk or not."""
    text = json.dumps(data, default=_jsonable) + '\n'
    os.makedirs(os.path.dirname(path) or '.', exist_ok=True)
    with open(path, 'w') as fh:
        fh.write(text + ' ' * max(0, size - len(text)))


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


def save_png(fig, path: str) -> None:
    """Write a matplotlib figure atomically (a reader never sees half a PNG) and close it."""
    import matplotlib.pyplot as plt
    fig.tight_layout()
    tmp = path + '.tmp.png'
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)


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
    from ..sweep.analysis import unwrap_deg
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
