"""Sweep runs: interrupted sessions keep finished points; the main job in batch; bad options."""
import json
import os
import subprocess

import numpy as np
import pytest
from scipy import signal as sps

from eha_ros.core.sweep.session import SweepSession, print_table
from eha_ros.core.sweep.signals import SteppedSine

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUN = os.path.join(ROOT, 'scripts', 'run')


def test_interrupted_session_keeps_finished_points(tmp_path):
    plan = SteppedSine(1, 2, 9, 6, 0.1, 1e-3)
    s = SweepSession(plan, str(tmp_path), {'mode': 'stepped'}, background_writes=False)
    s.start(100)
    sys_ = sps.dlti([0.2], [1, -0.8], dt=1e-3)                 # a known first-order lag
    _, y = sps.dlsim(sys_, plan.array())
    y = y[:, 0]
    stop = plan.segments[2].stop + 40                           # in the 4th frequency
    for i in range(stop):
        s.record('reference', 100 + i, plan.array()[i])
        s.record('truth', 100 + i, y[i])
        s.progress(100 + i)
    summary = s.finish(reason='interrupted')
    on_disk = json.load(open(tmp_path / 'summary.json'))
    assert on_disk['complete'] is False and on_disk['status'] == 'interrupted'
    assert [p['freq_hz'] for p in on_disk['points']] == [1, 3, 5]
    for p in on_disk['points']:                                 # the finished points are right
        _, h = sps.dfreqresp(sys_, w=[2 * np.pi * p['freq_hz'] * 1e-3])
        assert p['gain_db'] == pytest.approx(20 * np.log10(abs(h[0])), abs=0.05)
        assert p['phase_deg'] == pytest.approx(np.degrees(np.angle(h[0])), abs=0.5)
    assert summary['points'] == on_disk['points']
    assert len(os.listdir(tmp_path / 'data')) == 3             # one raw file per finished point
    assert (tmp_path / 'data.csv').exists() and (tmp_path / 'bode.png').exists()


def test_main_job_batch_mode(tmp_path):
    res = subprocess.run([RUN, '--mode', 'batch', '--out', str(tmp_path), '--name', 'b',
                          '--start-hz', '2', '--step-hz', '4', '--max-hz', '14', '--periods', '5'],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    summary = json.load(open(tmp_path / 'b' / 'summary.json'))
    assert summary['complete'] and len(summary['points']) == 4
    assert summary['bandwidth_hz'] is None or summary['bandwidth_hz'] >= 7.0
    assert all(p['coherence'] > 0.9 for p in summary['points'] if p['freq_hz'] < 10)
    assert 'bandwidth (-3 dB)' in res.stdout and f'report: {tmp_path}/b/' in res.stdout


@pytest.mark.parametrize('args, words', [
    (['--max-hz', '80'], 'above Nyquist/10'),
    (['--amplitude-mm', '70'], 'beyond the stroke'),
    (['--periods', '-3'], 'periods -3'),
    (['--name', '../x'], 'expected a plain folder name'),
    (['--name', 'a/b'], 'expected a plain folder name'),
    (['--timeout', 'nan'], '--timeout nan'),
])
def test_bad_sweep_options_one_line(args, words, tmp_path):
    res = subprocess.run([RUN, '--mode', 'batch', '--out', str(tmp_path)] + args,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and 'Traceback' not in res.stderr, res.stderr
    assert not os.listdir(tmp_path), 'nothing is written for a refused sweep'


def test_a_finished_run_is_never_overwritten(tmp_path):
    """--name of a folder holding a finished run (summary.json of scripts/run, stack.json of
    run_stack) gets a new folder beside it; an unfinished one is reused."""
    from eha_ros.core.io.report import run_dir
    for marker in ('summary.json', 'stack.json'):
        base = tmp_path / marker
        (base / 'r').mkdir(parents=True)
        (base / 'r' / marker).write_text('{}')
        assert run_dir(str(base), 'r') == str(base / 'r-1')
        assert (base / 'r' / marker).read_text() == '{}'
    assert run_dir(str(tmp_path), 'fresh') == run_dir(str(tmp_path), 'fresh')


def feed(session, plan, system, load=False):
    """Drive a session with a known discrete system's response, tick by tick, until it ends."""
    seq0 = 100
    session.start(seq0)
    k, u = 0, []
    A, B, C, D = sps.tf2ss(system.num, system.den)
    state = np.zeros(A.shape[0])
    while k < session.n_run:
        v = session.load_for(seq0 + k) if load else session.reference_for(seq0 + k)
        y = float((C @ state)[0] + D[0, 0] * v)
        state = A @ state + B[:, 0] * v
        session.record('load' if load else 'reference', seq0 + k, v)
        session.record('truth', seq0 + k, y)
        session.progress(seq0 + k)
        u.append(v)
        k += 1
    return np.array(u)


def test_sweep_stops_after_the_first_point_below_3db(tmp_path):
    # a second-order lag with its -3 dB point at 15.04 Hz: the sweep planned to 30 Hz stops at
    # 16 Hz, brackets the bandwidth and is complete; the reference rests at the offset after it
    plan = SteppedSine(1, 1, 30, 5, 0.1, 1e-3, offset=2e-3)
    wn = 2 * np.pi * 15.0
    sys_ = sps.cont2discrete(([wn ** 2], [1, 1.4 * wn, wn ** 2]), 1e-3, 'bilinear')
    d = sps.dlti(np.ravel(sys_[0]), sys_[1], dt=1e-3)
    s = SweepSession(plan, str(tmp_path), {}, background_writes=False, stop_at_db=-3.0)
    u = feed(s, plan, d)
    summary = s.finish()
    freqs = [p['freq_hz'] for p in summary['points']]
    assert freqs == list(range(1, len(freqs) + 1)) and summary['points'][-1]['gain_db'] < -3.0
    assert all(p['gain_db'] >= -3.0 for p in summary['points'][:-1])
    assert summary['complete'] and summary['stopped_at_bandwidth']
    _, h = sps.dfreqresp(d, w=2 * np.pi * np.linspace(1, 30, 2901) * 1e-3)
    f_true = np.linspace(1, 30, 2901)[np.argmax(20 * np.log10(np.abs(h)) < -3.0)]
    assert freqs[-1] == np.ceil(f_true)
    assert summary['bandwidth_hz'] == pytest.approx(f_true, abs=0.2)   # dB over log f, 1 Hz steps
    stop = plan.segments[len(freqs)].start                       # where the next sine would start
    assert np.all(u[stop:] == 2e-3) and s.n_run < plan.n_ticks
    assert s.reference_for(100 + stop + 5) == 2e-3


def test_no_point_is_analysed_after_the_stop(tmp_path):
    # sines shorter than the rest after the stop (4 periods at 40 Hz = 0.1 s, relax 0.02 s):
    # the stopped plan's flat reference must not be analysed as the next frequencies
    plan = SteppedSine(30, 10, 50, 4, 0.02, 1e-4)
    s = SweepSession(plan, str(tmp_path), {}, background_writes=False, stop_at_db=-3.0)
    s.start(0)
    for k in range(plan.n_ticks):                               # keeps calling progress
        r = s.reference_for(k)
        s.record('reference', k, r)
        s.record('truth', k, 0.5 * r)
        s.progress(k)
    summary = s.finish()
    assert [p['freq_hz'] for p in summary['points']] == [30.0]
    assert summary['points'][0]['gain_db'] == pytest.approx(-6.02, abs=0.01)
    assert summary['complete'] and summary['stopped_at_bandwidth']


def test_stepped_sine_stays_below_max_accel():
    plan = SteppedSine(1, 1, 50, 4, 0.1, 1e-3, max_accel=5.0)
    for seg in plan.segments:
        a = np.max(np.abs(np.diff(plan.array()[seg.start:seg.stop], 2))) / 1e-6   # inside the sine
        assert a <= 5.0 * 1.01
        assert seg.amplitude == pytest.approx(min(1e-3, 5.0 / (2 * np.pi * seg.freq_hz) ** 2))


def test_load_session_reports_stiffness(tmp_path):
    # x = F / k with a pure spring of 80 kN/mm: |F|/|x| = 80 at every frequency; reference held
    plan = SteppedSine(0, 0, 0, 6, 0.1, 5e3, freqs=(1.0, 4.0, 7.0))
    spring = sps.dlti([1 / 80e6], [1], dt=1e-3)
    s = SweepSession(plan, str(tmp_path), {}, background_writes=False, excite='load',
                     position=3e-3, stiffness_bound=lambda f: 49.0)
    feed(s, plan, spring, load=True)
    summary = s.finish()
    assert [r['stiffness_kn_per_mm'] for r in summary['stiffness']] == pytest.approx([80] * 3)
    assert summary['stiffness_min_ratio_to_bound'] == pytest.approx(80 / 49)
    assert summary['stiffness_meets_bound'] and summary['bandwidth_hz'] is None
    assert s.reference_for(100 + plan.segments[1].start + 3) == 3e-3
    assert (tmp_path / 'stiffness.png').exists() and not (tmp_path / 'bode.png').exists()


def test_main_job_sweeps_to_the_bandwidth_and_measures_stiffness(tmp_path):
    # the default sweep runs until the first frequency below -3 dB (stack controller: about
    # 19-20 Hz, the linear model predicts 19); the stiffness run: eq. 4.60 on the nominal plant
    res = subprocess.run([RUN, '--mode', 'batch', '--out', str(tmp_path), '--name', 'bw'],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    s = json.load(open(tmp_path / 'bw' / 'summary.json'))
    print('bandwidth', s['bandwidth_hz'], 'last point', s['points'][-1])
    assert s['complete'] and s['stopped_at_bandwidth'] and 15.0 <= s['bandwidth_hz'] <= 25.0
    assert s['points'][-1]['gain_db'] < -3.0 and all(p['coherence'] > 0.99 for p in s['points'])
    res = subprocess.run([RUN, '--mode', 'batch', '--stiffness', '--out', str(tmp_path),
                          '--name', 'st'], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    s = json.load(open(tmp_path / 'st' / 'summary.json'))
    print('stiffness', s['stiffness'])
    assert [r['freq_hz'] for r in s['stiffness']] == [1.0, 4.0, 7.0]
    assert s['stiffness_meets_bound'] and s['stiffness_min_kn_per_mm'] >= 49.0
    assert 'dynamic stiffness: min' in res.stdout


def load_step_session(tmp_path, **over):
    """A load_step session from the sweep's own parameters (config/ plus ``over``)."""
    from eha_ros.core.sim.batch import node_params
    from eha_ros.core.sweep.params import SCHEMA, build_plan
    from eha_ros.core.sweep.session import from_params
    over = {'mode': 'load_step', **over}
    p = node_params('sweep', SCHEMA, overrides={f'sweep:sweep.{k}': v for k, v in over.items()})
    plan = build_plan(p)
    return from_params(p, plan, str(tmp_path), {'mode': 'load_step'}, background_writes=False)


def test_load_step_session_reports_the_campaign_figures(tmp_path, capsys):
    # synthetic run held at 2 mm: the loop holds the sensor without its white noise (truth +
    # Gauss-Markov offset) near the reference, so the truth carries minus the offset; the
    # load deflects it by a decaying bump. The plant's truth of tick k reports the load
    # applied during tick k-1 -> k: the session puts the step one tick before that truth
    from eha_ros.core.sweep.analysis import LOAD_STEP, load_step_figures
    s = load_step_session(tmp_path, offset=2e-3)
    n, Ts, seq0 = s.n, s.Ts, 1000
    t = np.arange(n) * Ts
    rng = np.random.default_rng(4)
    off = 15e-6 + 5e-6 * np.sin(2 * np.pi * 0.3 * t)
    after = np.clip(t - 0.5, 0.0, None)
    bump = -150e-6 * after / 0.02 * np.exp(1 - after / 0.02) - 8e-6 * (after > 0)
    truth = 2e-3 + bump - off
    estimate = truth + off + 1e-6 * rng.standard_normal(n)
    s.start(seq0)
    loads = np.array([s.load_for(seq0 + k) for k in range(n)])
    assert loads[499] == 0.0 and loads[500] == 5e3 and loads[-1] == 5e3
    assert {s.reference_for(seq0 + k) for k in (0, 600, n - 1)} == {2e-3}
    for k in range(n):
        s.record('truth', seq0 + k, truth[k])
        s.record('sensor_offset', seq0 + k, off[k])
        s.record('estimate', seq0 + k, estimate[k])
        s.record('load', seq0 + k, loads[k - 1] if k else 0.0)
    summary = s.finish()
    p = LOAD_STEP
    want = load_step_figures({'t': t, 'truth': truth - 2e-3, 'sensor_lf': truth + off - 2e-3,
                              'estimate': estimate - 2e-3}, p, Ts)
    assert summary['complete'] and summary['status'] == 'complete'
    assert summary['analysis'] == 'load_step' and summary['output'] == 'truth'
    assert summary['step_time_s'] == pytest.approx(p['t_step'])
    assert summary['steady_window_s'] == pytest.approx(p['steady'])
    for key, value in want.items():
        assert summary[key] == pytest.approx(value, rel=1e-12), key
    assert summary['peak_deviation_m'] == pytest.approx(150e-6 + 8e-6, abs=3e-6)
    assert summary['steady_error_m'] == pytest.approx(8e-6, abs=0.1e-6)
    assert summary['steady_error_truth_m'] > summary['steady_error_m'] + 5e-6
    assert json.load(open(tmp_path / 'summary.json')) == json.loads(json.dumps(summary))
    assert 'sensor_offset' in open(tmp_path / 'data.csv').readline()
    print_table(summary)
    out = capsys.readouterr().out
    assert 'steady error (truth + sensor offset)' in out and out.strip().endswith('complete')


@pytest.mark.parametrize('shift, words', [
    (-200, 'a load reached the plant at 0.300 s, before the step planned at 0.5 s'),
    (600, 'the load step reached the plant at 1.100 s, 600 ms after the plan: the run of 5.5 s '
          'ends before its steady window'),
])
def test_a_load_step_off_its_plan_is_incomplete(tmp_path, shift, words):
    """The step is where the truth reports it; one that reached the plant well before the plan
    is not the sweep's, one so late that the run ends inside its steady window (a sweep lagging
    behind the plant in real time) cannot give the decided figure: incomplete, one line."""
    s = load_step_session(tmp_path)
    s.start(0)
    for k in range(s.n):
        s.record('truth', k, 0.0)
        s.record('sensor_offset', k, 0.0)
        s.record('estimate', k, 0.0)
        s.record('load', k, s.load_for(k - shift - 1))
    summary = s.finish()
    assert not summary['complete'] and summary['status'].startswith(words), summary['status']
    assert '\n' not in summary['status'] and summary['steady_error_m'] is None


def test_load_step_without_truth_is_incomplete_with_one_line(tmp_path, capsys):
    """A plant side without /eha/sim/truth (the hardware bridge): the figures are not taken
    from the estimate; the summary is incomplete and says why in one line."""
    s = load_step_session(tmp_path)
    s.start(0)
    for k in range(s.n):
        s.record('estimate', k, 1e-6)
        s.record('measured', k, 1e-6)
    summary = s.finish()
    assert not summary['complete'] and summary['peak_deviation_m'] is None
    assert summary['status'] == "the load step needs /eha/sim/truth (the simulator's ground truth)"
    print_table(summary)
    assert capsys.readouterr().out.strip().splitlines()[-1] == \
        "load step: INCOMPLETE: the load step needs /eha/sim/truth (the simulator's ground truth)"


def test_load_step_shorter_than_its_window_is_refused_in_one_line():
    from eha_ros.core.config.params import ParamError
    from eha_ros.core.sim.batch import node_params
    from eha_ros.core.sweep.params import SCHEMA
    with pytest.raises(ParamError) as err:
        node_params('sweep', SCHEMA, overrides={'sweep:sweep.mode': 'load_step',
                                                'sweep:sweep.load_step_duration': 4.9})
    assert 'expected at least 5 s' in str(err.value) and '\n' not in str(err.value)


def test_the_loops_safe_state_aborts_the_sweep(tmp_path):
    # the switch manager in FAILED_SAFE holds the actuator: nothing after it is the loop's
    # response, so the sweep is aborted and incomplete (a first run once reported a 1.00 Hz
    # bandwidth, "complete", from a loop its supervisor had put in the safe state)
    plan = SteppedSine(1, 2, 9, 6, 0.1, 1e-3)
    s = SweepSession(plan, str(tmp_path), {'mode': 'stepped'}, background_writes=False)
    assert not s.check_manager('ACTIVE_A', '')
    s.start(100)
    for i in range(500):
        s.record('reference', 100 + i, plan.array()[i])
        s.record('truth', 100 + i, plan.array()[i])
    assert s.check_manager('FAILED_SAFE', 'loop supervisor: estimator: no answer')
    assert not s.check_manager('FAILED_SAFE', 'again')          # reported once
    summary = s.finish()
    assert summary['complete'] is False
    assert summary['status'] == ('aborted: safe state: switch manager FAILED_SAFE (loop '
                                 'supervisor: estimator: no answer)')
