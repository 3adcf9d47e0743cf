"""controller as a separate process over DDS: one command per estimate with the same seq,
watchdog to zero speed and bumpless recovery, bad references reported, bad parameters."""
import subprocess
import threading
import time

import numpy as np
import pytest

from eha_ros.stack import node_command
import probes
from ros_util import start_process, stop_process, wait_for, wait_matched

pytestmark = pytest.mark.ros


def controller_cmd(*extra, files=None):
    return node_command('controller', extra=extra, files=files)


class FakeEstimator(probes.Probe):
    """Publishes estimates at ~1 kHz from a thread; records the commands that answer them."""

    def __init__(self, node):
        from eha_msgs.msg import ActuatorCommand, PositionEstimate, PositionReference
        super().__init__(node, diagnostics=10)
        self.Est, self.Ref = PositionEstimate, PositionReference
        from eha_ros.core import topics as T
        from eha_ros.nodes.common import qos_of
        # the stream's own QoS (1000 samples; with 10, a controller starved on a loaded machine
        # lost estimates in the writer's history: 532 of 700 answered with both cores busy)
        self.pub = node.create_publisher(PositionEstimate, '/eha/estimate', qos_of(T.ESTIMATE))
        self.ref_pub = node.create_publisher(PositionReference, '/eha/reference', 10)
        self.commands = self.received(ActuatorCommand, '/eha/command', 1000)
        self.seq, self.position, self.stale, self.running = 0, 0.0, False, True
        self.leak_flow = 0.0
        self.paused = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    @property
    def diags(self):
        return [s.values for s in self.diagnostics.all('controller', prefix=True)]

    def _run(self):
        while self.running:
            if not self.paused:
                self.seq += 1
                self.pub.publish(self.Est(seq=self.seq, position=self.position, stale=self.stale,
                                          leak_flow=self.leak_flow))
            time.sleep(0.001)

    def close(self):
        self.running = False
        self.thread.join()


def answered(est, seq) -> bool:
    """An answer to the estimate ``seq`` or a later one reached the fake estimator."""
    return max((c.seq for c in est.commands[-200:]), default=0) >= seq


@pytest.fixture
def ctl(ros_node):
    proc = start_process(controller_cmd())
    est = FakeEstimator(ros_node)
    try:
        assert wait_for(lambda: len(est.commands) > 100, 60), 'controller does not answer'
        wait_matched(est.ref_pub)
        yield est
    finally:
        est.close()
        code, out, err = stop_process(proc)
        assert 'Traceback' not in err, err


def test_one_command_per_estimate_with_same_seq(ctl):
    time.sleep(1.0)                         # steady state: start-up is not what is measured
    ctl.ref_pub.publish(ctl.Ref(position=0.002))
    time.sleep(1.0)
    est_seqs = set(range(ctl.seq - 800, ctl.seq - 100))
    # the answers of the window have arrived (a loaded machine delays them)
    assert wait_for(lambda: answered(ctl, max(est_seqs)), 10)
    answers = [c for c in ctl.commands if c.seq in est_seqs]
    cmd_seqs = [c.seq for c in answers]
    # nearly every estimate answered: CI's loaded machine once missed 8 of the 700 in a row
    # (a stall at the window's start), so the share is a transport figure, not the property
    print(f'{len(cmd_seqs)} of {len(est_seqs)} estimates answered')
    assert len(cmd_seqs) >= 0.95 * len(est_seqs)
    assert len(cmd_seqs) == len(set(cmd_seqs)), 'more than one command for an estimate'
    # piston held at 0 with a 2 mm reference: the controller drives positive, clamped (the
    # window's last answer: the newest command may be a watchdog zero, seq 0)
    assert answers[-1].motor_speed_ref > 0


def test_the_leakage_compensation_supplies_the_estimated_leak_flow(ros_node):
    """control.leakage_compensation = 1 over DDS: the piston held at its reference, each
    command is the pump speed q_L / D_p that supplies the estimate's leak_flow (50 rad/s
    here, within the drive's reach, so G stays at rest); a NaN leak flow adds nothing."""
    from eha_ros.core.sim.batch import node_params
    from eha_ros.core.controller.params import SCHEMA
    D_p = node_params('controller', SCHEMA)['plant.pump.D_p']
    proc = start_process(controller_cmd('-p', 'control.leakage_compensation:=1.0'))
    est = FakeEstimator(ros_node)
    try:
        est.leak_flow = 50.0 * D_p
        assert wait_for(lambda: len(est.commands) > 200, 60), 'controller does not answer'
        seq = est.seq
        assert wait_for(lambda: answered(est, seq + 51), 10)
        assert [c.motor_speed_ref for c in est.commands if c.seq > seq] == \
            pytest.approx([50.0] * len([c for c in est.commands if c.seq > seq]), rel=1e-12)
        est.leak_flow = float('nan')
        seq = est.seq
        assert wait_for(lambda: answered(est, seq + 51), 10)
        assert all(c.motor_speed_ref == 0.0 for c in est.commands if c.seq > seq + 5)
        # the switch manager blames the pressure sensors on /eha/redundancy: the estimate's
        # leak flow comes from a wrong p_D, the compensation stops (logged once, diagnostics)
        from eha_msgs.msg import RedundancyStatus
        from eha_ros.nodes.common import latched_qos
        status = ros_node.create_publisher(RedundancyStatus, '/eha/redundancy', latched_qos())
        est.leak_flow = 50.0 * D_p
        status.publish(RedundancyStatus(active_channel=1, channel_healthy=[True, True],
                                        state='ACTIVE_B', pressure_sensors_failed=True))
        assert wait_for(lambda: any(d.get('leakage_compensation') == 'False'
                                    for d in est.diags), 20), est.diags[-1:]
        seq = est.seq
        assert wait_for(lambda: answered(est, seq + 51), 10)
        assert all(c.motor_speed_ref == 0.0 for c in est.commands if c.seq > seq)
    finally:
        est.close()
        code, out, err = stop_process(proc)
        assert 'Traceback' not in err, err
    assert err.count('blamed the chamber pressure sensors') == 1, err


def test_watchdog_zero_speed_and_bumpless_recovery(ctl):
    ctl.ref_pub.publish(ctl.Ref(position=0.0))
    ctl.position = 0.0
    time.sleep(0.5)
    ctl.paused = True                       # estimator dies
    # the watchdog's zero commands come instead of answers (seq 0: they answer no estimate;
    # an answer at rest would read 0.0 too)
    assert wait_for(lambda: len(ctl.commands) > 20 and all(
        c.seq == 0 and c.motor_speed_ref == 0.0 for c in ctl.commands[-20:]), 10), \
        [(c.seq, c.motor_speed_ref) for c in ctl.commands[-20:]]
    assert wait_for(lambda: ctl.diags and int(ctl.diags[-1].get('watchdog_trips', 0)) >= 1, 5)
    n = len(ctl.commands)
    ctl.position = 0.003                    # the piston drifted 3 mm meanwhile
    ctl.paused = False

    def answers():                          # without the watchdog's zeros before they stop
        return [c.motor_speed_ref for c in ctl.commands[n:] if c.seq != 0]

    assert wait_for(lambda: len(answers()) > 30, 10)
    after = np.array(answers()[:30])
    # recovery starts at zero output (reference restarted at the piston) and ramps with the
    # rate-limited reference; restarting on the 3 mm error would jump to the 838 rad/s clamp
    assert abs(after[0]) < 50.0, after[:10]
    assert np.all(np.abs(after[:3]) < 838.0)


def test_inactive_while_the_plant_side_is_and_bumpless_when_it_becomes_active(ctl, ros_node):
    """Issue 18: the plant side says INACTIVE on eha/plant_state (a disarmed bridge): with a
    5 mm reference and the piston at 0 the controller answers every estimate with zero and
    integrates nothing (it used to wind up to the 838 rad/s clamp); ACTIVE again: it starts
    from the piston position (first answers near zero, then driving towards the reference)."""
    from lifecycle_msgs.msg import State
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    pub = ros_node.create_publisher(State, '/eha/plant_state', qos)
    pub.publish(State(id=State.PRIMARY_STATE_INACTIVE, label='inactive'))
    assert wait_for(lambda: ctl.diags and ctl.diags[-1].get('plant_state') == 'inactive', 20), \
        ctl.diags[-1:]
    ctl.position = 0.0
    ctl.ref_pub.publish(ctl.Ref(position=0.005))
    first = ctl.seq
    # the answers to estimates first+6..first+1500, once they came (windows by seq: a loaded
    # machine delays them; a command with seq 0 is the watchdog's, no answer)
    assert wait_for(lambda: answered(ctl, first + 1500), 30)
    held = [c.motor_speed_ref for c in ctl.commands if first + 5 < c.seq <= first + 1500]
    assert len(held) > 1000 and all(u == 0.0 for u in held), max(map(abs, held))
    assert ctl.diags[-1]['active'] == 'False'
    n = len(ctl.commands)
    pub.publish(State(id=State.PRIMARY_STATE_ACTIVE, label='active'))
    assert wait_for(lambda: any(c.motor_speed_ref != 0.0 for c in ctl.commands[n:]), 10)
    s1 = next(c.seq for c in ctl.commands[n:] if c.motor_speed_ref != 0.0)
    assert wait_for(lambda: answered(ctl, s1 + 299), 30)
    after = np.array([c.motor_speed_ref for c in ctl.commands if s1 <= c.seq < s1 + 300])
    # bumpless: the reference ramps from the piston at 190 mm/s, the output builds up from
    # near zero (a 5 mm error at once would be the clamp) and drives towards +5 mm
    assert len(after) > 250 and abs(after[0]) < 50.0 and after[-1] > 0.0, after[:10]
    ctl.ref_pub.publish(ctl.Ref(position=0.0))


def test_managed_controller_change_state_inactive_active_bumpless(ros_node):
    """Issue 18: the controller as a managed node, driven by an independent client over
    lifecycle_msgs ChangeState/GetState (control.autostart unconfigured, as run_stack starts
    it). Unconfigured and inactive it answers every estimate with zero and integrates nothing
    under a 5 mm reference; active it drives towards it from a bumpless start; deactivated it
    is back at zero at once; activated again (the piston meanwhile at 2 mm) it starts from
    the piston position, not from the wound-up state."""
    from lifecycle_msgs.srv import ChangeState, GetState
    proc = start_process(controller_cmd('-p', 'controller:control.autostart:=unconfigured'))
    est = FakeEstimator(ros_node)
    change = ros_node.create_client(ChangeState, '/controller/change_state')
    get = ros_node.create_client(GetState, '/controller/get_state')

    call = est.call

    def transition(label):
        req = ChangeState.Request()
        req.transition.label = label
        ok = call(change, req).success
        return ok, call(get, GetState.Request()).current_state.label

    def outputs(ticks=600, since=None):
        """Answers to the next ``ticks`` estimates, by seq once they came (``since``: from
        the estimate after this seq on)."""
        last = est.seq + ticks
        first = est.seq if since is None else since
        assert wait_for(lambda: answered(est, last), 30)
        return np.array([c.motor_speed_ref for c in est.commands if first < c.seq <= last])[3:]

    try:
        assert wait_for(lambda: len(est.commands) > 100, 60), 'controller does not answer'
        wait_matched(est.ref_pub)
        assert call(get, GetState.Request()).current_state.label == 'unconfigured'
        est.ref_pub.publish(est.Ref(position=0.005))
        seen = {'unconfigured': outputs()}
        assert transition('configure') == (True, 'inactive')
        seen['inactive'] = outputs()
        n = est.seq
        assert transition('activate') == (True, 'active')
        seen['active'] = outputs(since=n)
        assert transition('deactivate') == (True, 'inactive')
        seen['deactivated'] = outputs()
        est.position = 0.002                       # the piston moved meanwhile
        n = est.seq
        assert transition('activate') == (True, 'active')
        seen['again'] = outputs(since=n)
        assert transition('configure') == (False, 'active')      # not from 'active'
        assert wait_for(lambda: est.diags and est.diags[-1].get('lifecycle') == 'active', 5)
        print('controller lifecycle: ' + ', '.join(
            f'{k} |u| max {np.abs(u).max():.1f} rad/s over {len(u)} answers'
            for k, u in seen.items()))
        for k in ('unconfigured', 'inactive', 'deactivated'):
            assert len(seen[k]) > 500 and np.all(seen[k] == 0.0), k
        for k in ('active', 'again'):              # bumpless: the first answers near zero
            u = seen[k][np.nonzero(seen[k])[0][0]:]
            assert abs(u[0]) < 50.0 and u[-1] > 0.0 and np.abs(u).max() > 100.0, (k, u[:5])
    finally:
        est.close()
        code, out, err = stop_process(proc)
        assert 'Traceback' not in err, err


def test_stale_estimates_trip_watchdog(ctl):
    """Stale estimates (the estimator predicting without states) trip the watchdog: zero
    speed from then on. The piston 2 mm short of its reference keeps the answers before
    non-zero, so the zeros are the watchdog's."""
    ctl.ref_pub.publish(ctl.Ref(position=0.002))
    assert wait_for(lambda: len(ctl.commands) > 20 and all(
        c.seq > 0 and c.motor_speed_ref > 10.0 for c in ctl.commands[-20:]), 10), \
        [c.motor_speed_ref for c in ctl.commands[-20:]]
    trips = int(ctl.diags[-1].get('watchdog_trips', 0)) if ctl.diags else 0
    ctl.stale = True
    assert wait_for(lambda: ctl.diags and int(ctl.diags[-1].get('watchdog_trips', 0)) > trips,
                    10)
    n = len(ctl.commands) + 20              # answers still on their way when it was reported
    assert wait_for(lambda: len(ctl.commands) > n + 50, 10)
    assert all(c.motor_speed_ref == 0.0 for c in ctl.commands[n:])
    ctl.stale = False


def test_bad_references_rejected_and_reported(ctl):
    ctl.ref_pub.publish(ctl.Ref(position=float('nan')))
    ctl.ref_pub.publish(ctl.Ref(position=0.5))
    assert wait_for(lambda: ctl.diags and int(ctl.diags[-1].get('rejected_references', 0)) >= 1
                    and int(ctl.diags[-1].get('clamped_references', 0)) >= 1, 5)
    assert all(np.isfinite(c.motor_speed_ref) for c in ctl.commands)


def test_missing_transfer_function_stops_node_with_one_line(tmp_path):
    res = subprocess.run(controller_cmd(files=['plant.yaml', 'controller_node.yaml']),
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in res.stderr, res.stderr
    assert "missing required parameter 'position_controller.num'" in lines[0]
