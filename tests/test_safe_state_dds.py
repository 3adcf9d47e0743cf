"""The safe state over DDS (core.loop.safe_state): plant_sim, estimator, controller and
switch_manager, each its own process in lock-step; a stuck position sensor injected on
/eha/inject_fault while holding 0 under 5 kN. The estimate says sensor_fault, the controller
commands zero speed from that seq on, the switch manager closes every valve (hydraulic lock),
each logs it once and reports ERROR on /diagnostics, and the piston holds. Ticks by seq, not
by wall time."""
import re

import pytest

from eha_ros.stack import Stack
import probes
from ros_util import wait_for

pytestmark = pytest.mark.ros

NODES = ['plant_sim', 'estimator', 'controller', 'switch_manager']
SENSOR = 3                      # PositionEstimate.consistency: sensor_fault


class Watch(probes.Probe):
    def __init__(self, node):
        from eha_msgs.msg import (ActuatorCommand, ChannelSelect, ExternalLoad, PlantTruth,
                                  PositionEstimate, RedundancyStatus)
        from rclpy.qos import QoSProfile
        from eha_ros.nodes.common import latched_qos, stream_qos
        super().__init__(node, diagnostics=100)
        big = QoSProfile(depth=5000)
        self.estimates = self.by_seq(PositionEstimate, '/eha/estimate', big)
        self.commands = self.by_seq(ActuatorCommand, '/eha/command', big)
        self.truth = {}
        self.subscribe(PlantTruth, '/eha/sim/truth', self.on_truth, big)
        self.closed = {}                    # seq -> both pump valves closed (truth)
        keep = latched_qos()
        keep.depth = 100
        self.status = self.received(RedundancyStatus, '/eha/redundancy', keep)
        self.selects = self.received(ChannelSelect, '/eha/channel_select', keep)
        self.load = node.create_publisher(ExternalLoad, '/eha/sim/load_force', stream_qos())
        self.Load = ExternalLoad

    def on_truth(self, m):
        self.truth[m.seq] = m.position
        self.closed[m.seq] = max(m.valve_fraction) < 0.01

    @property
    def diag(self) -> dict:
        """name -> its newest DiagnosticStatus."""
        return {n: s.msg for n, s in self.diagnostics.latest_by_name().items()}

    def tick(self) -> int:
        return max(self.truth, default=-1)


def test_stuck_sensor_leads_to_zero_speed_and_hydraulic_lock(ros_node, tmp_path):
    from eha_msgs.srv import InjectFault
    w = Watch(ros_node)
    st = Stack(NODES, lockstep=True, log_dir=str(tmp_path)).start()
    try:
        assert wait_for(lambda: w.tick() >= 300, 120), 'loop not running'
        assert wait_for(lambda: w.load.get_subscription_count() > 0, 30)
        w.load.publish(w.Load(force=5e3))
        assert wait_for(lambda: w.tick() >= 1500, 120), 'loop stalled'
        client = ros_node.create_client(InjectFault, '/eha/inject_fault')
        assert client.wait_for_service(timeout_sec=30)
        fut = client.call_async(InjectFault.Request(fault='msp_stuck', channel=0,
                                                    magnitude=0.0, duration=0.0))
        assert wait_for(fut.done, 30) and fut.result().success, fut.result()
        k_fault = int(re.search(r'tick (\d+)', fut.result().message).group(1))
        assert wait_for(lambda: w.tick() >= k_fault + 1000, 120), 'loop stalled after the fault'
        assert wait_for(lambda: any(s.state == 'FAILED_SAFE' for s in w.status), 10)
        assert wait_for(lambda: 'safe state' in getattr(
            w.diag.get('controller: loop'), 'message', ''), 10), \
            {k: v.message for k, v in w.diag.items()}
        # ERROR on /diagnostics from estimator, controller and switch manager (each publishes
        # on its own wall-clock period: lock-step can run 1000 ticks before the next one)
        assert wait_for(lambda: {n for n in NODES[1:] if any(
            k.startswith(n) and v.level == b'\x02' for k, v in w.diag.items())} ==
            set(NODES[1:]), 15), {k: (v.level, v.message) for k, v in w.diag.items()}
    finally:
        st.stop(timeout=20)
    for n in NODES:
        assert 'Traceback' not in (tmp_path / f'{n}.log').read_text(), n
    # the estimate: sensor_fault within 20 ticks (stuck: 10 identical readings)
    flagged = sorted(k for k, m in w.estimates.items() if k >= k_fault and
                     m.consistency == SENSOR)
    assert flagged and flagged[0] - k_fault <= 20, (k_fault, flagged[:3])
    k_safe = flagged[0]
    assert not [k for k, m in w.estimates.items() if k < k_fault and m.consistency == SENSOR]
    # the controller: zero speed from that estimate on
    after = [m for k, m in w.commands.items() if k >= k_safe]
    assert len(after) > 500 and all(m.motor_speed_ref == 0.0 for m in after)
    # the switch manager: FAILED_SAFE, drives off and every valve closed (hydraulic lock)
    safe = [s for s in w.status if s.state == 'FAILED_SAFE']
    assert 'position fault' in safe[0].reason and 'sensor_fault' in safe[0].reason
    sel = w.selects[-1]
    assert list(sel.valve_open) == [False, False] and list(sel.drive_enable) == [False, False]
    assert not sel.bypass_open
    # logged once each
    log = {n: (tmp_path / f'{n}.log').read_text() for n in NODES}
    assert log['estimator'].count('sensor_fault: the position sensor is faulty') == 1, \
        log['estimator'][-2000:]
    # (its reason: the estimate, or the manager's FAILED_SAFE if that status came first)
    assert log['controller'].count(': safe state (') == 1, \
        log['controller'][-2000:]
    assert log['switch_manager'].count('position fault') == 1, log['switch_manager'][-2000:]
    # the piston holds under 5 kN (truth; the sensor is stuck): sealed chambers, it creeps
    # only by the cross-piston leakage, C_c (F / A_p) / A_p. The plant applies a channel
    # select when it arrives (not tick-locked, unlike commands): the lock's tick over DDS
    # depends on the machine (the batch campaigns give its time: 29 ms after a stuck sensor)
    from eha_ros.core.sim.batch import node_params
    from eha_ros.core.hardware.sim_params import SCHEMA
    p = node_params('plant_sim', SCHEMA)
    A_p = p['plant.cylinder.A_p']
    creep = p['plant.cylinder.C_c'] * (5e3 / A_p) / A_p
    k_lock = min(k for k, c in w.closed.items() if c and k >= k_safe)
    assert k_lock - k_safe < 300, (k_safe, k_lock)
    ks = [k for k in range(k_lock + 5, k_lock + 600) if k in w.truth]
    rate = abs(w.truth[ks[-1]] - w.truth[ks[0]]) / ((ks[-1] - ks[0]) * 1e-3)
    print(f'\nstuck sensor at tick {k_fault}: sensor_fault at {k_safe} '
          f'(+{k_safe - k_fault} ticks), valves closed at {k_lock}; the locked piston creeps '
          f'{rate * 1e3:.3f} mm/s under 5 kN (cross-piston leakage: {creep * 1e3:.3f} mm/s)')
    assert len(ks) > 400 and rate < 1.2 * creep
