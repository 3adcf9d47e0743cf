"""A set of campaigns: several scenarios, each on several noise seeds, on one Dask cluster,
and the table of pass counts per seed (scripts/campaign SCENARIO... --seeds A-B).

A campaign figure from one seed is one sample of the sensor noise (and, for ``random:N``, of
the family drawn with that seed). The figures of record come from the held-out seeds
RECORD_SEEDS, which no tuning reads; TUNING_SEEDS are the ones tuning may look at
(docs/measurements.md, "Seeds").

Output in DIR: one campaign folder per scenario and seed (``<scenario>-seed<S>/``, as
core.sim.campaign writes it), ``summary.json`` and ``summary.md``: per scenario the runs
passed per seed, the worst seed, the worst value of every spec over the seeds, and every
failing run named with its plant and the specs it failed.
"""
from __future__ import annotations

import json
import math
import os
import time

from ..config.cli import UsageError
from ..io.report import write_json
from .campaign import RECORD_SEEDS, TUNING_SEEDS, run_campaign, seed_role
from .scenarios import BESIDE


def parse_seeds(text: str) -> list[int]:
    """'101-105', '1,3,7', 'record' (RECORD_SEEDS) or 'tuning' (TUNING_SEEDS) -> seeds;
    UsageError (one line) otherwise."""
    named = {'record': RECORD_SEEDS, 'held-out': RECORD_SEEDS, 'tuning': TUNING_SEEDS}
    if text in named:
        return list(named[text])
    out = []
    try:
        for part in text.split(','):
            a, _, b = part.strip().partition('-')
            lo, hi = int(a), int(b) if b else int(a)
            if lo < 0 or hi < lo:
                raise ValueError
            out += range(lo, hi + 1)
    except ValueError:
        raise UsageError(f'--seeds {text!r}: expected A-B, a comma list of seeds and ranges '
                         f'(non-negative, ascending), "record" or "tuning"') from None
    return sorted(set(out))


def campaign_folder(out: str, scenario: str, seed: int) -> str:
    """The folder of one scenario on one seed in the set DIR ``out``."""
    return os.path.join(out, f'{scenario}-seed{seed}')


def scenario_of(folder_name: str) -> str:
    """The scenario of a campaign folder's name (:func:`campaign_folder`'s last part)."""
    return folder_name.rsplit('-seed', 1)[0]


def run_set(scenarios: list, family: str, seeds: list, out: str, client, log=print,
            progress: bool = True, report: bool = True, config_dir: str | None = None,
            plant_params: str | None = None, oracle: bool = False) -> dict:
    """Each scenario on each seed into DIR/<scenario>-seed<S>/ with the given Dask client;
    a folder that already holds a finished campaign is kept (reruns finish an interrupted
    set), an unfinished one is resumed (with the plant it started with; ``plant_params``: the
    family's centre of the new ones, run_campaign; ``oracle``: their estimator is given the
    plant parameters). Returns the summary (also DIR/summary.json, .md)."""
    from . import scenarios as SC
    loaded = [SC.load(s) for s in scenarios]             # unknown scenarios fail first
    names = [s.name for s in loaded]
    if len(set(names)) != len(names):
        raise UsageError(f'scenarios {", ".join(scenarios)}: a scenario given twice')
    for scn in loaded:                                  # a kept folder is of the same estimator
        want = scn.oracle or oracle
        for seed in seeds:
            d = campaign_folder(out, scn.name, seed)
            info = _info(d)
            if info is not None and bool((info.get('scenario') or {}).get('oracle')) != want:
                raise UsageError(f'{d} holds a campaign {"without" if want else "with"} '
                                 f'--oracle: give another --out')
    os.makedirs(out, exist_ok=True)
    t0 = time.monotonic()
    folders = {}
    for scn, name in zip(scenarios, names):
        for seed in seeds:
            d = campaign_folder(out, name, seed)
            folders[(name, seed)] = d
            info = _info(d)
            if info is not None and info.get('complete'):
                log(f'campaign set: {name} seed {seed}: done before, kept ({d})')
                continue
            resume = d if info is not None else None
            run_campaign(None if resume else scn, family, seed, out=None if resume else d,
                         resume=resume, client=client, progress=progress, report=report,
                         config_dir=config_dir, log=log,
                         plant_params=None if resume else plant_params,
                         oracle=oracle and not resume)
    summary = summarize(folders, family)
    summary['wall_s'] = round(time.monotonic() - t0, 1)
    write_json(os.path.join(out, 'summary.json'), summary, True)
    with open(os.path.join(out, 'summary.md'), 'w', encoding='utf-8') as f:
        f.write('\n'.join(markdown(summary)) + '\n')
    return summary


def _info(folder: str) -> dict | None:
    try:
        with open(os.path.join(folder, 'campaign.json')) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def summarize(folders: dict, family: str) -> dict:
    """{'family', 'seeds', 'scenarios': {name: {...}}} from finished campaign folders keyed
    by (scenario, seed)."""
    import pandas as pd
    from .family import COLUMNS
    from .report import spec_summary
    seeds = sorted({s for _, s in folders})
    out = {'family': family, 'seeds': seeds,
           'roles': {str(s): seed_role(s) for s in seeds}, 'scenarios': {}}
    for name in dict.fromkeys(n for n, _ in folders):
        per_seed, failures, specs_worst, oracle = {}, [], {}, False
        for seed in seeds:
            d = folders[(name, seed)]
            info = _info(d) or {}
            oracle = oracle or bool((info.get('scenario') or {}).get('oracle'))
            df = pd.read_parquet(os.path.join(d, 'results.parquet'))
            specs = (info.get('scenario') or {}).get('specs') or {}
            per_seed[str(seed)] = dict(runs=int(len(df)), passed=int(df['passed'].sum()),
                                       folder=d)
            for s in spec_summary(df, specs):
                w = specs_worst.setdefault(s['metric'], dict(requirement=s['requirement'],
                                                             worst=None, seed=None, run=None,
                                                             failed=0))
                w['failed'] += s['failed']
                # inf is a value (a fault never detected, the worst there is); NaN is none
                if not math.isnan(s['worst']) and (w['worst'] is None or _worse(
                        s['worst'], w['worst'], specs[s['metric']])):
                    w.update(worst=s['worst'], seed=seed, run=s['worst_run'])
            for r in df[~df['passed'].astype(bool)].to_dict('records'):
                failures.append(dict(
                    seed=seed, run_id=int(r['run_id']), failed_specs=str(r['failed_specs']),
                    error=str(r.get('error', '') or ''),
                    plant={c: round(float(r[c]), 4) for c in COLUMNS if c in r},
                    values={c: _val(r.get(c)) for m in str(r['failed_specs']).split(',')
                            for c in (m,) + BESIDE.get(m, ()) if c in r}))
        passed = [v['passed'] for v in per_seed.values()]
        runs = [v['runs'] for v in per_seed.values()]
        worst = min(per_seed, key=lambda s: (per_seed[s]['passed'] / max(1, per_seed[s]['runs'])))
        out['scenarios'][name] = dict(
            per_seed=per_seed, worst_seed=int(worst),
            worst_passed=per_seed[worst]['passed'], runs=runs[0] if runs else 0,
            all_passed=all(p == r for p, r in zip(passed, runs)),
            specs=specs_worst, failures=failures, oracle=oracle)
    return out


def _worse(a: float, b: float, spec) -> bool:
    """Is value a worse than b under the spec's form (a maximum: larger; a minimum: smaller)?"""
    cases = spec if isinstance(spec, list) else [spec]
    form = next(k for k in cases[0] if k != 'where')
    return a < b if form.startswith('min') else a > b


def _val(v):
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def markdown(summary: dict) -> list[str]:
    """summary.md: the pass table (scenario x seed), then the failures of every scenario."""
    from .report import fmt
    seeds = summary['seeds']
    roles = sorted(set(summary['roles'].values()))
    md = [f'# Campaign set: {summary["family"]}, seeds {", ".join(map(str, seeds))}', '',
          f'Seed roles: {", ".join(roles)} (held-out seeds {RECORD_SEEDS[0]}-{RECORD_SEEDS[-1]} '
          f'give the figures of record; tuning seeds {TUNING_SEEDS[0]}-{TUNING_SEEDS[-1]}).', '']
    if any(s.get('oracle') for s in summary['scenarios'].values()):
        md += ['(oracle): the estimator was given each run\'s plant parameters (campaign '
               '--oracle, core.sim.oracle).', '']
    md += ['| scenario | runs | ' + ' | '.join(f'seed {s}' for s in seeds) +
           ' | worst seed | worst figures |',
           '|' + '---|' * (len(seeds) + 4)]
    for name, s in summary['scenarios'].items():
        figs = '; '.join(f'{m} {fmt(m, w["worst"]) if w["worst"] is not None else "-"} '
                         f'({w["requirement"]})' for m, w in s['specs'].items())
        label = f'{name} (oracle)' if s.get('oracle') else name
        md.append(f'| {label} | {s["runs"]} | ' +
                  ' | '.join(str(s['per_seed'][str(x)]['passed']) for x in seeds) +
                  f' | {s["worst_seed"]} ({s["worst_passed"]}) | {figs} |')
    md.append('')
    for name, s in summary['scenarios'].items():
        if not s['failures']:
            continue
        md += [f'## {name}: {len(s["failures"])} failing runs', '',
               '| seed | run | failed specs | values | plant (x nominal) |',
               '|---|---|---|---|---|']
        for f in s['failures']:
            vals = ', '.join(f'{m} {fmt(m, v)}' for m, v in f['values'].items() if v is not None)
            plant = ' '.join(f'{c}={v:.3g}' for c, v in f['plant'].items() if v != 1.0)
            md.append(f'| {f["seed"]} | {f["run_id"]} | {f["failed_specs"]} | '
                      f'{vals or f["error"][:80]} | {plant or "nominal"} |')
        md.append('')
    return md
