"""Two campaign folders compared run by run: did a change move any figure, and by how much.
Two sets of campaigns (scripts/campaign with several scenarios or --seeds) are compared
campaign by campaign, matched by folder name (core.sim.campaign_set.campaign_folder), with the
pass counts summed per scenario.

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

from .campaign_set import scenario_of

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


def _first(items: list, text=str) -> str:
    """The first ten of ``items`` as ``text`` writes them, ' ...' when there are more."""
    return text(items[:10]) + (' ...' if len(items) > 10 else '')


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
                lines.append(f'  {len(ids)} pass in {side} only: {_first(ids)}')
    if c.traces_differing:
        lines.append('  traces: ' + ', '.join(c.traces_differing))
    for side, ids in (('only in the first', c.only_a), ('only in the second', c.only_b)):
        if ids:
            lines.append(f'  {len(ids)} runs {side}: {_first(ids)}')
    return lines


@dataclass
class SetComparison:
    pairs: list                            # (campaign folder name, Comparison) in both
    only_a: list = field(default_factory=list)      # campaign folder names in a only
    only_b: list = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return not (self.only_a or self.only_b) and all(c.identical for _, c in self.pairs)


def campaigns(folder: str) -> dict:
    """{name: path} of the campaign folders of a set (sub-folders holding results.parquet);
    {} for a single campaign folder or anything else."""
    if not os.path.isdir(folder) or os.path.isfile(os.path.join(folder, 'results.parquet')):
        return {}
    return {name: os.path.join(folder, name) for name in sorted(os.listdir(folder))
            if os.path.isfile(os.path.join(folder, name, 'results.parquet'))}


def compare_sets(a: dict, b: dict) -> SetComparison:
    """Two sets as :func:`campaigns` lists them, campaign by campaign."""
    return SetComparison([(n, compare(a[n], b[n])) for n in a if n in b],
                         sorted(set(a) - set(b)), sorted(set(b) - set(a)))


def set_summary(c: SetComparison) -> list[str]:
    """Lines for a terminal: the verdict, each campaign that moved, then the runs passed per
    scenario summed over its seeds (first -> second; lost: pass in the first only)."""
    runs = sum(x.runs for _, x in c.pairs)
    moved = [(n, x) for n, x in c.pairs if not x.identical]
    lines = [f'identical: {len(c.pairs)} campaigns, {runs} runs' if c.identical else
             f'different: {len(moved)} of {len(c.pairs)} campaigns moved ({runs} runs)']
    for n, x in moved:
        cols = sorted(x.differing)
        line = (f'  {n}: {len(cols)} of {x.columns} columns' +
                (f' ({", ".join(cols)})' if 0 < len(cols) <= 4 else '') +
                f', {len(x.traces_differing)} of {x.traces} trace arrays')
        if x.passed:
            line += f'; passed {x.passed[0]} -> {x.passed[1]}'
            if x.pass_only_a:
                line += f', lost {_first(x.pass_only_a)}'
            if x.pass_only_b:
                line += f', gained {_first(x.pass_only_b)}'
        if x.only_a or x.only_b:
            line += f'; runs in one only: {len(x.only_a)} / {len(x.only_b)}'
        lines.append(line)
    totals = {}
    for n, x in c.pairs:
        if x.passed:
            t = totals.setdefault(scenario_of(n), [0, 0, 0, 0, 0])
            t[0] += x.passed[0]
            t[1] += x.passed[1]
            t[2] += len(x.pass_only_a)
            t[3] += len(x.pass_only_b)
            t[4] += 1
    if totals:
        lines.append('runs passed per scenario, summed over its campaigns (first -> second):')
        lines += [f'  {name}: {t[0]} -> {t[1]} (lost {t[2]}, gained {t[3]}; {t[4]} campaigns)'
                  for name, t in totals.items()]
    for side, names in (('only in the first', c.only_a), ('only in the second', c.only_b)):
        if names:
            lines.append(f'  {len(names)} campaigns {side}: {_first(names, ", ".join)}')
    return lines
