"""The sweep node over DDS with the full simulated stack (lock-step, so the figures measure the
loop, not the CPU): bandwidth and coherence; Ctrl-C keeps the finished frequencies; bad
parameters stop the node with one line."""
import json
import subprocess

import numpy as np

import pytest

from eha_ros.stack import Stack, node_command
from ros_util import start_process, stop_process, wait_for

pytestmark = pytest.mark.ros
SHORT = ['-p', 'sweep:sweep.start_hz:=1.0', '-p', 'sweep:sweep.increment_hz:=3.0',
         '-p', 'sweep:sweep.max_hz:=13.0', '-p', 'sweep:sweep.periods:=6',
         '-p', 'sweep:sweep.relax_s:=0.2']


@pytest.fixture(scope='module')
def stack():
    st = Stack(['plant_sim', 'estimator', 'controller'], lockstep=True).start()
    yield st
    for name, (code, err) in st.stop().items():
        assert 'Traceback' not in err, (name, err)


def sweep_cmd(out, name):
    return node_command('sweep', extra=SHORT + ['-p', 'use_sim_time:=true','-p', f'sweep:sweep.out_dir:={out}',
                                                '-p', f'sweep:sweep.run_name:={name}'])


def points_done(summary_path) -> int:
    """Frequencies finished so far, from the summary the sweep rewrites as it goes."""
    try:
        return len(json.load(open(summary_path))['points'])
    except (OSError, ValueError):
        return 0


def test_stepped_sweep_over_dds(stack, tmp_path):
    res = subprocess.run(sweep_cmd(tmp_path, 'full'), capture_output=True, text=True, timeout=240)
    summary = json.load(open(tmp_path / 'full' / 'summary.json'))
    print(json.dumps({k: summary[k] for k in ('bandwidth_hz', 'phase_at_7hz_deg', 'complete')}))
    for p in summary['points']:
        print(p)
    assert res.returncode == 0, res.stderr[-2000:]
    assert summary['complete'] and [p['freq_hz'] for p in summary['points']] == [1, 4, 7, 10, 13]
    assert summary['bandwidth_hz'] is None or summary['bandwidth_hz'] >= 7.0
    assert all(p['coherence'] > 0.9 for p in summary['points'] if p['freq_hz'] < 10)
    assert (tmp_path / 'full' / 'bode.png').exists() and (tmp_path / 'full' / 'data.csv').exists()


def test_interrupt_mid_sweep_keeps_finished_points(stack, tmp_path):
    proc = start_process(sweep_cmd(tmp_path, 'cut'))
    summary_path = tmp_path / 'cut' / 'summary.json'
    assert wait_for(lambda: points_done(summary_path) >= 2, 120), 'no frequency finished'
    code, out, err = stop_process(proc)                 # SIGINT, like Ctrl-C
    summary = json.load(open(summary_path))
    assert summary['complete'] is False and summary['status'] == 'interrupted'
    assert [p['freq_hz'] for p in summary['points']][:2] == [1, 4]
    assert all(p['coherence'] > 0.9 for p in summary['points'])
    assert 'Traceback' not in err


def test_the_loops_safe_state_aborts_the_sweep_over_dds(stack, ros_node, tmp_path):
    # FAILED_SAFE on eha/redundancy (remapped here, so the module's controller never sees it)
    # mid-sweep: the sweep stops with the reason, exit 1, summary incomplete, no traceback
    from eha_msgs.msg import RedundancyStatus
    from eha_ros.nodes.common import latched_qos
    topic = '/test_sweep/redundancy'
    proc = start_process(sweep_cmd(tmp_path, 'safe') + ['-r', f'eha/redundancy:={topic}'])
    summary_path = tmp_path / 'safe' / 'summary.json'
    pub = ros_node.create_publisher(RedundancyStatus, topic, latched_qos())
    try:
        assert wait_for(lambda: points_done(summary_path) >= 1, 120), 'no frequency finished'
        msg = RedundancyStatus()
        msg.state, msg.reason = 'FAILED_SAFE', 'test: loop supervisor'
        pub.publish(msg)                    # latched: delivered once the sweep has matched
        proc.wait(timeout=60)
    finally:
        code, out, err = stop_process(proc)
        ros_node.destroy_publisher(pub)
    summary = json.load(open(summary_path))
    print(summary['status'], err[-600:])
    assert code == 1 and 'Traceback' not in err
    assert summary['complete'] is False
    assert summary['status'] == 'aborted: safe state: switch manager FAILED_SAFE (test: loop ' \
                                'supervisor)'
    assert 'safe state: switch manager FAILED_SAFE' in err


def test_stiffness_over_dds(stack, tmp_path):
    # mode stiffness: the sweep node drives /eha/sim/load_force (5 kN at 1, 4, 7 Hz) and holds
    # the reference; the nominal loop on the estimate meets eq. 4.60 (>= 49 kN/mm) at each
    cmd = node_command('sweep', extra=['-p', 'use_sim_time:=true',
                                       '-p', 'sweep:sweep.mode:=stiffness',
                                       '-p', f'sweep:sweep.out_dir:={tmp_path}',
                                       '-p', 'sweep:sweep.run_name:=st'])
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    summary = json.load(open(tmp_path / 'st' / 'summary.json'))
    print(summary['stiffness'])
    assert res.returncode == 0, res.stderr[-2000:]
    assert summary['complete'] and summary['excite'] == 'load'
    assert [r['freq_hz'] for r in summary['stiffness']] == [1.0, 4.0, 7.0]
    assert all(r['stiffness_kn_per_mm'] >= r['bound_kn_per_mm'] >= 49.0
               for r in summary['stiffness'])
    # under a varying load the estimator cannot tell the sensor's 1 Hz Gauss-Markov offset from
    # the piston (docs/estimator.md), so the held truth wanders with it (tens of um). The loop's
    # answer to 5 kN is |F|/stiffness: ~21 um at 7 Hz, above that wander (coherence 0.70-0.87
    # seen; since the position noise opens while the load swings, 0766403, the estimate and so
    # the held truth follow the sensor's wander more: 0.66-0.76 here, 0.47 once in CI), but 3-13
    # um at 1-4 Hz, where coherence has been seen from 0.04 to 0.59 (CI: 0.036 at 1 Hz, 1741
    # kN/mm). Noise uncorrelated with the load only adds to |x| in the single-bin ratio, so it
    # biases the figure low: above its bound it is a conservative pass. The 7 Hz check asks
    # that the load's answer is there at all (no answer: coherence near 0).
    coh = {p['freq_hz']: p['coherence'] for p in summary['points']}
    assert coh[7.0] > 0.3, coh
    assert (tmp_path / 'st' / 'stiffness.png').exists()


def test_bad_sweep_parameter_stops_node_with_one_line():
    res = subprocess.run(node_command('sweep', extra=['-p', 'sweep:sweep.amplitude:=0.08']),
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and 'beyond the stroke' in lines[0], res.stderr


def sweep_in_process(tmp_path, **params):
    """The sweep node in this process, fed by calling its callbacks (no DDS timing)."""
    from eha_ros.core.sim.batch import node_params
    from eha_ros.core.sweep.params import SCHEMA
    from eha_ros.nodes import sweep
    p = dict(node_params('sweep', SCHEMA), **{'sweep.start_delay': 0.0,
                                               'sweep.out_dir': str(tmp_path), **params})
    return sweep.make_node(p)


def test_plan_starts_after_every_tick_already_seen(rclpy_session, tmp_path):
    """A state handled after the estimates, commands and truth of later ticks (its queue behind
    theirs) starts the plan after the newest of them, so no tick of the plan lost a stream
    before the start (CI once lost the first 610 ticks of estimate, command and truth: the 1 Hz
    point had no data)."""
    from eha_msgs.msg import ActuatorCommand, ActuatorState, PlantTruth, PositionEstimate
    node = sweep_in_process(tmp_path)
    try:
        for k in range(100, 701):              # estimate, command, truth up to tick 700 ...
            node.on_command(ActuatorCommand(seq=k))
            node.on_estimate(PositionEstimate(seq=k, position=1e-6 * k))
            node.on_truth(PlantTruth(seq=k, position=1e-6 * k))
        node.on_state(ActuatorState(seq=100))  # ... before state 100
        lead = node.lead
        assert node.session.seq0 == 700 + lead
        for k in range(701, 800):
            node.on_estimate(PositionEstimate(seq=k, position=1e-6 * k))
        est = node.session.data['estimate'][:800 - 700 - lead]
        assert np.isfinite(est).all()         # every tick of the plan so far has its estimate
    finally:
        node.destroy_node()


def feed_tick(node, k, estimate=True):
    """The truth (load as planned, piston held), command and state of tick k; its estimate."""
    from eha_msgs.msg import ActuatorCommand, ActuatorState, PlantTruth, PositionEstimate
    node.on_truth(PlantTruth(seq=k, load_force=float(node.session.load_for(k))))
    node.on_command(ActuatorCommand(seq=k))
    if estimate:
        node.on_estimate(PositionEstimate(seq=k))
    node.on_state(ActuatorState(seq=k))


def test_the_run_ends_once_a_lagging_stream_has_its_last_ticks(rclpy_session, tmp_path):
    """A reliable reader that lost a sample holds the later ones until the writer repairs the
    gap (Fast DDS: up to 3 s) while the states go on. The load step must not end on the states
    alone: CI once ended it with the estimates of over 5 % of its ticks still on their way
    ('estimate: recorded on fewer than 95 % of the ticks')."""
    from eha_msgs.msg import PositionEstimate
    from eha_ros.nodes.sweep import MARGIN_TICKS
    node = sweep_in_process(tmp_path, **{'sweep.mode': 'load_step', 'sweep.run_name': 'ls'})
    try:
        feed_tick(node, 0)
        s = node.session
        seq0, n = s.seq0, s.n_run
        held = seq0 + n - 400                  # estimates after this one are held back
        last = seq0 + n + MARGIN_TICKS + 50    # the states go well past the end
        for k in range(1, last + 1):
            feed_tick(node, k, estimate=k <= held)
        assert not s.finished                  # waiting for the estimates
        for k in range(held + 1, last + 1):    # the repair delivers them
            node.on_estimate(PositionEstimate(seq=k))
        feed_tick(node, last + 1)
        assert s.finished
        summary = json.load(open(tmp_path / 'ls' / 'summary.json'))
        assert summary['complete'], summary['status']
        assert np.isfinite(s.data['estimate'][:n]).all()
    finally:
        node.destroy_node()


def test_a_stream_that_never_catches_up_ends_the_run_after_the_wait(rclpy_session, tmp_path,
                                                                    monkeypatch, capfd):
    """The wait for a lagging stream is bounded (sweep.STREAM_WAIT_S after the states reached
    the end): the run ends then, with one warning naming the stream and the ticks it lacks."""
    import time
    from eha_msgs.msg import PositionEstimate
    from eha_ros.nodes import sweep
    monkeypatch.setattr(sweep, 'STREAM_WAIT_S', 0.3)
    node = sweep_in_process(tmp_path, **{'sweep.mode': 'step', 'sweep.step_duration': 0.5,
                                         'sweep.run_name': 'st'})
    try:
        feed_tick(node, 0)
        s = node.session
        end = s.seq0 + s.n_run + sweep.MARGIN_TICKS
        for k in range(1, end + 1):            # the estimates trail the states by 100 ticks
            feed_tick(node, k, estimate=False)
            node.on_estimate(PositionEstimate(seq=max(k - 100, 0)))
        assert not s.finished
        time.sleep(0.35)
        node.on_estimate(PositionEstimate(seq=end - 99))
        feed_tick(node, end + 1, estimate=False)
        assert s.finished
        last = s.seq0 + s.n_run - 1
        warn = [line for line in capfd.readouterr().err.splitlines() if 'reached tick' in line]
        assert len(warn) == 1 and (f'estimate reached tick {end - 99}, the run ends at tick '
                                   f'{last}: ended without its last {last - end + 99} ticks'
                                   in warn[0]), warn
    finally:
        node.destroy_node()
