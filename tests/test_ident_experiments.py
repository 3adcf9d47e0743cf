"""The identification experiments (issue 43) without ROS: every shipped plan inside the stroke,
the drive's speed limit and its current limit, with the signal content the fitting needs; plans
beyond a limit refused in one line naming the parameter; the run's per-tick outputs and its
stops on the loop's safe state, the stroke, a lost track and a disarmed plant side."""
import json
import math

import numpy as np
import pytest

from eha_ros.core.config.cli import UsageError
from eha_ros.core.config.params import ParamError
from eha_ros.core.ident import experiments as E
from eha_ros.core.ident.params import SCHEMA
from eha_ros.core.ident.run import ExperimentRun
from eha_ros.core.sim.batch import node_params
from eha_ros.core.sweep.signals import Staircase


@pytest.fixture(scope='module')
def p():
    return node_params('experiment', SCHEMA)


@pytest.fixture(scope='module')
def limits(p):
    return E.Limits.from_params(p)


def plan(p, kind, **over):
    return E.build(dict(p, **{f'experiment.{kind}.{k}': v for k, v in over.items()}), kind)


def motor_speed_and_accel(plan, L):
    """Peak motor speed and acceleration the plan's sines ask of the drive (A_p/D_p); a sine
    starts at phase 0, a velocity step the controller's reference shaper smooths."""
    speed = accel = 0.0
    for q in plan.parts:
        v = np.diff(plan.reference[q['start']:q['stop']]) / L.Ts
        speed = max(speed, np.abs(v).max() * L.ratio)
        accel = max(accel, np.abs(np.diff(v) / L.Ts).max() * L.ratio)
    return speed, accel


def drive_travel(plan, L):
    """The piston of an ideal actuator (x' = D_p/A_p u) under the drive plan's command with the
    position loop closed on it: its largest |x| (from mid-stroke)."""
    x, worst = 0.0, 0.0
    for ff in plan.speed:
        u = ff - plan.position_gain * x
        x += u / L.ratio * L.Ts
        worst = max(worst, abs(x))
    return worst


def test_the_limits_are_the_plants(limits):
    assert limits.reach == pytest.approx(0.055)
    assert limits.omega_max == pytest.approx(837.758041)
    assert limits.accel_max == pytest.approx(0.73 * 36.0 / 0.000593)         # k_T I_max / J_eq
    assert limits.ratio == pytest.approx(0.002572 / 6.684e-7)
    assert limits.hold_force == pytest.approx(0.5 * 0.002572 * 25.5e6)


def test_drive_plan_speed_sines_1_to_15_hz_inside_every_limit(p, limits):
    d = E.build(p, 'drive')
    assert d.reference is None and d.load is None and d.speed is not None
    assert [q['freq_hz'] for q in d.parts] == [1, 2, 3, 5, 7, 10, 15]
    assert np.abs(d.speed).max() == pytest.approx(1000 * math.pi / 30, rel=1e-6)  # 1000 rpm
    # each part is a whole number of periods of its frequency, at the thesis' amplitude
    for q in d.parts:
        seg = d.speed[q['start']:q['stop']]
        spec = np.abs(np.fft.rfft(seg)) * 2 / len(seg)
        f = np.fft.rfftfreq(len(seg), d.Ts)
        assert f[spec.argmax()] == pytest.approx(q['freq_hz'], abs=1 / (len(seg) * d.Ts))
        assert spec.max() == pytest.approx(q['amplitude'], rel=1e-3)
    # the slow position loop: well below the lowest sine, and it keeps the piston centred
    assert d.position_gain / (2 * math.pi * limits.ratio) == pytest.approx(0.1)
    assert drive_travel(d, limits) < limits.reach / 5
    peak = np.abs(d.speed).max() + d.position_gain * drive_travel(d, limits)
    assert peak < E.SPEED_SHARE * limits.omega_max
    assert np.abs(np.diff(d.speed) / d.Ts).max() < E.ACCEL_SHARE * limits.accel_max


def test_friction_plan_covers_the_velocity_range_of_eq_3_33(p, limits):
    f = E.build(p, 'friction')
    assert f.speed is None and f.load is None
    assert np.abs(f.reference).max() <= limits.reach
    v = np.abs(np.diff(f.reference)) / f.Ts
    assert v.max() > 0.1                                     # beyond 0.1 m/s (Table 3.7's range)
    low = [q for q in f.parts if 2 * math.pi * q['freq_hz'] * q['amplitude'] < 0.01]
    assert low and all((q['stop'] - q['start']) * f.Ts >= 4 for q in low)  # slow sines: seconds
    freqs = [q['freq_hz'] for q in f.parts]
    assert freqs == sorted(freqs) and len(freqs) >= 5       # rising frequency (Fig. 3.40)
    speed, accel = motor_speed_and_accel(f, limits)
    assert speed < E.SPEED_SHARE * limits.omega_max and accel < E.ACCEL_SHARE * limits.accel_max


def test_leakage_plan_holds_two_levels_each_way(p, limits):
    k = E.build(p, 'leakage')
    assert np.all(k.reference == 0.0) and k.speed is None
    held = {q['load_n']: (q['stop'] - q['start']) * k.Ts for q in k.parts}
    assert held == {5e3: 4.0, 1e4: 4.0, -5e3: 4.0, -1e4: 4.0}
    for q in k.parts:                                        # the load is held, not ramping
        assert np.all(k.load[q['start']:q['stop']] == q['load_n'])
    assert k.load[0] == 0.0 and k.load[-1] == 0.0
    assert np.abs(k.load).max() <= limits.hold_force


def test_validation_plan_is_a_step_and_a_sine(p, limits):
    v = E.build(p, 'validation')
    names = [q['name'] for q in v.parts]
    assert names == ['step', 'step', 'sine']
    up, back, sine = v.parts
    assert np.all(v.reference[up['start']:up['stop']] == 0.005)
    assert np.all(v.reference[back['start']:back['stop']] == 0.0)
    assert sine['freq_hz'] == 1.0 and np.abs(v.reference[sine['start']:sine['stop']]).max() == \
        pytest.approx(0.005, rel=1e-4)
    assert np.abs(v.reference).max() <= limits.reach


@pytest.mark.parametrize('kind, over, words', [
    ('drive', {'amplitude': 400.0}, ('experiment.drive.amplitude', 'current-limited')),
    ('drive', {'amplitude': 700.0, 'freqs': [5.0]}, ('experiment.drive.amplitude', 'omega_max')),
    ('drive', {'freqs': [0.15], 'position_bandwidth': 0.02},
     ('experiment.drive.amplitude', 'stroke')),
    ('drive', {'position_bandwidth': 0.5}, ('position_bandwidth', 'lowest sine')),
    ('drive', {'freqs': [60.0]}, ('experiment.drive.freqs', 'Nyquist')),
    ('friction', {'amplitude': 0.058}, ('experiment.friction', 'stroke')),
    ('friction', {'freqs': [5.0], 'amplitude': 0.04}, ('friction.amplitude', 'omega_max')),
    ('friction', {'freqs': [12.0], 'amplitude': 0.002}, ('friction.amplitude', 'current')),
    ('leakage', {'loads': [5e3, -40e3]}, ('experiment.leakage.loads', '40000')),
    ('validation', {'step': 0.07}, ('experiment.validation.step', 'stroke')),
])
def test_a_plan_beyond_a_limit_is_one_line_naming_it(p, kind, over, words):
    with pytest.raises(UsageError) as err:
        plan(p, kind, **over)
    text = str(err.value)
    assert '\n' not in text and all(w in text for w in words), text
    # the node refuses the same (its schema's check), before ROS starts
    with pytest.raises(ParamError, match=words[0].split('.')[-1]):
        node_params('experiment', SCHEMA, None, {'experiment:experiment.kind': kind, **{
            f'experiment:experiment.{kind}.{k}': v for k, v in over.items()}})


def test_the_message_is_the_contract(p):
    d = E.build(p, 'drive')
    msg = json.loads(json.dumps(d.message('bridge', 1234)))
    assert set(msg) == {'experiment', 'version', 'plant_side', 'params'}
    assert (msg['experiment'], msg['version'], msg['plant_side']) == ('drive', 1, 'bridge')
    q = msg['params']
    assert q['start_seq'] == 1234 and q['n_ticks'] == d.n_ticks and q['Ts'] == 1e-3
    assert q['freqs'] == [1, 2, 3, 5, 7, 10, 15] and q['position_gain'] == d.position_gain
    assert q['parts'][0] == {'name': 'sine', 'freq_hz': 1.0, 'amplitude': q['amplitude'],
                             'start': 300, 'stop': 6300}
    assert 'position_gain' not in E.build(p, 'leakage').message('sim', 0)['params']


def test_staircase_ramps_between_held_levels():
    s = Staircase((2.0, -1.0), hold_s=0.004, ramp_s=0.002, rest_s=0.001, Ts=1e-3)
    assert s.array().tolist() == [0, 0, 1, 2, 2, 2, 2, 2, 0.5, -1, -1, -1, -1, -1, -0.5, 0]
    assert [(g.start, g.stop, g.amplitude) for g in s.segments] == [(3, 7, 2.0), (9, 13, -1.0)]
    assert [s.value(k) for k in range(-1, 17)] == [0.0] + s.array().tolist() + [0.0]


def run_of(p, kind, **kw):
    pl = E.build(p, kind)
    r = ExperimentRun(pl, E.Limits.from_params(p), kw.get('abort_error', 0.005),
                      kw.get('abort_ticks', 3))
    r.start(100)
    return pl, r


def test_the_run_sends_the_plan_by_seq(p):
    pl, r = run_of(p, 'leakage')
    i = pl.parts[1]['start'] + 5
    assert r.load_for(100 + i) == 1e4 and r.reference_for(100 + i) == 0.0
    assert r.load_for(99) == 0.0 and r.load_for(100 + pl.n_ticks) == 0.0
    assert not r.done(100 + pl.n_ticks - 1) and r.done(100 + pl.n_ticks)
    parts = [r.new_part(100 + k) for k in range(pl.n_ticks)]
    assert [q['load_n'] for q in parts if q] == [5e3, 1e4, -5e3, -1e4]
    assert r.describe(pl.parts[1]) == 'experiment leakage: part 2/4: load 10000 N held ' \
                                      '(at 5.4 of 19.0 s)'


def test_the_drive_command_is_the_sine_minus_the_position_loop(p, limits):
    pl, r = run_of(p, 'drive')
    k = 100 + pl.parts[0]['start'] + 123
    x = 0.002
    assert r.command_for(k, x) == pytest.approx(pl.speed[k - 100] - pl.position_gain * x)
    assert r.command_for(50, x) == pytest.approx(-pl.position_gain * x)   # before: the loop
    assert r.command_for(k, -1.0) == limits.omega_max                     # clipped
    assert r.on_state(k, 0.0549) == '' and r.command_for(k, 0.0) != 0.0
    why = r.on_state(k, -0.0551)                                          # the stroke guard
    assert why.startswith('measured position -55.10 mm at tick') and 'stroke' in why
    assert r.command_for(k + 1, 0.0) == 0.0 and r.on_state(k + 2, 0.06) == ''   # once


@pytest.mark.parametrize('event, expect', [
    (lambda r: r.on_manager('FAILED_SAFE', 'both couples failed'),
     'safe state: switch manager FAILED_SAFE (both couples failed)'),
    (lambda r: r.on_estimate(150, 0.0, 3), 'safe state: position fault: estimator reports '
                                           'sensor_fault'),
    (lambda r: r.on_plant_active(False), 'the plant side stopped applying commands'),
])
def test_the_run_stops_on_the_safe_state_and_a_disarmed_plant(p, event, expect):
    pl, r = run_of(p, 'validation')
    assert r.on_manager('ACTIVE_A', '') == '' and r.on_estimate(150, 0.0, 1) == ''
    assert r.on_plant_active(True) == ''
    k = 100 + pl.parts[0]['start'] + 10
    assert r.reference_for(k) == 0.005
    assert event(r).startswith(expect)
    assert r.stopped.startswith(expect)
    assert r.reference_for(k) == 0.0 and r.load_for(k) == 0.0 and r.command_for(k, 0.0) == 0.0


def test_the_run_stops_when_the_loop_loses_track(p):
    pl, r = run_of(p, 'validation', abort_error=0.001, abort_ticks=3)
    k = 100 + pl.parts[0]['start']                     # the reference steps to 5 mm
    assert [r.on_estimate(k + i, 0.0, 0) for i in range(2)] == ['', '']
    assert r.on_estimate(k + 2, 0.0, 0) == 'position error 5.00 mm > 1.00 mm at tick 502'
