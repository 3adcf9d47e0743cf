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
