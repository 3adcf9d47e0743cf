"""Campaign report: report.md with figures (matplotlib, Agg) next to it.

Figures of merit (spec table, normalised excess, worst runs, sweep comparison) are plain
functions of the results frame; the plot_* functions only draw them.

- envelope.png      min/max band of truth - reference (truth for load scenarios) over every
                    run, the pointwise median, the run nearest the nominal plant, failing runs
                    in red; step: the T_up/T_low step envelope (eqs. 4.62/4.63) scaled to the
                    step, the settling band and the steady-error band
- stiffness.png     |F|/|x| per frequency per plant vs the linear prediction and 1/|M| (eq. 4.60)
- sweep.png         gain/phase per plant vs the linear prediction of the same plant, differences
- relative.png      each max_rel spec: the metric against the column it is relative to
- scatter.png       each metric against each multiplier that varies (failing runs red)
"""
from __future__ import annotations

import math
import os
import re

import numpy as np

MULTIPLIERS = ('C_eq', 'D_p', 'beta', 'k_T', 'k_E', 'friction', 'noise', 'leak_split')
ID_COLUMNS = ('run_id', 'seed', 'noise_seed', 'passed', 'failed_specs', 'error', 'wall_s',
              'plant_s')
HEADLINE = {
    'step': ('overshoot_pct', 'settling_s', 'steady_error_m', 'estimate_error_m'),
    'load_step': ('peak_deviation_m', 'steady_error_m', 'estimate_error_m'),
    'sweep': ('gain_db_1hz', 'gain_db_7hz', 'phase_deg_7hz', 'gain_db_15hz'),
    'stiffness': ('stiffness_kn_per_mm_1hz', 'stiffness_kn_per_mm_4hz',
                  'stiffness_kn_per_mm_7hz'),
    'sine': ('rmse_ratio', 'estimate_rmse_m', 'tracking_rmse_m'),
}
LOAD_KINDS = ('load_step', 'stiffness')
MAX_SCATTER_METRICS = 8
RED, GREY, BLUE = '#d62728', '0.55', '#1f77b4'


# ------------------------------------------------------------------------------ units
def metric_unit(name: str) -> tuple[float, str]:
    """(scale from SI, unit label) for a metric column name."""
    n = name.lower()
    if n.endswith('_pct'):
        return 1.0, '%'
    if 'kn_per_mm' in n:
        return 1.0, 'kN/mm'
    if '_db' in n:
        return 1.0, 'dB'
    if '_deg' in n:
        return 1.0, 'deg'
    if n.endswith('_m'):
        return 1e3, 'mm'
    if n.endswith('_s'):
        return 1.0, 's'
    if n.endswith('_ticks'):
        return 1.0, 'ticks'
    if 'command' in n:
        return 1.0, 'rad/s'
    return 1.0, ''


def label(name: str) -> str:
    u = metric_unit(name)[1]
    return f'{name} ({u})' if u else name


def fmt(name: str, value) -> str:
    """A metric value in display units, 4 significant digits."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not math.isfinite(v):
        return str(v)
    s, u = metric_unit(name)
    return f'{v * s:.4g} {u}'.rstrip()


# ------------------------------------------------------------------------------ figures of merit
def spec_limit(row, spec) -> float:
    """The limit a spec puts on one row (scenarios.limit: the case that applies to the row;
    max_rel / min_rel = factor x row[to] + offset)."""
    from .scenarios import limit
    return limit(spec, row)[1]


def requirement(metric: str, s) -> str:
    """'<= 5 %', '>= 49 kN/mm', '<= 1.25 x lin_peak_deviation_m + 0.05 mm'; a list of cases
    as 'where C: ...; else ...'."""
    if isinstance(s, list):
        return '; '.join((f'where {c["where"]}: ' if 'where' in c else 'else ' if i else '') +
                         requirement(metric, {k: v for k, v in c.items() if k != 'where'})
                         for i, c in enumerate(s))
    form, v = next(iter(s.items()))
    if form.endswith('_rel'):
        off = v.get('offset', 0.0)
        tail = f' + {fmt(metric, off)}' if off else ''
        return f'{"<=" if form == "max_rel" else ">="} {v.get("factor", 1.0):g} x {v["to"]}{tail}'
    return f'{"<=" if form == "max" else ">="} {fmt(metric, v)}'


def normalised_excess(row, specs: dict) -> tuple[float, str]:
    """Largest normalised spec excess of one row (x/limit - 1 for max, 1 - x/limit for min;
    > 0: failed) and its spec; a run that raised: (inf, 'error')."""
    if str(row.get('error', '') or ''):
        return math.inf, 'error'
    from .scenarios import excess
    if not specs:
        return -math.inf, ''
    return excess(row, specs)


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def excess_frame(results, specs: dict):
    """results with columns 'excess' and 'worst_spec' (see normalised_excess)."""
    df = results.copy()
    vals = [normalised_excess(r, specs) for r in df.to_dict('records')]
    df['excess'] = [v[0] for v in vals]
    df['worst_spec'] = [v[1] for v in vals]
    return df


def worst_runs(results, specs: dict, n: int = 10):
    """The n runs with the largest normalised excess (failing first), excess_frame columns."""
    df = excess_frame(results, specs)
    df['_fail'] = ~df['passed'].astype(bool)
    df = df.sort_values(['_fail', 'excess', 'run_id'], ascending=[False, False, True])
    return df.drop(columns='_fail').head(n)


def spec_summary(results, specs: dict) -> list[dict]:
    """Per spec: requirement, runs evaluated, passed, worst value and its run, median value."""
    from .scenarios import limit
    out = []
    rows = results.to_dict('records')
    for metric, s in specs.items():
        x = (results[metric].to_numpy(float) if metric in results
             else np.full(len(results), np.nan))
        forms = [limit(s, r) for r in rows]
        lim = np.array([f[1] for f in forms], float)
        is_max = np.array([f[0] == 'max' for f in forms], bool)
        ok = np.isfinite(x) & np.isfinite(lim) & np.where(is_max, x <= lim, x >= lim)
        finite = np.isfinite(x)
        if finite.any():
            rel = isinstance(s, list) or next(iter(s)).endswith('_rel')
            if rel:                          # per-row limits: the largest normalised excess
                with np.errstate(divide='ignore', invalid='ignore'):
                    e = np.where(is_max, x / lim - 1, 1 - x / lim)
                i = int(np.nanargmax(np.where(finite, e, -np.inf)))
            else:
                i = int(np.nanargmax(x) if is_max[0] else np.nanargmin(x))
            worst, worst_id = float(x[i]), int(results['run_id'].iloc[i])
            median = float(np.nanmedian(x))
        else:
            worst, worst_id, median = math.nan, -1, math.nan
        out.append(dict(metric=metric, requirement=requirement(metric, s),
                        evaluated=int(finite.sum()), passed=int(ok.sum()),
                        failed=int(len(x) - ok.sum()), worst=worst, worst_run=worst_id,
                        median=median))
    return out


def varying(results, columns=MULTIPLIERS + ('seed',)) -> list[str]:
    """The multiplier columns (and seed) that take more than one value."""
    return [c for c in columns if c in results and
            np.unique(results[c].to_numpy(float)[np.isfinite(results[c].to_numpy(float))]).size > 1]


def nearest_nominal(results) -> int:
    """run_id of the run whose multipliers are nearest 1 (sum of |log m|)."""
    cols = [c for c in MULTIPLIERS if c in results]
    if not cols:
        return int(results['run_id'].iloc[0])
    m = np.abs(np.log(np.clip(results[cols].to_numpy(float), 1e-12, None))).sum(axis=1)
    return int(results['run_id'].iloc[int(np.nanargmin(m))])


def metric_columns(results, info: dict) -> list[str]:
    """Metrics for the scatter grid: the spec metrics, then the kind's headline figures, then
    other numeric figures (no multipliers, ids, linear predictions), at most
    MAX_SCATTER_METRICS."""
    scn = info.get('scenario', {})
    specs = list((scn.get('specs') or {}).keys())
    head = list(HEADLINE.get(scn.get('kind', ''), ()))
    skip = set(MULTIPLIERS) | set(ID_COLUMNS) | {'max_abs_command'}
    rest = [c for c in results.columns if c not in skip and not c.startswith(('lin_', 'loaded_'))
            and results[c].dtype.kind in 'fiu']
    out = []
    for c in specs + head + rest:
        if c in results and c not in out and results[c].dtype.kind in 'fiu' and \
                np.isfinite(results[c].to_numpy(float)).any():
            out.append(c)
    return out[:MAX_SCATTER_METRICS]


def _freq_of(tag: str) -> float:
    return float(tag.replace('p', '.'))


def frequency_columns(results, prefix: str) -> list[tuple[float, str]]:
    """[(f Hz, column)] of columns '<prefix>_<f>hz', sorted by f."""
    pat = re.compile(rf'^{re.escape(prefix)}_([0-9p.]+)hz$')
    out = []
    for c in results.columns:
        m = pat.match(str(c))
        if m:
            out.append((_freq_of(m.group(1)), c))
    return sorted(out)


def sweep_table(results) -> dict:
    """Nonlinear and linear gain (dB) / phase (deg) per run and frequency, (N, F) each, on the
    frequencies that have both; phase differences wrapped to (-180, 180]."""
    g = dict(frequency_columns(results, 'gain_db'))
    lg = dict(frequency_columns(results, 'lin_gain_db'))
    f = sorted(g)
    has_lin = all(x in lg for x in f) and bool(f)
    out = {'f_hz': np.asarray(f, float), 'has_linear': has_lin}
    out['gain_db'] = results[[g[x] for x in f]].to_numpy(float) if f else np.zeros((len(results), 0))
    ph = dict(frequency_columns(results, 'phase_deg'))
    out['phase_deg'] = results[[ph[x] for x in f]].to_numpy(float) if all(x in ph for x in f) \
        else np.full(out['gain_db'].shape, np.nan)
    if has_lin:
        lph = dict(frequency_columns(results, 'lin_phase_deg'))
        out['lin_gain_db'] = results[[lg[x] for x in f]].to_numpy(float)
        out['lin_phase_deg'] = results[[lph[x] for x in f]].to_numpy(float) \
            if all(x in lph for x in f) else np.full(out['gain_db'].shape, np.nan)
        out['gain_diff_db'] = out['gain_db'] - out['lin_gain_db']
        out['phase_diff_deg'] = (out['phase_deg'] - out['lin_phase_deg'] + 180.0) % 360.0 - 180.0
    return out


def stiffness_table(results) -> dict:
    """Measured and linear stiffness (kN/mm) per run and frequency, (N, F)."""
    k = dict(frequency_columns(results, 'stiffness_kn_per_mm'))
    f = sorted(k)
    out = {'f_hz': np.asarray(f, float),
           'stiffness': results[[k[x] for x in f]].to_numpy(float) if f else
           np.zeros((len(results), 0))}
    for name in ('lin_stiffness', 'lin_loaded_stiffness'):
        lk = dict(frequency_columns(results, name + '_kn_per_mm'))
        if f and all(x in lk for x in f):
            out[name] = results[[lk[x] for x in f]].to_numpy(float)
    return out


def envelope(y: np.ndarray) -> dict:
    """Pointwise min, max, median of traces (N, M), ignoring NaN."""
    with np.errstate(all='ignore'):
        return {'min': np.nanmin(y, axis=0), 'max': np.nanmax(y, axis=0),
                'median': np.nanmedian(y, axis=0)}


def trace_signal(traces: dict, kind: str) -> tuple[np.ndarray, str]:
    """(N, M) signal of the envelope plot and its label: truth for load scenarios, truth -
    reference otherwise."""
    if kind in LOAD_KINDS or 'reference' not in traces:
        return np.asarray(traces['truth'], float), 'truth x'
    return np.asarray(traces['truth'], float) - np.asarray(traces['reference'], float), \
        'truth - reference'


# ------------------------------------------------------------------------------ plots
def _plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    _plt().close(fig)
    return path


def _status(results) -> dict:
    return dict(zip(results['run_id'].astype(int), results['passed'].astype(bool)))


def plot_envelope(path, info: dict, results, traces: dict) -> str:
    """Envelope of truth - reference (or truth) with spec bounds where they apply."""
    plt = _plt()
    scn = info.get('scenario', {})
    kind, params, specs = scn.get('kind', ''), scn.get('params') or {}, scn.get('specs') or {}
    t = np.asarray(traces['t'], float)
    ids = np.asarray(traces['run_id']).astype(int)
    ok = _status(results)
    fail = np.array([not ok.get(int(i), False) for i in ids])
    nom = nearest_nominal(results)
    y, what = trace_signal(traces, kind)
    has_load = 'load' in traces and np.nanmax(np.abs(traces['load'])) > 0
    panels = 2 if (kind == 'step' or has_load) else 1
    fig, axes = plt.subplots(panels, 1, figsize=(10, 3.6 * panels + 0.6), sharex=True,
                             squeeze=False)
    axes = axes[:, 0]

    def band(ax, sig, scale, name):
        e = envelope(sig)
        ax.fill_between(t, e['min'] * scale, e['max'] * scale, color='0.8',
                        label=f'min..max over {len(sig)} runs')
        ax.plot(t, e['median'] * scale, 'k--', lw=0.9, label='pointwise median')
        for k in np.nonzero(fail)[0][:50]:
            ax.plot(t, sig[k] * scale, color=RED, lw=0.7, alpha=0.8,
                    label='failing runs' if k == np.nonzero(fail)[0][0] else None)
        j = np.nonzero(ids == nom)[0]
        if len(j):
            ax.plot(t, sig[j[0]] * scale, color=BLUE, lw=1.2,
                    label=f'run {nom} (nearest nominal)')
        ax.set_ylabel(f'{name} (mm)')
        ax.grid(True, alpha=0.4)

    if kind == 'step':
        from .linear import bounds
        a = float(params.get('amplitude', 5e-3))
        ts = float(params.get('t_step', 0.0))
        truth = np.asarray(traces['truth'], float)
        ax = axes[0]
        band(ax, truth, 1e3, 'truth x')
        after = t >= ts
        b = bounds(t=t[after] - ts)
        ax.plot(t[after], a * 1e3 * b['step_upper'], color='g', lw=1.2,
                label='T_up step (eq. 4.62)')
        ax.plot(t[after], a * 1e3 * b['step_lower'], color='m', lw=1.2,
                label='T_low step (eq. 4.63)')
        bnd = float(params.get('band', 0.02))
        ax.axhspan(a * 1e3 * (1 - bnd), a * 1e3 * (1 + bnd), color='g', alpha=0.12,
                   label=f'+-{bnd * 100:g} % settling band')
        if isinstance(specs.get('settling_s'), dict) and 'max' in specs['settling_s']:
            ax.axvline(ts + specs['settling_s']['max'], color='g', ls=':',
                       label='settling time limit')
        ax.set_title(f'{scn.get("name", kind)}: {a * 1e3:g} mm step, true position')
        ax.legend(fontsize=7, loc='lower right')
        ax = axes[1]
        band(ax, y, 1e3, 'truth - reference')
        se = specs['steady_error_m'].get('max') if isinstance(
            specs.get('steady_error_m'), dict) else None
        if se is not None:
            st = params.get('steady', [1.0, 1.5])
            ax.fill_between([ts + st[0], ts + st[1]], -se * 1e3, se * 1e3, color='g', alpha=0.25,
                            label=f'steady error +-{se * 1e3:g} mm (window)')
        lim = abs(a) * 1e3 * 2 * bnd
        ax.set_ylim(-lim, lim)
        ax.axhspan(-abs(a) * 1e3 * bnd, abs(a) * 1e3 * bnd, color='g', alpha=0.08)
        ax.set_title(f'tracking error (zoom: +-{2 * bnd * 100:g} % of the step; light green: '
                     f'settling band)')
        ax.legend(fontsize=7, loc='lower right')
    else:
        ax = axes[0]
        band(ax, y, 1e3, what)
        ax.set_title(f'{scn.get("name", kind)}: {what} over all runs')
        ax.legend(fontsize=7, loc='best')
        if panels == 2:
            ax = axes[1]
            ld = np.asarray(traces['load'], float)
            ax.plot(t, ld[0] / 1e3, 'k', lw=0.8)
            ax.set_ylabel('load force F_L (kN)')
            ax.grid(True, alpha=0.4)
            ax.set_title('external load (positive pushes towards -x)')
    axes[-1].set_xlabel('time (s)')
    return _save(fig, path)


def plot_stiffness(path, results) -> str:
    """Measured |F|/|x| per plant (failing red) vs the linear prediction and 1/|M|."""
    from .linear import bounds
    plt = _plt()
    st = stiffness_table(results)
    f = st['f_hz']
    ok = results['passed'].astype(bool).to_numpy()
    fig, ax = plt.subplots(figsize=(9, 6))
    for i in range(len(results)):
        ax.plot(f, st['stiffness'][i], '-o', ms=3, lw=0.6,
                color=GREY if ok[i] else RED, alpha=0.6 if ok[i] else 0.9)
    ax.plot([], [], '-o', color=GREY, label='nonlinear, passing')
    ax.plot([], [], '-o', color=RED, label='nonlinear, failing')
    if 'lin_stiffness' in st:
        lo, hi = np.nanmin(st['lin_stiffness'], 0), np.nanmax(st['lin_stiffness'], 0)
        ax.fill_between(f, lo, hi, color=BLUE, alpha=0.15,
                        label='linear prediction, min..max over the plants')
    if 'lin_loaded_stiffness' in st:
        ax.plot(f, np.nanmin(st['lin_loaded_stiffness'], 0), color=BLUE, ls='--',
                label='linear at the loaded leakage (C_p + C_c + C_r), smallest')
    w = np.logspace(np.log10(2 * np.pi * max(0.5, f.min() / 2 if len(f) else 0.5)),
                    np.log10(2 * np.pi * (f.max() * 2 if len(f) else 20)), 200)
    b = bounds(w=w)
    ax.plot(b['f_hz'], b['stiffness_bound_kn_per_mm'], 'k', lw=2, label='1/|M| bound (eq. 4.60)')
    ax.set_xscale('log')
    ax.set_yscale('log')
    ax.set_xlabel('frequency (Hz)')
    ax.set_ylabel('dynamic stiffness |F_L|/|x| (kN/mm)')
    ax.set_title('dynamic stiffness per plant (thesis Fig. 4.52)')
    ax.grid(True, which='both', alpha=0.4)
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_sweep(path, results) -> str:
    """Gain and phase per plant vs the linear prediction of the same plant; differences."""
    plt = _plt()
    sw = sweep_table(results)
    f = sw['f_hz']
    ok = results['passed'].astype(bool).to_numpy()
    lin = sw['has_linear']
    fig, ax = plt.subplots(2, 2, figsize=(12, 8))
    for i in range(len(results)):
        c = GREY if ok[i] else RED
        ax[0, 0].plot(f, sw['gain_db'][i], '-o', ms=2.5, lw=0.5, color=c, alpha=0.6)
        ax[1, 0].plot(f, sw['phase_deg'][i], '-o', ms=2.5, lw=0.5, color=c, alpha=0.6)
        if lin:
            ax[0, 0].plot(f, sw['lin_gain_db'][i], '--', lw=0.5, color=BLUE, alpha=0.4)
            ax[1, 0].plot(f, sw['lin_phase_deg'][i], '--', lw=0.5, color=BLUE, alpha=0.4)
    ax[0, 0].plot([], [], '-o', color=GREY, label='nonlinear, passing')
    ax[0, 0].plot([], [], '-o', color=RED, label='nonlinear, failing')
    if lin:
        ax[0, 0].plot([], [], '--', color=BLUE, label='linear, same plant')
    ax[0, 0].axhline(-3.0, color='g', ls=':', label='-3 dB')
    for a, yl in ((ax[0, 0], 'gain truth/reference (dB)'), (ax[1, 0], 'phase (deg)')):
        a.set_xscale('log')
        a.set_xlabel('frequency (Hz)')
        a.set_ylabel(yl)
        a.grid(True, which='both', alpha=0.4)
    ax[0, 0].set_title('closed-loop gain per plant')
    ax[1, 0].set_title('closed-loop phase per plant')
    ax[0, 0].legend(fontsize=8)
    if lin:
        rng = np.random.default_rng(0)
        jit = 1 + 0.04 * rng.standard_normal(sw['gain_diff_db'].shape)
        for a, key, yl in ((ax[0, 1], 'gain_diff_db', 'gain nonlinear - linear (dB)'),
                           (ax[1, 1], 'phase_diff_deg', 'phase nonlinear - linear (deg)')):
            d = sw[key]
            col = np.broadcast_to(np.where(ok[:, None], GREY, RED), d.shape)
            a.scatter((f[None] * jit).ravel(), d.ravel(), s=6, c=col.ravel(), alpha=0.6)
            a.plot(f, np.nanmedian(d, 0), 'k-', lw=1.2, label='median')
            a.plot(f, np.nanmax(np.abs(d), 0), 'k:', lw=1, label='max |difference|')
            a.axhline(0, color='k', lw=0.5)
            a.set_xscale('log')
            a.set_xlabel('frequency (Hz)')
            a.set_ylabel(yl)
            a.grid(True, which='both', alpha=0.4)
            a.legend(fontsize=8)
        ax[0, 1].set_title('nonlinear vs linear prediction, per plant')
        ax[1, 1].set_title('nonlinear vs linear prediction, per plant')
    else:
        for a in ax[:, 1]:
            a.axis('off')
        ax[0, 1].text(0.1, 0.5, 'no linear predictions (lin_gain_db_<f>hz) in the results',
                      transform=ax[0, 1].transAxes)
    return _save(fig, path)


def plot_relative(path, results, specs: dict) -> str | None:
    """Each spec relative to another column (max_rel / min_rel, alone or as a case): the metric
    against that column, with the limit line of that case."""
    rel = [(m, form, c[form]) for m, s in specs.items()
           for c in (s if isinstance(s, list) else [s])
           for form in c if form.endswith('_rel') and m in results and c[form]['to'] in results]
    if not rel:
        return None
    plt = _plt()
    ok = results['passed'].astype(bool).to_numpy()
    fig, axes = plt.subplots(1, len(rel), figsize=(5.5 * len(rel), 4.8), squeeze=False)
    for ax, (m, form, v) in zip(axes[0], rel):
        x = results[v['to']].to_numpy(float)
        y = results[m].to_numpy(float)
        sx, ux = metric_unit(v['to'])
        sy, uy = metric_unit(m)
        ax.scatter(x[ok] * sx, y[ok] * sy, s=10, color=GREY, label='passing')
        ax.scatter(x[~ok] * sx, y[~ok] * sy, s=14, color=RED, label='failing run (any spec)')
        xs = np.linspace(0, np.nanmax(x) * 1.05 if np.isfinite(x).any() else 1, 50)
        ax.plot(xs * sx, (v.get('factor', 1.0) * xs + v.get('offset', 0.0)) * sy, 'k--',
                label=f'limit {requirement(m, {form: v})}')
        ax.plot(xs * sx, xs * sy, color=BLUE, lw=0.8, label='equal')
        ax.set_xlabel(label(v['to']))
        ax.set_ylabel(label(m))
        ax.set_title(f'{m} vs {v["to"]}')
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=7)
    return _save(fig, path)


def plot_scatter_grid(path, results, metrics: list, mults: list, specs: dict) -> str | None:
    """Each metric (rows) against each varying multiplier (columns); failing runs red; fixed
    spec limits as horizontal lines."""
    if not metrics or not mults:
        return None
    plt = _plt()
    ok = results['passed'].astype(bool).to_numpy()
    nr, nc = len(metrics), len(mults)
    fig, axes = plt.subplots(nr, nc, figsize=(2.7 * nc + 0.8, 2.3 * nr + 0.8), squeeze=False,
                             sharex='col')
    for i, m in enumerate(metrics):
        y = results[m].to_numpy(float)
        s, _ = metric_unit(m)
        spec = specs.get(m, {})
        lim = {k: v for c in (spec if isinstance(spec, list) else [spec])
               for k, v in c.items() if k in ('max', 'min')}
        for j, c in enumerate(mults):
            ax = axes[i, j]
            x = results[c].to_numpy(float)
            ax.scatter(x[ok], y[ok] * s, s=6, color=GREY, alpha=0.6)
            ax.scatter(x[~ok], y[~ok] * s, s=9, color=RED, alpha=0.9)
            pos = x[np.isfinite(x)]
            if c != 'seed' and len(pos) and pos.min() > 0 and pos.max() / pos.min() > 4:
                ax.set_xscale('log')
            for form in ('max', 'min'):
                if form in lim:
                    ax.axhline(lim[form] * s, color='k', ls='--', lw=0.8)
            ax.grid(True, alpha=0.3)
            ax.tick_params(labelsize=7)
            if i == nr - 1:
                ax.set_xlabel(f'{c} (x nominal)' if c != 'seed' else 'seed', fontsize=8)
            if j == 0:
                ax.set_ylabel(label(m), fontsize=8)
    fig.suptitle('metrics vs plant multipliers (red: failing runs; dashed: spec limit)',
                 fontsize=10)
    return _save(fig, path)


# ------------------------------------------------------------------------------ markdown
def _table(header: list, rows: list) -> list[str]:
    out = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    for r in rows:
        out.append('| ' + ' | '.join(str(x).replace('|', '/') for x in r) + ' |')
    return out


def _num(v, nd=3):
    try:
        return f'{float(v):.{nd}g}'
    except (TypeError, ValueError):
        return str(v)


def comparison_tables(results) -> dict:
    """Markdown lines comparing the nonlinear figures with the linear predictions:
    {'sweep': [...], 'stiffness': [...]} (empty when the columns are missing)."""
    out = {'sweep': [], 'stiffness': []}
    if frequency_columns(results, 'lin_gain_db'):
        sw = sweep_table(results)
        if sw['has_linear']:
            d = sw['gain_diff_db']
            pd_ = sw['phase_diff_deg']
            out['sweep'] += ['Nonlinear minus linear, over the runs:', '']
            out['sweep'] += _table(
                ['f (Hz)', 'gain median (dB)', 'gain max abs (dB)', 'phase median (deg)',
                 'phase max abs (deg)'],
                [(_num(f), _num(np.nanmedian(d[:, k])), _num(np.nanmax(np.abs(d[:, k]))),
                  _num(np.nanmedian(pd_[:, k])), _num(np.nanmax(np.abs(pd_[:, k]))))
                 for k, f in enumerate(sw['f_hz'])]) + ['']
    st = stiffness_table(results)
    if len(st['f_hz']) and 'lin_stiffness' in st:
        r = st['stiffness'] / st['lin_stiffness']
        out['stiffness'] += ['Measured over linear stiffness, over the runs:', '']
        out['stiffness'] += _table(
            ['f (Hz)', 'min measured (kN/mm)', 'min linear (kN/mm)', 'ratio median',
             'ratio min'],
            [(_num(f), _num(np.nanmin(st['stiffness'][:, k])),
              _num(np.nanmin(st['lin_stiffness'][:, k])), _num(np.nanmedian(r[:, k])),
              _num(np.nanmin(r[:, k]))) for k, f in enumerate(st['f_hz'])]) + ['']
    return out


def write_report(out_dir: str, info: dict, results, traces: dict | None) -> str:
    """Writes out_dir/report.md and PNGs next to it; returns the report path."""
    os.makedirs(out_dir, exist_ok=True)
    scn = info.get('scenario', {}) or {}
    kind, specs = scn.get('kind', ''), scn.get('specs') or {}
    results = results.reset_index(drop=True).copy()
    if 'passed' not in results:
        results['passed'] = True
    for c in ('failed_specs', 'error'):
        if c not in results:
            results[c] = ''
        results[c] = results[c].fillna('').astype(str)
    n = len(results)
    passed = int(results['passed'].astype(bool).sum())
    errors = int((results['error'] != '').sum())
    md = [f'# Campaign {scn.get("name", "?")}: {passed} of {n} runs passed', '']
    if scn.get('description'):
        md += [f'_{scn["description"]}_', '']
    rows = [('scenario', f'{scn.get("name", "")} (kind {kind}, {_num(scn.get("duration", ""))} s '
                         'of plant time per run)'),
            ('family', info.get('family', '')),
            ('runs', f'{n} of {info.get("count", n)}' +
             ('' if info.get('complete', True) else ' (INCOMPLETE: finish with --resume)')),
            ('passed / failed', f'{passed} / {n - passed}'),
            ('runs that raised', errors),
            ('wall time', f'{_num(info.get("wall_s", ""), 4)} s'),
            ('plant-s per wall-s', _num(info.get('plant_s_per_wall_s', ''), 4)),
            ('workers', info.get('workers', '')),
            ('scheduler', info.get('scheduler', '')),
            ('campaign seed', f'{info.get("seed", "")} ({info.get("seed_role", "?")}; each run '
                              'draws its own noise from the seed and its run id)')]
    if scn.get('oracle'):
        rows.append(('estimator', "the oracle: given each run's plant parameters, no adaptive "
                                  "states (campaign --oracle, core.sim.oracle)"))
    md += _table(['item', 'value'], rows) + ['']

    # specs
    md += ['## Specs', '']
    if specs:
        srows = []
        for s in spec_summary(results, specs):
            srows.append((s['metric'], s['requirement'], f'{s["passed"]} / {n}',
                          fmt(s['metric'], s['median']),
                          f'{fmt(s["metric"], s["worst"])} (run {s["worst_run"]})'))
        md += _table(['metric', 'requirement', 'passed', 'median', 'worst'], srows) + ['']
    else:
        md += ['The scenario sets no specs.', '']

    figures = []
    extra = comparison_tables(results)
    if traces is not None and len(np.asarray(traces.get('run_id', []))):
        p = plot_envelope(os.path.join(out_dir, 'envelope.png'), info, results, traces)
        figures.append(('Time response envelope', p,
                        'Grey band: min..max over the runs with traces; dashed: pointwise '
                        'median; blue: the run nearest the nominal plant; red: failing runs.'))
    if frequency_columns(results, 'stiffness_kn_per_mm'):
        p = plot_stiffness(os.path.join(out_dir, 'stiffness.png'), results)
        figures.append(('Dynamic stiffness', p, 'Measured |F_L|/|x| per plant against the '
                        'linear prediction (position fed back without error) and 1/|M| of '
                        'eq. 4.60; below the black line misses the bound.', extra['stiffness']))
    if frequency_columns(results, 'gain_db'):
        p = plot_sweep(os.path.join(out_dir, 'sweep.png'), results)
        figures.append(('Frequency response', p, 'Nonlinear closed loop per plant against '
                        'the linear prediction of the same plant (core.sim.linear).',
                        extra['sweep']))
    p = plot_relative(os.path.join(out_dir, 'relative.png'), results, specs)
    if p:
        figures.append(('Relative specs', p, 'Each max_rel spec against the column it is '
                        'relative to; above the dashed line fails.'))
    metrics = metric_columns(results, info)
    mults = varying(results)
    p = plot_scatter_grid(os.path.join(out_dir, 'scatter.png'), results, metrics, mults, specs)
    if p:
        figures.append(('Which parameter drives the failures', p,
                        'Each metric against each multiplier that varies in the family.'))

    md += ['## Figures', '']
    for title, path, caption, *more in figures:
        md += [f'### {title}', '', f'![{title}]({os.path.basename(path)})', '', caption, '']
        md += more[0] if more else []
    # worst runs
    md += ['## Worst runs', '']
    worst = worst_runs(results, specs, 10)
    cols = [c for c in MULTIPLIERS if c in mults]
    wrows = []
    for k, r in enumerate(worst.to_dict('records'), 1):
        spec = r['worst_spec']
        if spec == 'error':
            val, lim = '', ''
        elif spec:
            val, lim = fmt(spec, r.get(spec, math.nan)), fmt(spec, spec_limit(r, specs[spec]))
        else:
            val = lim = ''
        ex = r['excess']
        wrows.append((k, int(r['run_id']), 'PASS' if bool(r['passed']) else 'FAIL',
                      spec or '-', val, lim,
                      'inf' if ex == math.inf else ('' if ex == -math.inf else f'{ex * 100:+.1f} %'),
                      r['failed_specs'] or '-',
                      ' '.join(f'{c}={float(r[c]):.3g}' for c in cols),
                      (r['error'][:120] if r['error'] else '')))
    md += ['Ranked by the largest normalised spec excess (value/limit - 1 for a maximum, '
           '1 - value/limit for a minimum; positive: failed).', '']
    md += _table(['rank', 'run', 'result', 'worst spec', 'value', 'limit', 'excess',
                  'failed specs', 'multipliers', 'error'], wrows) + ['']
    failing = results.loc[~results['passed'].astype(bool), 'run_id'].astype(int).tolist()
    if failing:
        shown = ', '.join(str(i) for i in failing[:300])
        more = f' ... ({len(failing) - 300} more)' if len(failing) > 300 else ''
        md += [f'Failing runs ({len(failing)}): {shown}{more}', '']
        counts = {}
        for s in results.loc[~results['passed'].astype(bool), 'failed_specs']:
            for m in filter(None, str(s).split(',')):
                counts[m] = counts.get(m, 0) + 1
        if counts:
            md += ['Failures per spec: ' + ', '.join(f'{m} {c}' for m, c in
                                                     sorted(counts.items(), key=lambda x: -x[1])),
                   '']
    else:
        md += ['No run failed.', '']
    path = os.path.join(out_dir, 'report.md')
    with open(path, 'w', encoding='utf-8') as f:
        f.write('\n'.join(md))
    return path
