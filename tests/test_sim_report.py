"""core.sim.report: campaign report from a synthetic results frame and traces."""
import math
import os
import re

import numpy as np
import pytest

pd = pytest.importorskip('pandas')

from eha_ros.core.sim import report  # noqa: E402

MULT = ('C_eq', 'D_p', 'beta', 'k_T', 'k_E', 'friction', 'noise', 'leak_split')


def _family(n, rng):
    df = pd.DataFrame({'run_id': np.arange(n)})
    for c in MULT:
        df[c] = 1.0
    df['C_eq'] = np.geomspace(0.1, 10, n)
    df['beta'] = rng.uniform(0.7, 1.4, n)
    df['seed'] = 1
    return df


def _judge(df, specs):
    from eha_ros.core.sim.scenarios import judge
    res = [judge(r, specs) for r in df.to_dict('records')]
    df['passed'] = [r[0] for r in res]
    df['failed_specs'] = [r[1] for r in res]
    df['error'] = ''
    return df


def _info(kind, specs, df, params):
    return {'scenario': {'name': kind, 'kind': kind, 'description': f'synthetic {kind}',
                         'duration': 1.6, 'params': params, 'specs': specs},
            'family': 'random:12', 'count': len(df), 'passed': int(df['passed'].sum()),
            'failed': int((~df['passed']).sum()), 'wall_s': 12.5, 'plant_s_per_wall_s': 21.3,
            'workers': 2, 'scheduler': 'LocalCluster', 'seed': 1, 'complete': True}


def _pngs_ok(out, names):
    for name in names:
        p = os.path.join(out, name)
        assert os.path.isfile(p) and os.path.getsize(p) > 1000, name
        with open(p, 'rb') as f:
            assert f.read(8) == b'\x89PNG\r\n\x1a\n'


def _worst_ids(md):
    part = md.split('## Worst runs', 1)[1]
    return {int(m) for m in re.findall(r'^\| \d+ \| (\d+) \|', part, flags=re.M)}


def test_step_report(tmp_path):
    rng = np.random.default_rng(0)
    n = 12
    df = _family(n, rng)
    a, ts = 5e-3, 0.1
    t = np.linspace(0, 1.6, 800)
    zeta = np.where(df['C_eq'] > 3, 0.35, 0.9)          # the leaky plants ring
    wn = 60.0
    truth = np.zeros((n, len(t)))
    for i in range(n):
        tt = np.clip(t - ts, 0, None)
        z = zeta[i]
        wd = wn * math.sqrt(1 - z * z)
        y = 1 - np.exp(-z * wn * tt) * (np.cos(wd * tt) + z / math.sqrt(1 - z * z) *
                                        np.sin(wd * tt))
        truth[i] = a * y * (t >= ts)
    ref = np.where(t >= ts, a, 0.0)[None].repeat(n, 0)
    after = t >= ts
    df['overshoot_pct'] = np.max(truth[:, after] - a, axis=1).clip(0) / a * 100
    df['settling_s'] = np.where(zeta < 0.5, 0.35, 0.08)
    df['steady_error_m'] = rng.uniform(0, 1e-5, n)
    df['estimate_error_m'] = rng.uniform(0, 5e-6, n)
    df['plant_s'] = 1.6
    df['wall_s'] = 0.1
    specs = {'overshoot_pct': {'max': 5.0}, 'settling_s': {'max': 0.3},
             'steady_error_m': {'max': 2e-5}}
    df = _judge(df, specs)
    df.loc[3, ['passed', 'failed_specs', 'error']] = [False, 'error', 'RuntimeError: boom']
    df.loc[3, ['overshoot_pct', 'settling_s', 'steady_error_m']] = np.nan
    failing = set(df.loc[~df['passed'], 'run_id'].astype(int))
    assert 3 in failing and len(failing) >= 3
    traces = {'t': t, 'run_id': np.delete(np.arange(n), 3),
              'reference': np.delete(ref, 3, 0), 'truth': np.delete(truth, 3, 0),
              'estimate': np.delete(truth, 3, 0), 'measured': np.delete(truth, 3, 0),
              'command': np.zeros((n - 1, len(t))), 'load': np.zeros((n - 1, len(t)))}
    info = _info('step', specs, df, {'amplitude': a, 't_step': ts, 'band': 0.02,
                                     'steady': [1.0, 1.5], 'duration': 1.6})
    path = report.write_report(str(tmp_path), info, df, traces)
    assert path == os.path.join(str(tmp_path), 'report.md')
    md = open(path).read()
    assert failing <= _worst_ids(md)
    for k in ('LocalCluster', 'random:12', '21.3', 'overshoot_pct', 'settling_s',
              'RuntimeError: boom', 'envelope.png', 'scatter.png'):
        assert k in md, k
    _pngs_ok(str(tmp_path), ['envelope.png', 'scatter.png'])
    # the worst run is one that raised, then the largest excess
    worst = report.worst_runs(df, specs, 10)
    assert int(worst['run_id'].iloc[0]) == 3 and worst['worst_spec'].iloc[0] == 'error'
    assert worst['excess'].iloc[1] > 0
    # spec table counts
    s = {r['metric']: r for r in report.spec_summary(df, specs)}
    assert s['settling_s']['passed'] == int(np.sum(df['settling_s'] <= 0.3))


def test_sweep_report(tmp_path):
    rng = np.random.default_rng(1)
    n = 10
    df = _family(n, rng)
    freqs = (1, 2, 4, 7, 10, 15)
    for f in freqs:
        lg = -0.02 * f - 0.5 * (df['C_eq'] > 5) * (f / 7) ** 2
        lp = -3.6 * f
        df[f'lin_gain_db_{f}hz'] = lg
        df[f'lin_phase_deg_{f}hz'] = lp
        df[f'gain_db_{f}hz'] = lg + rng.normal(0, 0.1, n) - 3.0 * (df['run_id'] == 7) * (f >= 7)
        df[f'phase_deg_{f}hz'] = lp + rng.normal(0, 1.0, n)
    df['plant_s'] = 16.5
    specs = {'gain_db_1hz': {'min': -0.5}, 'gain_db_7hz': {'min': -3.0},
             'phase_deg_7hz': {'min': -60.0}}
    df = _judge(df, specs)
    failing = set(df.loc[~df['passed'], 'run_id'].astype(int))
    assert 7 in failing
    t = np.arange(0, 3.0, 0.002)
    ref = 1e-3 * np.sin(2 * np.pi * 2 * t)
    truth = np.array([0.98 * 1e-3 * np.sin(2 * np.pi * 2 * t - 0.2 - 0.01 * i)
                      for i in range(n)])
    traces = {'t': t, 'run_id': np.arange(n), 'reference': np.repeat(ref[None], n, 0),
              'truth': truth, 'estimate': truth, 'measured': truth,
              'command': np.zeros_like(truth), 'load': np.zeros_like(truth)}
    info = _info('sweep', specs, df, {'amplitude': 1e-3, 'freqs': list(freqs)})
    path = report.write_report(str(tmp_path), info, df, traces)
    md = open(path).read()
    assert failing <= _worst_ids(md)
    assert 'sweep.png' in md and 'Nonlinear minus linear' in md
    _pngs_ok(str(tmp_path), ['envelope.png', 'sweep.png', 'scatter.png'])
    sw = report.sweep_table(df)
    assert list(sw['f_hz']) == list(freqs) and sw['has_linear']
    assert np.nanmax(np.abs(sw['gain_diff_db'][7])) > 2.5


def test_stiffness_and_relative_without_traces(tmp_path):
    """No traces: no envelope; stiffness and max_rel figures from the frame alone."""
    rng = np.random.default_rng(2)
    n = 8
    df = _family(n, rng)
    for f in (1, 4, 7):
        df[f'lin_stiffness_kn_per_mm_{f}hz'] = 300.0 / df['C_eq'] ** 0.5 / (1 + f / 10)
        df[f'stiffness_kn_per_mm_{f}hz'] = 0.6 * df[f'lin_stiffness_kn_per_mm_{f}hz']
    df['lin_peak_deviation_m'] = 2e-4 * df['C_eq'] ** 0.1
    df['peak_deviation_m'] = 1.1 * df['lin_peak_deviation_m'] + 4e-5 * (df['C_eq'] > 5)
    specs = {f'stiffness_kn_per_mm_{f}hz': {'min': 49.0} for f in (1, 4, 7)}
    specs['peak_deviation_m'] = {'max_rel': {'to': 'lin_peak_deviation_m', 'factor': 1.25,
                                             'offset': 5e-6}}
    df = _judge(df, specs)
    info = _info('stiffness', specs, df, {'force': 5e3, 'freqs': [1.0, 4.0, 7.0]})
    path = report.write_report(str(tmp_path), info, df, None)
    md = open(path).read()
    assert set(df.loc[~df['passed'], 'run_id'].astype(int)) <= _worst_ids(md)
    assert 'envelope.png' not in md
    assert '<= 1.25 x lin_peak_deviation_m + 0.005 mm' in md
    _pngs_ok(str(tmp_path), ['stiffness.png', 'relative.png', 'scatter.png'])


def test_units_and_helpers():
    assert report.metric_unit('peak_deviation_m') == (1e3, 'mm')
    assert report.metric_unit('stiffness_kn_per_mm_7hz')[1] == 'kN/mm'
    assert report.metric_unit('gain_db_2p5hz')[1] == 'dB'
    assert report.metric_unit('phase_deg_7hz')[1] == 'deg'
    assert report.metric_unit('settling_s')[1] == 's'
    assert report.fmt('steady_error_m', 2e-5) == '0.02 mm'
    df = pd.DataFrame({'run_id': [0, 1], 'gain_db_2p5hz': [0.0, 1.0], 'gain_db_10hz': [1, 2]})
    assert report.frequency_columns(df, 'gain_db') == [(2.5, 'gain_db_2p5hz'),
                                                       (10.0, 'gain_db_10hz')]
