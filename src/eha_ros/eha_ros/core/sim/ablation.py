"""Ablation of the estimator's stages (issue 44): the campaigns with every stage on, then with
each stage switched off in turn, on the same family and seeds; a stage earns its place when
switching it off costs passed runs or worsens a spec's worst figure.

A stage is switched off by leaving it out of estimator.stages (:data:`STAGES`). A knob (an
estimator.* number) is judged the same way with its value changed (:func:`knob_variants`: a
knob whose every value changes nothing is a candidate for removal). Each variant, a name and
its estimator.* overrides, is a campaign set (core.sim.campaign_set) of the scenarios with the
overrides added to each scenario's own, under DIR/<name>/. The table compares each variant's
summary with 'all_on'.
"""
from __future__ import annotations

import math
import os

import yaml

from ..config.cli import UsageError
from ..estimator.params import DEFAULT_STAGES, STAGES as ESTIMATOR_STAGES
from ..io.report import write_json

# stage -> the estimator.* override that switches it off: estimator.stages without it (each
# default stage of the default chambers structure, core.estimator.params.STAGES)
STAGES = {stage: {'estimator.stages': [s for s in DEFAULT_STAGES if s != stage]}
          for stage in DEFAULT_STAGES if ESTIMATOR_STAGES[stage].structure in (None, 'chambers')}
BASE = 'all_on'
# the scenarios: what the estimator is for (tracking, load, stiffness) and its faults,
# and since 2026-12-01 drift_loaded (a sensor drift under a held load: the flow state's report)
SCENARIOS = ('step', 'load_step', 'sine', 'stiffness', 'sensor_fault', 'sensor_stuck',
             'false_alarm', 'drift_loaded')


def parse_stages(text: str | None) -> list[str]:
    """Stage names of a comma list (None: all of :data:`STAGES`); UsageError for an unknown
    one."""
    if text is None:
        return list(STAGES)
    names = [s.strip() for s in text.split(',') if s.strip()]
    bad = [s for s in names if s not in STAGES]
    if bad or not names:
        raise UsageError(f'--stages {text!r}: expected a comma list of {", ".join(STAGES)}')
    return list(dict.fromkeys(names))


def knob_variants(texts: list) -> dict:
    """``--vary`` texts 'KEY=V1,V2' -> {'KEY=V1': {'estimator.KEY': V1}, ...}: KEY an
    estimator.* parameter (the prefix may be left out), each value a YAML scalar or list;
    UsageError for a malformed text."""
    out = {}
    for text in texts or []:
        key, eq, values = text.partition('=')
        key = key.strip()
        if not eq or not key or not values.strip():
            raise UsageError(f'--vary {text!r}: expected KEY=V1,V2 (an estimator.* parameter '
                             f'and the values to try)')
        full = key if key.startswith('estimator.') else 'estimator.' + key
        try:
            vals = yaml.safe_load(f'[{values}]')
        except yaml.YAMLError:
            raise UsageError(f'--vary {text!r}: the values are not a YAML list') from None
        for v in vals:
            label = f'[{", ".join(map(str, v))}]' if isinstance(v, list) else v
            out[f'{full[len("estimator."):]}={label}'] = {full: _number(v)}
    return out


def _number(v):
    """A YAML 1.1 string that is a number (1e-5) as that number, also in a list; anything
    else as it is. (A params file or -p stays strict, with a hint, as rcl reads it:
    core.config.params; --vary is read by this tool alone, which writes the number into its
    scenario files.)"""
    if isinstance(v, list):
        return [_number(x) for x in v]
    if isinstance(v, str):
        for kind in (int, float):
            try:
                return kind(v)
            except ValueError:
                pass
    return v


def scenario_files(scenarios: list, stage: str, folder: str,
                   overrides: dict | None = None) -> list[str]:
    """Each scenario written to ``folder`` as YAML with the variant's overrides (default: stage
    ``stage``'s) added to its own ('all_on': unchanged); a scenario that already sets one of
    those keys is refused."""
    from . import scenarios as SC
    os.makedirs(folder, exist_ok=True)
    paths = []
    for name in scenarios:
        scn = SC.load(name)
        doc = {k: v for k, v in scn.as_dict().items() if k != 'duration'}
        over = STAGES.get(stage, {}) if overrides is None else overrides
        extra = {f'estimator:{k}': v for k, v in over.items()}
        clash = sorted(set(extra) & set(doc['overrides']))
        if clash:
            raise UsageError(f'scenario {scn.name} sets {", ".join(clash)} itself: variant '
                             f'{stage} cannot change it')
        doc['overrides'] = {**doc['overrides'], **extra}
        doc['description'] = (doc['description'] + f' [ablation: {stage}]').strip()
        path = os.path.join(folder, f'{scn.name}.yaml')
        with open(path, 'w', encoding='utf-8') as f:
            yaml.safe_dump(doc, f, sort_keys=False)
        paths.append(path)
    return paths


def check_overrides(variants: dict) -> None:
    """Every variant's overrides ({name: overrides}) load (names, types, cross-key checks)
    before any run starts."""
    from ..config.params import ParamError
    from .batch import nominal_params
    for name, over in variants.items():
        try:
            nominal_params(overrides={f'estimator:{k}': v for k, v in over.items()})
        except ParamError as err:
            raise UsageError(f'{name}: {err}') from None


def run(variants: dict, scenarios: list, family: str, seeds: list, out: str, client,
        log=print, progress: bool = True) -> dict:
    """'all_on' and each variant ({name: overrides}; a stage off: STAGES[stage]): a campaign
    set each under ``out``/<name>/ (kept and resumed like a set); returns the table (also
    ``out``/ablation.json, .md)."""
    from .campaign_set import run_set
    check_overrides(variants)
    summaries = {}
    for stage, over in [(BASE, {})] + list(variants.items()):
        d = os.path.join(out, stage)
        what = ('every stage on' if stage == BASE else 'switched off' if stage in STAGES
                else ', '.join(f'{k} = {v}' for k, v in over.items()))
        log(f'ablation: {stage} ({what})')
        files = scenario_files(scenarios, stage, os.path.join(d, 'scenarios'), over)
        summaries[stage] = run_set(files, family, seeds, d, client, log=log, progress=progress,
                                   report=False)
    from . import scenarios as SC
    result = table(summaries, family, seeds, {n: SC.load(n).specs for n in scenarios},
                   variants)
    write_json(os.path.join(out, 'ablation.json'), result)
    with open(os.path.join(out, 'ablation.md'), 'w', encoding='utf-8') as f:
        f.write('\n'.join(markdown(result)) + '\n')
    return result


def table(summaries: dict, family: str, seeds: list, specs: dict,
          variants: dict | None = None) -> dict:
    """{'family', 'seeds', 'scenarios', 'stages', 'rows': {stage: {scenario: cell}}}: a cell
    holds the passed runs summed over the seeds (and all_on's), the worst seed's count, and
    each spec's worst figure with its relative change from all_on and whether it is worse
    (``specs``: {scenario: its specs}, core.sim.campaign_set.summarize's figures)."""
    from .campaign_set import _worse
    base = summaries[BASE]['scenarios']
    rows = {}
    for stage, summary in summaries.items():
        row = {}
        for name, s in summary['scenarios'].items():
            b = base[name]
            cell_specs = {}
            for metric, w in s['specs'].items():
                bw = b['specs'].get(metric, {}).get('worst')
                ch = _change(w['worst'], bw)
                cell_specs[metric] = dict(
                    worst=w['worst'], base=bw, failed=w['failed'], change=ch,
                    worse=ch is not None and _worse(w['worst'], bw, specs[name][metric]))
            row[name] = dict(passed=sum(v['passed'] for v in s['per_seed'].values()),
                             runs=sum(v['runs'] for v in s['per_seed'].values()),
                             base_passed=sum(v['passed'] for v in b['per_seed'].values()),
                             worst_seed_passed=s['worst_passed'], specs=cell_specs)
        rows[stage] = row
    return dict(family=family, seeds=list(seeds), scenarios=list(base),
                stages={k: (variants or STAGES).get(k, {}) for k in summaries}, rows=rows)


def _change(v, base):
    """Relative change of a worst figure from its all_on value (None when undefined)."""
    if v is None or base is None or not (math.isfinite(v) and math.isfinite(base)) or base == 0:
        return None
    return v / base - 1.0


def verdict(result: dict, stage: str, tolerance: float = 0.05) -> str:
    """'earns' when switching ``stage`` off (or a knob's variant) costs a passed run in some
    scenario or makes a spec's worst figure worse by more than ``tolerance`` (relative: beyond
    noise); 'harmful' when off only gains passed runs; 'no effect' otherwise."""
    cells = result['rows'][stage].values()
    if any(c['passed'] < c['base_passed'] for c in cells) or any(
            s['worse'] and abs(s['change']) > tolerance for c in cells
            for s in c['specs'].values()):
        return 'earns'
    if any(c['passed'] > c['base_passed'] for c in cells):
        return 'harmful'
    return 'no effect'


def markdown(result: dict) -> list[str]:
    """The ablation table: per stage and scenario, passed (change from all_on)."""
    names = result['scenarios']
    lines = [f'# Estimator ablation: {result["family"]}, seeds '
             f'{", ".join(str(s) for s in result["seeds"])}', '',
             'Passed runs summed over the seeds; in brackets the change from every stage on. '
             'Verdict (core.sim.ablation.verdict): earns = off costs a passed run or worsens a '
             'worst figure by more than 5 %; harmful = off only gains passed runs.', '',
             '| stage off / knob | ' + ' | '.join(names) + ' | verdict |',
             '| --- | ' + ' | '.join('---' for _ in names) + ' | --- |']
    for stage, row in result['rows'].items():
        cells = []
        for n in names:
            c = row[n]
            d = c['passed'] - c['base_passed']
            cells.append(f'{c["passed"]}/{c["runs"]}' + (f' ({d:+d})' if stage != BASE else ''))
        v = '' if stage == BASE else verdict(result, stage)
        lines.append(f'| {stage} | ' + ' | '.join(cells) + f' | {v} |')
    lines += ['', '## Worst figure per spec (change from every stage on)', '']
    for n in names:
        lines.append(f'### {n}')
        metrics = sorted({m for row in result['rows'].values() for m in row[n]['specs']})
        lines.append('| stage off / knob | ' + ' | '.join(metrics) + ' |')
        lines.append('| --- | ' + ' | '.join('---' for _ in metrics) + ' |')
        for stage, row in result['rows'].items():
            cells = []
            for m in metrics:
                s = row[n]['specs'].get(m)
                if s is None or s['worst'] is None:
                    cells.append('')
                else:
                    ch = '' if s['change'] is None or stage == BASE else \
                        f' ({100 * s["change"]:+.0f} %)'
                    cells.append(f'{s["worst"]:.4g}{ch}')
            lines.append(f'| {stage} | ' + ' | '.join(cells) + ' |')
        lines.append('')
    return lines
