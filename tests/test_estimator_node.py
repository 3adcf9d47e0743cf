"""estimator node as a separate process over DDS: one estimate per state with the same seq and
stamp, NaN measurement -> predict only, counted and reported, stale when the states stop,
bad parameters -> one line and exit 2."""
import contextlib
import math
import os
import re
import subprocess
import threading
import time

import numpy as np
import pytest

import probes
from ros_util import ROOT, VENV_BIN, start_process, stop_process, wait_for

pytestmark = pytest.mark.ros
PLANT = [os.path.join(ROOT, 'config', 'plant.yaml')]
EST = PLANT + [os.path.join(ROOT, 'config', 'estimator.yaml')]
SIM = PLANT + [os.path.join(ROOT, 'config', 'plant_sim.yaml')]


def cmd(name, files, *extra):
    args = [os.path.join(VENV_BIN, name), '--ros-args']
    for f in files:
        args += ['--params-file', f]
    return args + list(extra)


class Probe(probes.Probe):
    def __init__(self, node, ns=''):
        from eha_msgs.msg import ActuatorState, PositionEstimate
        from rclpy.qos import QoSProfile
        qos = QoSProfile(depth=2000)
        super().__init__(node)
        self.states = self.by_seq(ActuatorState, f'{ns}/eha/state', qos)
        self.estimates = self.received(PositionEstimate, f'{ns}/eha/estimate', qos, stamped=True)
        self.ns = ns or '/'
        self.state_pub = node.create_publisher(ActuatorState, f'{ns}/eha/state', qos)
        self.State = ActuatorState

    @property
    def diags(self):
        return [s.values for s in self.diagnostics.all(f'estimator: filter {self.ns}')]

    def clear(self):
        with self.lock:
            self.states.clear()
            self.estimates.clear()


@pytest.fixture(scope='module')
def stack():
    est = start_process(cmd('estimator', EST))
    plant = start_process(cmd('plant_sim', SIM))
    procs = {'estimator': est, 'plant_sim': plant}
    yield procs
    errs = {name: stop_process(p)[2] for name, p in procs.items()}     # all stopped, then
    for name, err in errs.items():                                     # checked
        assert 'Traceback' not in err, f'{name}: {err}'


def test_bad_params_file_one_line_exit_2(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('estimator:\n  ros__parameters:\n    estimator:\n      filter: ekf\n')
    res = subprocess.run(cmd('estimator', PLANT + [str(bad)]), capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and 'estimator.filter' in lines[0] and 'model|pva' in lines[0], \
        res.stderr
    broken = tmp_path / 'broken.yaml'
    broken.write_text('estimator:\n  ros__parameters: [\n')
    res = subprocess.run(cmd('estimator', [str(broken)]), capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert 'Traceback' not in res.stderr


class Stream:
    """Crafted states to ``probe``'s estimator at about 1 kHz from a thread: seq counts up,
    a noisy position about 1 mm (a noise-free constant would rightly be reported stuck),
    motors at rest, both pressures 10 bar; ``fill(m)`` changes the message before it goes."""

    def __init__(self, probe, node, fill=None):
        self.probe, self.node, self.fill = probe, node, fill
        self.seq = 1
        self.rng = np.random.default_rng(0)
        self.stop = threading.Event()
        self.th = threading.Thread(target=self.run, daemon=True)
        self.th.start()

    def run(self):
        while not self.stop.is_set():
            m = self.probe.State()
            m.header.stamp = self.node.get_clock().now().to_msg()
            m.seq = self.seq
            m.position = 1e-3 + 1e-5 * self.rng.normal()
            m.motor_speed = [0.0, 0.0]
            m.pressure_a = m.pressure_b = 1.0e6
            m.active_channel = 0
            m.valid = True
            if self.fill is not None:
                self.fill(m)
            self.probe.state_pub.publish(m)
            self.seq += 1
            time.sleep(0.001)

    def close(self):
        self.stop.set()
        self.th.join()


@contextlib.contextmanager
def crafted(ros_node, ns, fill):
    """An estimator alone on ``ns``, fed a crafted :class:`Stream` with ``fill`` until it
    answers (discovery); yields (probe, stream, log), log['err'] its stderr once stopped."""
    proc = start_process(cmd('estimator', EST, '-r', f'__ns:={ns}', '-p',
                             'estimator:estimator.node.diagnostics_period:=0.2'))
    log, stream = {}, None
    try:
        probe = Probe(ros_node, ns)
        stream = Stream(probe, ros_node, fill)
        assert wait_for(lambda: len(probe.estimates) > 200, 60), \
            f'no estimates from the estimator on {ns}'
        yield probe, stream, log
    finally:
        if stream is not None:
            stream.close()
        log['err'] = stop_process(proc)[2]
    assert 'Traceback' not in log['err'], log['err']


def test_nan_measurement_predict_only_counted_and_reported(ros_node):
    """A crafted state stream to an estimator alone on /est_test; a few NaN positions."""
    nan_seqs = set()

    def fill(m):
        if m.seq in nan_seqs:
            m.position = float('nan')

    # good states until the estimator answers (discovery), then NaN
    with crafted(ros_node, '/est_test', fill) as (probe, stream, log):
        answered, bursts = [], 0
        # the good states after the NaN ones are updates again. A loaded machine may lose a
        # stretch of estimates on their way to the probe (CI: first+100..+199 once, all 250 of
        # first+51..+300 another time): the stream runs until 20 of them came, not a set time,
        # and a burst whose NaN states' estimates were lost is repeated (3 bursts at most)
        while len(answered) < 4 and bursts < 3:
            first = stream.seq + 100
            burst = [*range(first, first + 5), first + 50]
            nan_seqs.update(burst)
            bursts += 1

            def good():
                return [e for _, e in list(probe.estimates)
                        if e.seq > first + 50 and not e.stale]

            assert wait_for(lambda: len(good()) >= 20, 60), \
                f'{len(good())} fresh estimates of the good states after the NaN ones in 60 s'
            by_seq = {e.seq: e for _, e in list(probe.estimates) if not e.stale}
            answered = [s for s in burst if s in by_seq]
        stream.close()
        # on a heavily loaded machine the estimator may miss a state (then counted as lost)
        assert len(answered) >= 4, \
            f'estimates for only {len(answered)} of 6 NaN states, in each of {bursts} bursts'
        for s in answered:
            e = by_seq[s]
            assert e.update_skipped and math.isfinite(e.position)
            assert abs(e.position - 1e-3) < 1e-4
        assert wait_for(lambda: any(int(d.get('estimator_rejected_position', 0)) >= len(answered)
                                    for d in list(probe.diags)), 10), str(probe.diags[-1:])
        assert not any(e.update_skipped for e in good())
        d = probe.diags[-1]
        assert int(d['estimator_skipped_updates']) >= len(answered)
        assert int(d['rejected_states']) >= len(answered)
        # the measured noise levels (core.estimator.noise_level): the crafted position has the
        # datasheet's white sigma (10 um; no Gauss-Markov part: 0.99), its pressures none
        assert 0.85 < float(d['noise_level_position']) < 1.15, d
        assert float(d['noise_level_pressure']) == 0.5, d     # bottom of adapt_range
    assert 'rejected position' in log['err']


def test_a_two_sample_glitch_is_held_back_counted_and_logged(ros_node):
    """Two consecutive states read 1 mm off (a glitch of the position sensor): the estimator
    does not take them (a suspected jump, fault_detector.suspect), reports no fault, counts
    them on /diagnostics (jump_suspect_samples) and logs them once per diagnostics period that
    had any. A loaded machine can lose every estimate near a glitch on its way to the probe
    (CI lost 250 in a row once): then the glitch is repeated 400 ticks on, 3 glitches at most."""
    glitch = set()

    def fill(m):
        if m.seq in glitch:
            m.position += 1e-3

    with crafted(ros_node, '/est_glitch', fill) as (probe, stream, log):
        near, glitches = [], 0
        while not near and glitches < 3:
            first = stream.seq + 100
            glitch.update((first, first + 1))
            glitches += 1
            assert wait_for(lambda: any(e.seq > first + 300 for _, e in list(probe.estimates)),
                            30)
            by_seq = {e.seq: e for _, e in list(probe.estimates) if not e.stale}
            near = [e for s, e in by_seq.items() if first <= s <= first + 50]
        stream.close()
        assert near, f'no estimate around any of {glitches} glitches reached the probe'
        assert all(abs(e.position - 1e-3) < 50e-6 for e in near), \
            max(abs(e.position - 1e-3) for e in near)
        assert not any(e.sensor_fault for e in near)
        # a held-back sample's estimate is predict only: update_skipped, on glitch samples only
        assert all(e.seq in glitch for e in near if e.update_skipped), \
            [e.seq for e in near if e.update_skipped]
        assert wait_for(lambda: any(int(d.get('jump_suspect_samples', 0)) > 0
                                    for d in list(probe.diags)), 10), str(probe.diags[-1:])
        d = probe.diags[-1]
        assert 1 <= int(d['jump_suspect_samples']) <= 2 * glitches, (d, glitches)
        assert int(d['detections_jump']) == 0 and d['consistency'] == 'ok', d
    # one line per diagnostics period that had any: a glitch across a period's end gives two;
    # each line's count is what the period added to the total it names
    lines = [(int(n), int(total)) for n, total in re.findall(
        r'(\d+) position samples held back as a suspected sensor jump \(jump_suspect_samples '
        r'(\d+)\)', log['err'])]
    added = [n for n, _ in lines]
    assert 1 <= len(lines) <= 2 * glitches and sum(added) <= 2 * glitches, (log['err'], glitches)
    assert [total for _, total in lines] == list(np.cumsum(added)), lines


def test_blamed_pressure_sensors_position_only_from_then_on(ros_node):
    """The switch manager blames the chamber pressure sensors on /eha/redundancy: the
    estimator updates on the position alone from then on (logged once, pressures_used false
    on /diagnostics). Before, NaN pressures are rejected and counted; after, they are not
    read at all."""
    from eha_msgs.msg import RedundancyStatus
    from eha_ros.nodes.common import latched_qos
    proc = start_process(cmd('estimator', EST, '-r', '__ns:=/est_p', '-p',
                             'estimator:estimator.node.diagnostics_period:=0.2'))
    stream = None
    try:
        probe = Probe(ros_node, '/est_p')
        nan_from = [math.inf]

        def fill(m):
            if m.seq >= nan_from[0]:
                m.pressure_a = float('nan')

        stream = Stream(probe, ros_node, fill)
        assert wait_for(lambda: len(probe.estimates) > 200, 60), 'no estimates on /est_p'
        nan_from[0] = stream.seq
        assert wait_for(lambda: any(int(d.get('estimator_rejected_pressure', 0)) > 0
                                    for d in list(probe.diags)), 20), probe.diags[-1:]
        status = ros_node.create_publisher(RedundancyStatus, '/est_p/eha/redundancy',
                                           latched_qos())
        for _ in range(2):                      # re-sent status: still one log line
            status.publish(RedundancyStatus(active_channel=1, channel_healthy=[True, True],
                                            state='ACTIVE_B', pressure_sensors_failed=True))
        assert wait_for(lambda: any(d.get('pressures_used') == 'False'
                                    for d in list(probe.diags)), 20), probe.diags[-1:]
        rejected = int(probe.diags[-1]['estimator_rejected_pressure'])
        seq = stream.seq
        assert wait_for(lambda: any(int(d.get('last_seq', 0)) > seq + 300
                                    for d in list(probe.diags)), 30)
        d = probe.diags[-1]
        assert int(d['estimator_rejected_pressure']) == rejected and \
            int(d['pressure_stops']) == 1, d
        skipped = [e.seq for _, e in list(probe.estimates) if e.seq > seq and not e.stale
                   and e.update_skipped]
        assert not skipped, skipped[:10]
    finally:
        if stream is not None:
            stream.close()
        code, out, err = stop_process(proc)
    assert 'Traceback' not in err, err
    assert err.count('blamed the chamber pressure sensors') == 1, err


def test_one_estimate_per_state_same_seq_and_stamp(stack, ros_node):
    probe = Probe(ros_node)
    assert wait_for(lambda: len(probe.estimates) > 200, 60), 'no /eha/estimate'
    time.sleep(0.5)
    probe.clear()
    time.sleep(3.0)
    with probe.lock:
        states = dict(probe.states)
        ests = [e for _, e in probe.estimates]
    fresh = [e for e in ests if not e.stale]
    by_seq = {}
    for e in fresh:
        by_seq.setdefault(e.seq, []).append(e)
    assert all(len(v) == 1 for v in by_seq.values()), 'more than one estimate for a seq'
    common = [s for s in states if s in by_seq]
    missing = [s for s in states if s not in by_seq]
    lo, hi = min(states) + 20, max(states) - 20          # edges of the window
    inner_missing = [s for s in missing if lo <= s <= hi]
    print(f'{len(states)} states, {len(fresh)} estimates, {len(inner_missing)} without estimate, '
          f'{len(ests) - len(fresh)} stale')
    # The node publishes exactly one estimate per state it receives. Seen from this test
    # process, on an overloaded machine some states or estimates are missed by either side
    # (plant_sim may also run slower than 1 kHz), so coverage is checked loosely here; the
    # node's own count of states it never got is lost_states on /diagnostics.
    assert len(states) > 300 and len(common) >= 0.5 * len(states)
    seqs = [e.seq for e in fresh]
    assert all(b > a for a, b in zip(seqs, seqs[1:])), 'estimates out of order'
    for s in common[::50]:
        assert by_seq[s][0].header.stamp == states[s].header.stamp
    pos = np.array([by_seq[s][0].position for s in common])
    meas = np.array([states[s].position for s in common])
    assert np.all(np.abs(pos - meas) < 1e-3)                 # tracks the measured piston
    assert all(e.position_variance > 0 and e.nis >= 0 for e in fresh)
    # the model's input goes on to the controller's anti-windup: the active motor's speed
    used = [s for s in common if not by_seq[s][0].update_skipped]
    assert used and all(by_seq[s][0].motor_speed ==
                        states[s].motor_speed[states[s].active_channel] for s in used)
    # not a constant: the encoder's noise (no controller here, the motor stands)
    assert len({by_seq[s][0].motor_speed for s in used}) > 0.9 * len(used)


def test_stale_marked_when_plant_stops(stack, ros_node):
    probe = Probe(ros_node)
    assert wait_for(lambda: len(probe.estimates) > 100, 30)
    code, out, err = stop_process(stack['plant_sim'])
    assert 'Traceback' not in err
    t_stop = time.monotonic()

    def stale_after_stop():
        with probe.lock:
            return sum(1 for t, e in probe.estimates if t > t_stop and e.stale)
    # one per 1 ms timer tick; on an overloaded machine fewer, so counted, not timed
    assert wait_for(lambda: stale_after_stop() > 100, 30), \
        f'estimator stopped publishing when the states stopped ({stale_after_stop()} stale)'
    with probe.lock:
        after = probe.estimates[-50:]     # the plant long gone
        last_state = max(probe.states) if probe.states else 0
    print(f'{stale_after_stop()} stale estimates in {time.monotonic() - t_stop:.2f} s after '
          f'the plant stopped')
    assert all(t > t_stop for t, _ in after)
    assert all(e.stale and e.update_skipped for _, e in after)
    assert all(e.seq > last_state for _, e in after)
    assert all(math.isfinite(e.position) for _, e in after)
    assert stack['estimator'].poll() is None


def test_failed_publish_is_counted_not_a_crash(rclpy_session, params):
    """rmw can refuse a publish ('cannot publish data') under DDS overload or at shutdown:
    the node counts it, logs it and answers the next state (it used to exit with a Traceback
    from inside its state callback)."""
    from eha_msgs.msg import ActuatorState
    from eha_ros.nodes import estimator

    class RefusingPublisher:
        calls = 0

        def publish(self, msg):
            RefusingPublisher.calls += 1
            raise RuntimeError('Failed to publish: cannot publish data')

    node = estimator.make_node(params)
    try:
        node.pub = node.pub_diag = RefusingPublisher()
        for seq in (1, 2, 3):
            m = ActuatorState(seq=seq, position=1e-3, motor_speed=[0.0, 0.0],
                              pressure_a=1.0e6, pressure_b=1.0e6, active_channel=0, valid=True)
            node.on_state(m)
        node.publish_diagnostics()
        assert RefusingPublisher.calls == 4
        assert node.c['publish_errors'] == 4
        assert node.c['estimates'] == 3 and node.last_seq == 3
    finally:
        node.destroy_node()
