"""Plots around each channel switch: piston position and reference, both motor speeds (with
the speed reference) and the on-off valve states (Fig. 3.12 valves, bypass), like the
thesis' Fig. 3.22 and 3.24. From in-memory arrays or a recording CSV.

    python -m eha_ros.tools.plot_switch RECORDING.csv --events 3.0 5.0 --out out/redundancy/plots

CSV columns: t [s], ref [m], x [m], w0, w1 [rad/s], w_ref [rad/s] (optional), valve0, valve1
[0..1], bypass [0..1] (optional), active (optional). SI in the file, mm / rpm in the plots.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys

import numpy as np

from ..core.config.cli import UsageError, guarded

RPM = 60.0 / (2.0 * np.pi)
COLUMNS = ('t', 'ref', 'x', 'w0', 'w1', 'valve0', 'valve1')


def write_csv(path: str, rec: dict) -> None:
    """Write a recording dict (1-D arrays keyed as COLUMNS + optional ones) to CSV."""
    keys = [k for k in ('t', 'ref', 'x', 'w0', 'w1', 'w_ref', 'valve0', 'valve1', 'bypass',
                        'active') if k in rec]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, 'w', newline='') as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for row in zip(*(np.asarray(rec[k]) for k in keys)):
            w.writerow([f'{v:.9g}' for v in row])


def read_csv(path: str) -> dict:
    try:
        with open(path, newline='') as fh:
            rows = list(csv.reader(fh))
    except OSError as err:
        raise UsageError(f'{path}: cannot read recording: {err.strerror}') from None
    if not rows:
        raise UsageError(f'{path}: empty recording: expected a header with {", ".join(COLUMNS)}')
    head = rows[0]
    missing = [c for c in COLUMNS if c not in head]
    if missing:
        raise UsageError(f'{path}: column {missing[0]!r} missing: expected at least '
                         f'{", ".join(COLUMNS)}')
    try:
        data = np.array(rows[1:], float)
    except ValueError:
        raise UsageError(f'{path}: non-numeric value in the recording') from None
    if data.ndim != 2 or len(data) < 2:
        raise UsageError(f'{path}: fewer than 2 samples')
    return {name: data[:, i] for i, name in enumerate(head)}


def plot_switches(rec: dict, events, out_dir: str, before: float = 0.1, after: float = 0.25,
                  labels=None) -> list[str]:
    """One PNG per event time: position/reference (mm), motor speeds (rpm), valve fractions."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    os.makedirs(out_dir, exist_ok=True)
    t = np.asarray(rec['t'], float)
    paths = []
    for n, te in enumerate(events):
        m = (t >= te - before) & (t <= te + after)
        if not m.any():
            continue
        fig, ax = plt.subplots(3, 1, sharex=True, figsize=(8, 8))
        ax[0].plot(t[m], 1e3 * np.asarray(rec['ref'])[m], 'k--', label='reference')
        ax[0].plot(t[m], 1e3 * np.asarray(rec['x'])[m], 'b', label='position')
        ax[0].set_ylabel('position [mm]')
        for c, col in ((0, 'tab:blue'), (1, 'tab:orange')):
            ax[1].plot(t[m], RPM * np.asarray(rec[f'w{c}'])[m], color=col,
                       label=f'motor {"AB"[c]}')
            ax[2].plot(t[m], np.asarray(rec[f'valve{c}'])[m], color=col,
                       label=f'valves {"AB"[c]}')
        if 'w_ref' in rec:
            ax[1].plot(t[m], RPM * np.asarray(rec['w_ref'])[m], 'k:', lw=0.8,
                       label='speed reference')
        if 'bypass' in rec:
            ax[2].plot(t[m], np.asarray(rec['bypass'])[m], 'g', label='A-B bypass')
        ax[1].set_ylabel('motor speed [rpm]')
        ax[2].set_ylabel('valve opening [-]')
        ax[2].set_xlabel('time [s]')
        for a in ax:
            a.axvline(te, color='r', lw=0.8)
            a.grid(True, alpha=0.3)
            a.legend(loc='upper right', fontsize=7)
        title = labels[n] if labels else f'switch at {te:.3f} s'
        ax[0].set_title(title)
        fig.tight_layout()
        path = os.path.join(out_dir, f'switch_{n}_{te:.3f}s.png')
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='plot_switch', description=__doc__.splitlines()[0])
    ap.add_argument('recording', help='CSV recording (see module doc for the columns)')
    ap.add_argument('--events', type=float, nargs='+', required=True, help='switch times [s]')
    ap.add_argument('--out', default='out/redundancy/plots', help='output folder')
    args = ap.parse_args(argv)

    def run():
        for p in plot_switches(read_csv(args.recording), args.events, args.out):
            print(p)
        return 0

    return guarded('plot_switch', run)


if __name__ == '__main__':
    sys.exit(main())
