"""The experiment node (issue 43) as a separate process over DDS, the test playing the plant,
the estimator and the controller tick by tick (so every assertion is on seq): the drive
experiment answers estimate(k) with command(k) = the plan's speed sine minus the slow position
loop and stops on the switch manager's FAILED_SAFE; a closed-loop experiment sends the
reference and load of tick k + lead_ticks stamped with that seq (and that tick's time) and
stops at the stroke guard;
both publish /eha/experiment (latched) at the plan's start; bad parameters are one line."""
import json
import subprocess
import threading
import time

import pytest

from eha_ros.core.ident import experiments as E
from eha_ros.core.ident.params import SCHEMA
from eha_ros.core.sim.batch import node_params
from eha_ros.stack import node_command
from ros_util import start_process, stop_process, wait_fed, wait_for, wait_matched

pytestmark = pytest.mark.ros

DRIVE = {'kind': 'drive', 'drive.freqs': [5.0, 20.0], 'drive.periods': 2,
         'drive.relax': 0.01, 'start_delay': 0.0}
LEAK = {'kind': 'leakage', 'leakage.loads': [3000.0, -6000.0], 'leakage.hold': 0.05,
        'leakage.ramp': 0.01, 'leakage.rest': 0.02, 'start_delay': 0.0}


def args_of(over: dict) -> list:
    return [x for k, v in over.items() for x in (
        '-p', f'experiment:experiment.{k}:={json.dumps(v) if isinstance(v, list) else v}')]


def plan_of(over: dict):
    p = node_params('experiment', SCHEMA, None, {f'experiment:experiment.{k}': v
                                                 for k, v in over.items()})
    return E.build(p), E.Limits.from_params(p)


class Loop:
    """The test's side: state/estimate/command/redundancy publishers, command, reference, load
    and experiment subscribers, each message kept by seq."""

    def __init__(self, node):
        from eha_msgs.msg import (ActuatorCommand, ActuatorState, ExternalLoad,
                                  PositionEstimate, PositionReference, RedundancyStatus)
        from std_msgs.msg import String

        from eha_ros.nodes.common import latched_qos, stream_qos
        self.node, self.M = node, (ActuatorState, PositionEstimate, ActuatorCommand,
                                   RedundancyStatus)
        self.cond = threading.Condition()
        self.commands, self.references, self.loads, self.info = {}, {}, {}, []
        qos = stream_qos()
        self.pub_state = node.create_publisher(ActuatorState, 'eha/state', qos)
        self.pub_est = node.create_publisher(PositionEstimate, 'eha/estimate', qos)
        self.pub_cmd = node.create_publisher(ActuatorCommand, 'eha/command', qos)
        self.pub_red = node.create_publisher(RedundancyStatus, 'eha/redundancy', latched_qos())
        self.sub_cmd = node.create_subscription(ActuatorCommand, 'eha/command',
                                                self.keep(self.commands), qos)
        self.sub_ref = node.create_subscription(PositionReference, 'eha/reference',
                                                self.keep(self.references), qos)
        self.sub_load = node.create_subscription(ExternalLoad, 'eha/sim/load_force',
                                                 self.keep(self.loads), qos)
        node.create_subscription(String, 'eha/experiment',
                                 lambda m: self.info.append(json.loads(m.data)), latched_qos())

    def keep(self, where):
        def cb(msg):
            with self.cond:
                where.setdefault(msg.seq, msg)
                self.cond.notify_all()
        return cb

    def tick(self, k: int, x: float, wait_for_seq=None, answer=False):
        """state(k) and estimate(k) at position x (and command(k) as a controller, when
        ``answer``); then wait until ``wait_for_seq`` has come in (commands or references)."""
        from builtin_interfaces.msg import Time
        S, P, C, _ = self.M
        state = S(seq=k, position=x, valid=True)
        state.header.stamp = Time(sec=k // 1000, nanosec=(k % 1000) * 1_000_000)   # k ms
        est, cmd = P(seq=k, position=x), C(seq=k)

        def publish():
            self.pub_state.publish(state)
            self.pub_est.publish(est)
            if answer:
                self.pub_cmd.publish(cmd)
        publish()
        if wait_for_seq is not None:
            where, seq = wait_for_seq
            deadline = time.monotonic() + 30.0
            while True:
                with self.cond:
                    if self.cond.wait_for(lambda: seq in where, 2.0):
                        return
                assert time.monotonic() < deadline, f'no answer for tick {seq}'
                # a sample written just after discovery can be dropped (the node's reader may
                # not know this writer yet, though the writer knows the reader): the same tick
                # again; the node answers by seq, the first answer is the one kept
                publish()


def test_drive_answers_each_estimate_and_stops_on_failed_safe(ros_node):
    plan, L = plan_of(DRIVE)
    proc = start_process(node_command('experiment', extra=args_of(DRIVE)))
    try:
        loop = Loop(ros_node)
        wait_matched(loop.pub_state, loop.pub_est, loop.pub_red)
        wait_fed(loop.sub_cmd, publishers=2)    # the node's and the test's own (unused here)
        x, k = 0.001, 0                         # an ideal actuator: x' = D_p/A_p u
        while not loop.info or k < loop.info[0]['params']['start_seq'] + plan.n_ticks // 2:
            loop.tick(k, x, (loop.commands, k))
            x += loop.commands[k].motor_speed_ref / L.ratio * L.Ts
            k += 1
        info = loop.info[0]
        start = info['params']['start_seq']
        assert (info['experiment'], info['version'], info['plant_side']) == ('drive', 1, 'sim')
        assert info['params']['n_ticks'] == plan.n_ticks and info['params']['freqs'] == [5, 20]
        xs, k2 = [0.001], 0                     # replay: command(k) from position x(k) alone
        for seq in range(k):
            u = loop.commands[seq].motor_speed_ref
            i = seq - start
            ff = plan.speed[i] if 0 <= i < plan.n_ticks else 0.0
            assert u == pytest.approx(ff - plan.position_gain * xs[-1], rel=1e-12, abs=1e-12), seq
            xs.append(xs[-1] + u / L.ratio * L.Ts)
        assert max(abs(loop.commands[s].motor_speed_ref) for s in range(start, k)) > 100
        # the safe state: FAILED_SAFE on /eha/redundancy stops it; zero speed from then on
        loop.pub_red.publish(loop.M[3](state='FAILED_SAFE', reason='test: both couples failed'))
        stopped = lambda: proc.poll() is not None       # noqa: E731
        while not stopped() and k2 < 5000:
            loop.tick(k + k2, x)
            k2 += 1
            wait_for(stopped, 0.005)
        assert wait_for(stopped, 30), 'the node did not end on FAILED_SAFE'
    finally:
        code, out, err = stop_process(proc)
    last = err.strip().splitlines()[-1]
    assert code == 1 and last.endswith('experiment drive stopped: safe state: switch manager '
                                       'FAILED_SAFE (test: both couples failed)'), err[-1500:]
    late = [m.motor_speed_ref for s, m in loop.commands.items() if s >= k + 1]
    assert all(u == 0.0 for u in late[1:]), late[:5]


def test_closed_loop_sends_references_and_loads_by_seq_and_stops_at_the_stroke(ros_node):
    plan, L = plan_of(LEAK)
    proc = start_process(node_command('experiment', extra=args_of(LEAK)))
    lead = 2
    try:
        loop = Loop(ros_node)
        wait_matched(loop.pub_state, loop.pub_est, loop.pub_cmd)
        wait_fed(loop.sub_ref, loop.sub_load)   # its first reference and load are for tick 2
        k = 0
        while not loop.info or k < loop.info[0]['params']['start_seq'] + plan.n_ticks - lead:
            loop.tick(k, 0.0, (loop.loads, k + lead), answer=True)
            k += 1
        start = loop.info[0]['params']['start_seq']
        assert loop.info[0]['experiment'] == 'leakage'
        for seq in range(start, k + lead):
            i = seq - start
            ref, load = loop.references[seq], loop.loads[seq]
            assert ref.position == 0.0 and load.force == plan.load[i], seq
            # stamped with the time of the tick they are for, as the state of that tick
            assert (ref.header.stamp.sec, ref.header.stamp.nanosec) == \
                (load.header.stamp.sec, load.header.stamp.nanosec) == \
                (seq // 1000, (seq % 1000) * 1_000_000), seq
        assert {loop.loads[start + q['start']].force for q in plan.parts} == {3e3, -6e3}
        loop.tick(k, 0.0571)                    # beyond the stroke margin: it stops
        assert wait_for(lambda: proc.poll() is not None, 30)
    finally:
        code, out, err = stop_process(proc)
    assert code == 1 and err.strip().splitlines()[-1].endswith(
        f'experiment leakage stopped: measured position +57.10 mm at tick {k}: beyond +-55 mm '
        f'(the stroke minus its margin)'), err[-1500:]


def test_bad_experiment_parameter_stops_the_node_with_one_line():
    res = subprocess.run(node_command('experiment', extra=[
        '-p', 'experiment:experiment.kind:=friction',
        '-p', 'experiment:experiment.friction.amplitude:=0.06']),
        capture_output=True, text=True, timeout=120)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert 'experiment.friction' in lines[0] and 'beyond the stroke' in lines[0]
