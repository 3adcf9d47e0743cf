"""Two campaign folders compared run by run: did a change move any figure, and by how much.

Rows are matched by run_id; every column of results.parquet present in both is compared
exactly (NaN equals NaN), the wall-time bookkeeping aside, and every array of traces.npz. A
refactoring must give "identical"; a tuning change lists what moved, and which runs pass on one
side only (the stack beside its oracle, core.sim.oracle: the runs lost to learning the
plant's parameters).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

# columns that measure the machine, not the loop
TIMING = ('wall_s', 'elapsed_s', 'worker', 'duration_s')


@dataclass
class Comparison:
    runs: int                              # run_ids in both
    only_a: list = field(default_factory=list)
    only_b: list = field(default_factory=list)
    columns: int = 0                       # columns compared
    differing: dict = field(default_factory=dict)   # column -> (runs differing, max |a - b|)
    traces: int = 0                        # trace arrays compared
    traces_differing: list = field(default_factory=list)
    passed: tuple = ()                     # runs passed in a, in b (both have `passed`)
    pass_only_a: list = field(default_factory=list)     # run_ids passing in a, failing in b
    pass_only_b: list = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return not (self.only_a or self.only_b or self.differing or self.traces_differing)


def _results(folder: str):
    import pandas as pd
    from ..config.params import ParamError
    path = os.path.join(folder, 'results.parquet')
    if not os.path.isfile(path):
        raise ParamError(f'{folder}: no results.parquet: expected a campaign folder '
                         f'(scripts/campaign --out)')
    return pd.read_parquet(path).set_index('run_id', drop=False).sort_index()


def _same(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Element-wise exact equality, NaN equal to NaN (numbers); == otherwise."""
    if x.dtype.kind in 'fc' and y.dtype.kind in 'fc':
        return (x == y) | (np.isnan(x) & np.isnan(y))
    return np.array([p == q or (p != p and q != q) for p, q in zip(x, y)], bool)


def compare(folder_a: str, folder_b: str) -> Comparison:
    a, b = _results(folder_a), _results(folder_b)
    common = a.index.intersection(b.index)
    out = Comparison(len(common), sorted(set(a.index) - set(b.index)),
                     sorted(set(b.index) - set(a.index)))
    a, b = a.loc[common], b.loc[common]
    if 'passed' in a.columns and 'passed' in b.columns:
        pa, pb = a['passed'].astype(bool), b['passed'].astype(bool)
        out.passed = (int(pa.sum()), int(pb.sum()))
        out.pass_only_a = [int(i) for i in common[(pa & ~pb).to_numpy()]]
        out.pass_only_b = [int(i) for i in common[(pb & ~pa).to_numpy()]]
    for col in a.columns:
        if col in TIMING or col not in b.columns:
            continue
        out.columns += 1
        x, y = a[col].to_numpy(), b[col].to_numpy()
        same = _same(x, y)
        if not same.all():
            gap = float(np.nanmax(np.abs(x[~same] - y[~same]))) \
                if x.dtype.kind in 'fci' and y.dtype.kind in 'fci' else float('nan')
            out.differing[col] = (int((~same).sum()), gap)
    ta, tb = (os.path.join(f, 'traces.npz') for f in (folder_a, folder_b))
    if os.path.isfile(ta) and os.path.isfile(tb):
        with np.load(ta) as A, np.load(tb) as B:
            for name in A.files:
                out.traces += 1
                if name not in B.files or A[name].shape != B[name].shape or \
                        not np.array_equal(A[name], B[name], equal_nan=True):
                    out.traces_differing.append(name)
    return out


def summary(c: Comparison) -> list[str]:
    """Lines for a terminal: the verdict first."""
    head = (f'identical: {c.runs} runs, {c.columns} columns, {c.traces} trace arrays'
            if c.identical else
            f'different: {len(c.differing)} of {c.columns} columns over {c.runs} runs, '
            f'{len(c.traces_differing)} of {c.traces} trace arrays')
    lines = [head]
    lines += [f'  {col}: {n} of {c.runs} runs differ, largest |a - b| {gap:.6g}'
              for col, (n, gap) in sorted(c.differing.items())]
    if c.passed and not c.identical:
        lines.append(f'  pass count: {c.passed[0]} in the first, {c.passed[1]} in the second; '
                     f'{c.runs - c.passed[0] - len(c.pass_only_b)} fail in both')
        for side, ids in (('the first', c.pass_only_a), ('the second', c.pass_only_b)):
            if ids:
                lines.append(f'  {len(ids)} pass in {side} only: {ids[:10]}' +
                             (' ...' if len(ids) > 10 else ''))
    if c.traces_differing:
        lines.append('  traces: ' + ', '.join(c.traces_differing))
    for side, ids in (('only in the first', c.only_a), ('only in the second', c.only_b)):
        if ids:
            lines.append(f'  {len(ids)} runs {side}: {ids[:10]}' + (' ...' if len(ids) > 10
                                                                     else ''))
    return lines
