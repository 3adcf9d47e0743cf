"""Plant variants for campaigns: multipliers of config/plant.yaml, one row per plant.

Columns (all multipliers, 1 = nominal): C_eq (C_p, C_c, C_r together), D_p, beta, k_T, k_E
(Table 4.5), friction (F_c and F_s), noise (every sensor noise sigma) and leak_split (the
external share C_r of the leakage with C_eq = C_p + C_c + C_r/2 kept, eq. 3.22).
"""
from __future__ import annotations

import os

import numpy as np

from ..config.cli import UsageError
from ..config.params import default_config_dir
from ..qft.family import NAMES, grid_scales, scaled_params
from ..qft.family_box import COLUMNS, EXTRA, load_box

NOISE_KEYS = ('plant.sensors.position_sigma', 'plant.sensors.position_gm_sigma',
              'plant.sensors.pressure_sigma', 'plant.sensors.speed_sigma',
              'plant.sensors.current_sigma')


def thesis() -> dict:
    """The 270 plants of Table 4.5, the grid of the QFT design (config/qft_spec.yaml)."""
    from ..qft.spec import load_spec
    return _table(grid_scales(load_spec(os.path.join(default_config_dir(), 'qft_spec.yaml'))))


def _table(scales: np.ndarray, extra: dict | None = None) -> dict:
    n = len(scales)
    out = {name: np.asarray(scales[:, i], float) for i, name in enumerate(NAMES)}
    for name in EXTRA:
        out[name] = np.asarray((extra or {}).get(name, np.ones(n)), float)
    return out


def random(n: int, seed: int, box: dict | None = None) -> dict:
    """n plants drawn by a seeded Latin hypercube (scipy.stats.qmc) over ``box``."""
    from scipy.stats import qmc
    box = box if box is not None else load_box()
    names = list(box)
    u = qmc.LatinHypercube(d=len(names), seed=seed).random(n)
    out = {c: np.ones(n) for c in COLUMNS}
    for i, name in enumerate(names):
        lo, hi, log = box[name]
        out[name] = (np.exp(np.log(lo) + u[:, i] * (np.log(hi) - np.log(lo))) if log
                     else lo + u[:, i] * (hi - lo))
    return out


def from_file(path: str) -> dict:
    """Multipliers from a CSV or Parquet file: columns C_eq, D_p, beta, k_T, k_E required,
    friction, noise, leak_split optional (1); other columns are refused."""
    import pandas as pd
    try:
        if path.endswith(('.parquet', '.pq')):
            df = pd.read_parquet(path)
        else:
            df = pd.read_csv(path, comment='#')
    except FileNotFoundError:
        raise UsageError(f'family file {path}: not found')
    except Exception as err:       # pandas/pyarrow parse errors of many kinds
        raise UsageError(f'family file {path}: cannot read it: {str(err).splitlines()[0]}')
    cols = [str(c).strip() for c in df.columns]
    df.columns = cols
    unknown = [c for c in cols if c not in COLUMNS]
    missing = [c for c in NAMES if c not in cols]
    if unknown or missing:
        raise UsageError(f'family file {path}: ' + '; '.join(
            ([f'unknown column(s) {", ".join(unknown)}'] if unknown else []) +
            ([f'missing column(s) {", ".join(missing)}'] if missing else [])) +
            f' (expected {", ".join(NAMES)} and optionally {", ".join(EXTRA)})')
    if len(df) == 0:
        raise UsageError(f'family file {path}: no rows')
    out = {}
    for c in COLUMNS:
        if c not in cols:
            out[c] = np.ones(len(df))
            continue
        v = pd.to_numeric(df[c], errors='coerce').to_numpy(float)
        bad = np.nonzero(~(np.isfinite(v) & (v > 0)))[0]
        if len(bad):
            raise UsageError(f'family file {path}: row {bad[0] + 1}, column {c}: '
                             f'{df[c].iloc[bad[0]]!r} is not a positive number')
        out[c] = v
    return out


def resolve(spec: str, seed: int) -> dict:
    """'thesis' | 'random:N' | a CSV/Parquet path -> {column: array}."""
    if spec == 'thesis':
        return thesis()
    if spec.startswith('random:'):
        try:
            n = int(spec.split(':', 1)[1])
        except ValueError:
            n = 0
        if n < 1:
            raise UsageError(f'family {spec!r}: expected random:N with N a positive integer')
        return random(n, seed)
    if os.path.isfile(spec) or spec.endswith(('.csv', '.parquet', '.pq')):
        return from_file(spec)
    raise UsageError(f'family {spec!r}: expected thesis, random:N or a CSV/Parquet file')


def plant_params(base: dict, m: dict) -> dict:
    """Plant parameter dict of one variant: ``base`` (nominal, dotted keys) times the
    multipliers ``m`` (a mapping with the COLUMNS)."""
    split = float(m.get('leak_split', 1.0))
    b = dict(base)
    if split != 1.0:
        cp, cc, cr = (base[k] for k in ('plant.pump.C_p', 'plant.cylinder.C_c', 'plant.pump.C_r'))
        c_eq = cp + cc + cr / 2.0
        k = (c_eq - split * cr / 2.0) / (cp + cc)
        if k <= 0:
            raise ValueError(f'leak_split {split}: the external leakage alone exceeds C_eq '
                             f'(at most {2 * c_eq / cr:.3g})')
        b['plant.pump.C_p'], b['plant.cylinder.C_c'] = cp * k, cc * k
        b['plant.pump.C_r'] = cr * split
    out = scaled_params(b, [m[c] for c in NAMES])
    f = float(m.get('friction', 1.0))
    out['plant.friction.F_c'] = base['plant.friction.F_c'] * f
    out['plant.friction.F_s'] = base['plant.friction.F_s'] * f
    nz = float(m.get('noise', 1.0))
    for key in NOISE_KEYS:
        out[key] = base[key] * nz
    return out
