"""Identification, fitting side (issue 43): recordings of the four experiments simulated on a
plant with changed parameters (tests/ident_experiments.py, default sensor noise) and fitted
from the recordings only; bad inputs end in one line with nothing but a log written."""
import json
import os
import shutil

import numpy as np
import pytest

pytest.importorskip('rclpy')
import ident_experiments as E                                     # noqa: E402
from eha_ros.core.config.cli import UsageError                    # noqa: E402
from eha_ros.core.ident import fit as F                           # noqa: E402
from eha_ros.core.ident.pipeline import fit_recordings            # noqa: E402
from eha_ros.core.plant.parameters import nominal_plant           # noqa: E402

NOM = nominal_plant()
# C_eq x5 (split kept), F_c x1.5, drive delay 2 ms, k_T x0.9, Kp_w x1.2, Ki_w x0.8
CHANGED = {'plant.pump.C_p': 5 * NOM['plant.pump.C_p'], 'plant.pump.C_r': 5 * NOM['plant.pump.C_r'],
           'plant.cylinder.C_c': 5 * NOM['plant.cylinder.C_c'],
           'plant.friction.F_c': 1.5 * NOM['plant.friction.F_c'], 'plant.drive.delay': 0.002,
           'plant.motor.k_T': 0.9 * NOM['plant.motor.k_T'],
           'plant.drive.Kp_w': 1.2 * NOM['plant.drive.Kp_w'],
           'plant.drive.Ki_w': 0.8 * NOM['plant.drive.Ki_w']}
# the issue's tolerances: (relative, absolute)
TOLERANCE = {'C_eq': (0.10, 0.0), 'friction.F_c': (0.10, 30.0), 'friction.F_s': (0.10, 30.0),
             'friction.mu': (0.20, 0.0), 'drive.Kp_w': (0.15, 0.0), 'drive.Ki_w': (0.15, 0.0),
             'drive.delay': (0.0, 0.5e-3), 'motor.k_T': (0.10, 0.0)}


def truth(key: str) -> float:
    values = {**NOM, **CHANGED}
    if key == 'C_eq':
        return values['plant.pump.C_p'] + values['plant.cylinder.C_c'] + \
            0.5 * values['plant.pump.C_r']
    return values['plant.' + key]


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    return E.record_set(tmp_path_factory.mktemp('rec'), CHANGED, seed=3)


@pytest.fixture(scope='module')
def identified(recordings, tmp_path_factory):
    out = str(tmp_path_factory.mktemp('ident') / 'run')
    lines = []
    result = fit_recordings(list(reversed(recordings)), out, log=lines.append)
    return result, out, lines


def test_changed_parameters_recovered_within_the_issue_tolerances(identified):
    result, _, _ = identified
    params = result['parameters']
    for key, e in sorted(params.items()):
        print(f'{key:14s} {e["value"]:.5g} [{e["ci_low"]}, {e["ci_high"]}] truth '
              f'{truth(key)} identified {e["identified"]}')
    for key, (rel, absolute) in TOLERANCE.items():
        e, true = params[key], truth(key)
        if key in ('C_eq', 'friction.F_c', 'drive.Kp_w', 'drive.Ki_w', 'drive.delay',
                   'motor.k_T'):           # changed: the data must determine them
            assert e['identified'], (key, e['note'])
        if e['identified']:
            assert abs(e['value'] - true) <= max(rel * abs(true), absolute), (key, e, true)
            assert e['ci_low'] <= true <= e['ci_high'], (key, e, true)
    for key in ('friction.F_s', 'friction.v_s', 'friction.mu'):
        e = params[key]
        assert not e['identified'] or e['ci_low'] <= truth(key) <= e['ci_high'], (key, e)
    assert not params['fluid.beta']['identified'] and params['fluid.beta']['ci_low'] is None
    for key in ('pump.C_p', 'cylinder.C_c', 'pump.C_r'):      # only the loaded sum is seen
        assert not params[key]['identified'] and 'split' in params[key]['note']
        assert params[key]['value'] == pytest.approx(truth(key), rel=0.1)


def test_identified_model_validates_and_the_sweep_matches(identified):
    result, _, _ = identified
    val = result['validation']
    # the floor (an exact model's error: the recording's noise through the loop) is about the
    # sensor's: 10 um white + its slow offset in position, the loop's answer in motor speed
    sensor = {'position_rmse_m': (10e-6, 40e-6), 'motor_speed_rmse_rad_s': (2.0, 20.0)}
    judged = 0
    for key, (lo, hi) in sensor.items():
        q = val[key]
        print(key, {k: q[k] for k in ('nominal', 'identified', 'floor', 'excess')})
        assert lo < q['floor'] < hi, (key, q)
        assert len(q['runs']['nominal']) == len(q['runs']['identified']) == len(val['seeds'])
        assert q['judged'] == (q['nominal'] > 2 * q['floor']), (key, q)
        assert q['repeatable'] == {'nominal': True, 'identified': True}, (key, q)
        if q['judged']:
            judged += 1
            assert q['excess'] <= 1 / 3, (key, q)
        assert q['identified'] < 1.5 * q['floor'], (key, q)    # an exact model's, nearly
    assert judged >= 1, val               # the leakier plant's held speed tells them apart
    sweep = result['drive_sweep']['motor_speed_rmse_rad_s']
    assert sweep['identified'] <= 27 * 2 * np.pi / 60 < sweep['nominal'], sweep


def test_outputs_identified_yaml_json_report(identified):
    from eha_ros.core.config.params import load
    from eha_ros.core.plant.parameters import PLANT_SCHEMA, PlantParams, plant_file
    result, out, lines = identified
    on_disk = json.load(open(os.path.join(out, 'identification.json')))
    assert on_disk['parameters'] == result['parameters']
    for key, e in result['parameters'].items():
        assert set(e) >= {'value', 'ci_low', 'ci_high', 'nominal', 'identified'}, key
    text = open(os.path.join(out, 'identified.yaml')).read()
    assert text.count('ros__parameters') == 1 and 'beta' not in text
    values = load(PLANT_SCHEMA, [plant_file(), os.path.join(out, 'identified.yaml')])
    p = PlantParams.from_dict(values)
    assert p.delay_ticks == 2 and p.C_eq == pytest.approx(truth('C_eq'), rel=0.1)
    assert set(result['identified_yaml']) < {'plant.' + k for k in result['parameters']}
    report = open(os.path.join(out, 'report.md')).read()
    for png in ('drive_sweep.png', 'friction.png', 'leakage.png', 'validation.png'):
        assert f']({png})' in report and os.path.getsize(os.path.join(out, png)) > 10000
    assert result['wall_time']['fits_s'] < 600 and any('fits' in line for line in lines)


def _bad(tmp_path, paths):
    out = tmp_path / 'out'
    lines = []
    with pytest.raises(UsageError) as err:
        fit_recordings([str(p) for p in paths], str(out), log=lines.append)
    text = str(err.value)
    assert '\n' not in text
    assert not out.exists()
    return text


def test_bad_inputs_are_one_line_and_write_nothing(recordings, tmp_path):
    drive, friction, leakage, validation = recordings
    # a recording without /eha/state
    cols = {k: np.zeros(3000) for k in ('x', 'w0', 'w1', 'i0', 'i1', 'pa', 'pb', 'u', 'ch')}
    no_state = E.write(str(tmp_path / 'no_state.mcap'), 'friction', cols,
                       topics=('/eha/experiment', '/eha/command'))
    text = _bad(tmp_path, [drive, no_state, leakage, validation])
    assert 'no_state.mcap' in text and '/eha/state' in text
    # truncated
    cut = tmp_path / 'cut.mcap'
    data = open(friction, 'rb').read()
    cut.write_bytes(data[:len(data) // 2])
    text = _bad(tmp_path, [drive, cut, leakage, validation])
    assert 'cut.mcap' in text
    # a foreign MCAP (no experiment on /eha/experiment)
    foreign = E.write(str(tmp_path / 'foreign.mcap'), 'friction', cols,
                      topics=('/eha/state', '/eha/command'))
    text = _bad(tmp_path, [drive, foreign, leakage, validation])
    assert 'foreign.mcap' in text and 'not a recording of an identification' in text
    # another experiment where friction is missing
    other = tmp_path / 'other_drive.mcap'
    shutil.copy(drive, other)
    text = _bad(tmp_path, [drive, leakage, validation])
    assert 'friction' in text
    # two recordings of the same experiment
    text = _bad(tmp_path, [drive, other, friction, leakage, validation])
    assert 'other_drive.mcap' in text and 'second recording of the drive' in text
    # unknown experiment and version
    for meta, what in (({'experiment': 'swim', 'version': 1}, 'swim'),
                       ({'experiment': 'friction', 'version': 7}, 'version')):
        path = E.write(str(tmp_path / 'meta.mcap'), 'friction', cols, meta=meta)
        assert what in _bad(tmp_path, [drive, path, leakage, validation])


def test_fit_reports_what_the_data_cannot_separate():
    rng = np.random.default_rng(1)
    t = np.linspace(-1.0, 1.0, 2000)
    y = 2.0 * t + 0.5 + 0.01 * rng.standard_normal(len(t))

    def model(x):          # a and b only as their sum: not separable; c unseen
        return (x[0] + x[1]) * t + 0.5 + 0.0 * x[2] - y

    fit = F.least_squares_fit(model, [0.5, 0.5, 1.0], ['a', 'b', 'c'], [-10] * 3, [10] * 3)
    for name in ('a', 'b', 'c'):
        assert not fit.estimate(name, 1.0).identified
    covered = 0
    for seed in range(40):                # the 95 % interval holds the truth about 95 % of runs
        y = 2.0 * t + 0.5 + 0.01 * np.random.default_rng(seed).standard_normal(len(t))
        good = F.least_squares_fit(lambda x: x[0] * t + x[1] - y, [1.0, 1.0], ['k', 'd'],
                                   [-10, -10], [10, 10])
        k = good.estimate('k', 2.0)
        assert k.identified
        covered += k.ci_low < 2.0 < k.ci_high
    assert covered >= 34, covered


def test_identified_yaml_takes_the_friction_curve_whole_or_not_at_all():
    """Eq. 3.33's four parameters trade off: identified.yaml gets all four fitted values or none
    (a fitted F_s beside a nominal F_c is a curve no data showed), the others one by one."""
    from eha_ros.core.ident.pipeline import changed_keys, nominal_plant as plant_values
    _, values = plant_values(None)
    est = {'C_eq': F.Estimate(2e-12, 1.9e-12, 2.1e-12, 3.8e-12, True, ''),
           'drive.Kp_w': F.Estimate(0.7, 0.69, 0.71, 0.59, True, ''),
           'drive.Ki_w': F.Estimate(40.0, 20.0, 60.0, 46.2, False, 'wide'),
           'friction.F_s': F.Estimate(1200.0, 1150.0, 1250.0, 800.0, True, ''),
           'friction.F_c': F.Estimate(700.0, 400.0, 1000.0, 450.0, False, 'wide')}
    curve = {'F_c': 700.0, 'F_s': 1200.0, 'v_s': 0.02, 'mu': 1500.0}
    out = changed_keys(est, values, curve)
    assert {k: out[k] for k in out if 'friction' in k} == {
        f'plant.friction.{n}': v for n, v in curve.items()}
    assert out['plant.drive.Kp_w'] == 0.7 and 'plant.drive.Ki_w' not in out
    assert not any('friction' in k for k in changed_keys(est, values, None))
    bad = dict(curve, F_s=300.0)                       # F_s < F_c: eq. 3.33 refuses it
    assert not any('friction' in k for k in changed_keys(est, values, bad))
