"""Issue 18's scenario as a user runs it: scripts/ads_peer, then
`run_stack --plant bridge --no-peer`. A 5 mm reference sent before arming moves nothing and
no longer winds the controller up (the bridge says INACTIVE on /eha/plant_state); arming
succeeds at once; then a 5 mm step within 5 % overshoot and 0.4 s of 2 % settling. In
lock-step (peer --lockstep, run_stack --mode lockstep). (In real time on a loaded machine the
bridge's catch-up cycles could read the same PLC sample ten times, which the estimator took
for a stuck sensor; a repeated sample is now published not valid and predicted over:
docs/nodes/plant_side.md.)
In a module of its own: it owns the /eha topics."""
import os
import subprocess
import threading

import numpy as np
import pytest

from probes import DiagnosticsCollector
from ros_util import ROOT, start_process, stop_process, wait_for, wait_matched
from test_bridge_core import free_port

pytestmark = pytest.mark.ros


def test_reference_before_arming_moves_nothing_then_arm_and_step(ros_node, tmp_path):
    from eha_msgs.msg import ActuatorCommand, ActuatorState, PositionReference
    from rclpy.qos import QoSProfile
    from std_srvs.srv import SetBool
    states, commands = [], []

    diagnostics = DiagnosticsCollector(ros_node)
    diags = diagnostics.view('controller', prefix=True, merged=True)
    bridge = diagnostics.view('hardware_bridge', prefix=True, merged=True, fields=True)
    ros_node.create_subscription(ActuatorState, '/eha/state', states.append,
                                 QoSProfile(depth=1000))
    ros_node.create_subscription(ActuatorCommand, '/eha/command', commands.append,
                                 QoSProfile(depth=1000))
    ref = ros_node.create_publisher(PositionReference, '/eha/reference', 10)
    from eha_ros.nodes.common import latched_qos
    from lifecycle_msgs.msg import State
    plant_states = []
    ros_node.create_subscription(State, '/eha/plant_state',
                                 lambda m: plant_states.append(m.label), latched_qos())
    port = free_port()
    peer = start_process([f'{ROOT}/scripts/ads_peer', '--port', str(port), '--no-ros',
                          '--lockstep'])
    lines = []
    threading.Thread(target=lambda: lines.append(peer.stdout.readline()), daemon=True).start()
    stack = None
    try:
        assert wait_for(lambda: lines and 'serving' in lines[0], 60), lines
        stack = start_process([os.path.join(ROOT, 'scripts', 'run_stack'), '--plant', 'bridge',
                               '--no-peer', '--mode', 'lockstep', '--duration', '300',
                               '--out', str(tmp_path),
                               '--name', 'run', '--progress', '0',
                               '-p', f'hardware_bridge:ads.tcp_port:={port}'])
        assert wait_for(lambda: len(states) > 500 and diags.get('plant_state'), 120), \
            (len(states), diags)
        assert diags['plant_state'] == 'inactive'
        wait_matched(ref)
        x0 = np.mean([s.position for s in states[-200:]])
        ref.publish(PositionReference(position=0.005))
        seq0 = states[-1].seq
        assert wait_for(lambda: states[-1].seq > seq0 + 1500, 60)
        held = [c.motor_speed_ref for c in commands if c.seq > seq0 + 20]
        moved = np.mean([s.position for s in states[-200:]]) - x0
        speed = max(abs(s.motor_speed[s.active_channel]) for s in states if s.seq > seq0)
        print(f'before arming, 5 mm reference: {len(held)} commands, largest '
              f'{max(map(abs, held)):.1f} rad/s; motor speed at most {speed:.2f} rad/s; '
              f'piston moved {1e6 * moved:.1f} um (means of 0.2 s, 1.5 s apart)')
        assert len(held) > 1000 and all(u == 0.0 for u in held)
        assert speed < 1.0                          # the encoder's noise: the motor stands
        assert abs(moved) < 1e-4                    # the sensor's slow error: no motion
        ref.publish(PositionReference(position=0.0))
        cli = ros_node.create_client(SetBool, '/eha/bridge/arm')
        assert cli.wait_for_service(timeout_sec=30)
        fut = cli.call_async(SetBool.Request(data=True))
        assert wait_for(fut.done, 20) and fut.result().success, fut.result().message
        assert wait_for(lambda: diags.get('plant_state') == 'active', 10), diags
        assert plant_states == ['inactive', 'active'], plant_states
        x0 = np.mean([s.position for s in states[-200:]])
        ref.publish(PositionReference(position=x0 + 0.005))
        seq_sent = states[-1].seq
        # the step starts where the controller took the reference: its first command that drives
        # towards it (> 100 rad/s; holding, it answers the sensor's noise with a few rad/s).
        # Lock-step does not wait for an untimed reference: counted from the test's sending, the
        # settling was 1.04 s once with both cores of this machine busy beside the tests.
        assert wait_for(lambda: any(c.seq > seq_sent and c.motor_speed_ref > 100.0
                                    for c in commands[-3000:]), 60)
        seq1 = next(c.seq for c in commands
                    if c.seq > seq_sent and c.motor_speed_ref > 100.0) - 1
        print(f'the controller took the reference {seq1 - seq_sent} ticks after the test sent it')
        assert wait_for(lambda: states[-1].seq > seq1 + 1500, 60)
        k = np.array([s.seq for s in states if s.seq > seq1]) - seq1
        x = np.array([s.position for s in states if s.seq > seq1]) - x0
        xs = np.convolve(x, np.ones(5) / 5, mode='same')[2:-2]      # the sensor's white noise
        overshoot = 100 * (xs.max() - 0.005) / 0.005
        outside = np.nonzero(np.abs(xs - 0.005) > 0.02 * 0.005)[0]
        settling = (k[2:-2][outside[-1]] + 1) * 1e-3
        print(f'after arming, 5 mm step (measured position): overshoot {overshoot:.2f} %, '
              f'2 % settling {settling:.3f} s from the controller taking the reference')
        assert overshoot <= 5.0 and settling <= 0.4, (diags, bridge, plant_states)
    finally:
        if stack is not None:
            code, out, err = stop_process(stack, timeout=30)
            print(out[-3000:], err[-3000:])
            assert 'Traceback' not in err, err
        stop_process(peer)
