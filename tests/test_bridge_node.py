"""hardware_bridge as a separate process over DDS against the plant-backed ADS test peer (in
this process, real-time PLC task at 1 kHz, every speed the PLC receives logged): state stream,
not armed -> no speed reaches the PLC, arming with preconditions, watchdog, channel select,
link dropped and restored (latched, reported, reset), bad symbol maps, a second plant refused.
Timing assertions leave room for a loaded 2-core machine; the figures are printed."""
import os
import subprocess
import time

import numpy as np
import pytest

from eha_ros.core.sim.batch import node_params
from eha_ros.core.bridge.peer import AdsPeer
from eha_ros.core.bridge.symbols import load_symbol_map
from eha_ros.core.hardware.sim_params import SCHEMA as SIM
from eha_ros.stack import node_command
import probes
from ros_util import start_process, stop_process, wait_for, wait_matched
from test_bridge_core import MAP, free_port, write_map

pytestmark = pytest.mark.ros
WATCHDOG = 0.05


@pytest.fixture(scope='module')
def peer():
    p = AdsPeer(load_symbol_map(MAP), node_params('plant_sim', SIM), port=free_port()).start()
    yield p
    p.stop()


def bridge_cmd(port, *extra):
    return node_command('hardware_bridge', extra=[
        '-p', f'hardware_bridge:ads.tcp_port:={port}',
        '-p', f'hardware_bridge:bridge.command_timeout:={WATCHDOG}',
        '-p', 'hardware_bridge:bridge.diagnostics_period:=0.2',
        '-p', 'hardware_bridge:bridge.stale_limit:=0.05',     # the PLC task shares this process
        # and a busy test process can miss 3 x 100 ms (seen once in CI after the reset)
        '-p', 'hardware_bridge:ads.link_loss_cycles:=8',
        '-p', 'hardware_bridge:bridge.startup_discovery:=0.5', *extra])


def run_alone(cmd, timeout=90):
    """Run a bridge on a DDS domain of its own (no other plant visible); (code, stderr)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str((int(os.environ.get('ROS_DOMAIN_ID', '0')) + 117)
                                             % 200 + 1))
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    return res.returncode, res.stderr


# ---------------------------------------------------------------- refused starts (run first)
def test_unknown_symbol_stops_with_one_line(peer, tmp_path):
    path = write_map(tmp_path, lambda s: s['motor_speed_1'].update(symbol='GVL_EHA.fSpeedB'))
    code, err = run_alone(bridge_cmd(peer.port, '-p', f'hardware_bridge:bridge.symbol_map:={path}'))
    lines = err.strip().splitlines()
    print(err)
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith('hardware_bridge: error: symbol map') and \
        "symbols.motor_speed_1.symbol = 'GVL_EHA.fSpeedB': unknown symbol on the PLC" in lines[0]


def test_wrong_type_stops_with_one_line(peer, tmp_path):
    path = write_map(tmp_path, lambda s: s['plc_cycle'].update(type='UINT'))
    code, err = run_alone(bridge_cmd(peer.port, '-p', f'hardware_bridge:bridge.symbol_map:={path}'))
    lines = err.strip().splitlines()
    print(err)
    assert code == 2 and len(lines) == 1, err
    assert 'symbols.plc_cycle.type = UINT: wrong type: the PLC declares GVL_EHA.nCycle as ' \
        'UDINT' in lines[0]


def test_bad_map_file_stops_with_one_line(peer, tmp_path):
    path = write_map(tmp_path, lambda s: s['valve_cmd_0'].update(type='LREAL'))
    code, err = run_alone(bridge_cmd(peer.port, '-p', f'hardware_bridge:bridge.symbol_map:={path}'))
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and 'symbols.valve_cmd_0.type = LREAL: wrong type' \
        in lines[0], err


# ---------------------------------------------------------------- the running bridge
@pytest.fixture(scope='module')
def bridge(peer):
    proc = start_process(bridge_cmd(peer.port))
    yield proc
    code, out, err = stop_process(proc)
    assert 'Traceback' not in err, err


class Probe(probes.Probe):
    LOOP = 'hardware_bridge: loop'

    def __init__(self, node):
        from eha_msgs.msg import ActuatorCommand, ActuatorState, ChannelSelect
        from std_srvs.srv import SetBool, Trigger
        from eha_ros.nodes.common import latched_qos
        super().__init__(node)
        self.states = self.received(ActuatorState, '/eha/state', 1000)
        self.cmd_pub = node.create_publisher(ActuatorCommand, '/eha/command', 100)
        self.sel_pub = node.create_publisher(ChannelSelect, '/eha/channel_select', latched_qos())
        self.arm_cli = self.client(SetBool, '/eha/bridge/arm')
        self.reset_cli = self.client(Trigger, '/eha/bridge/reset')
        self.Cmd, self.Sel, self.SetBool, self.Trigger = ActuatorCommand, ChannelSelect, SetBool, \
            Trigger
        self.last_cmd_time = None

    def diag(self):
        return self.diagnostics.fields(self.LOOP)

    def wait_diag(self, pred, timeout=20):
        return self.diagnostics.wait(self.LOOP, lambda s: pred(s.fields()), timeout, new=True)

    def hold(self, speed, seconds):
        """Commands every ~2 ms (answering the latest state), like a controller."""
        end = time.monotonic() + seconds
        self.cmd_times = []
        while time.monotonic() < end:
            seq = self.states[-1].seq if self.states else 0
            self.cmd_pub.publish(self.Cmd(seq=int(seq), motor_speed_ref=float(speed)))
            self.last_cmd_time = time.monotonic()
            self.cmd_times.append(self.last_cmd_time)
            time.sleep(0.002)

    def arm(self, on=True):
        return self.call(self.arm_cli, self.SetBool.Request(data=on), 20, 20)

    def arm_fresh(self, timeout=5.0):
        """arm(True), asked again while it is refused for stale drive data (CI: the PLC task in
        this process starved, the data went stale, refused for that, rightly) for up to
        ``timeout`` s; the last answer."""
        res, deadline = self.arm(True), time.monotonic() + timeout
        while not res.success and 'stale' in res.message and time.monotonic() < deadline:
            time.sleep(0.1)
            res = self.arm(True)
        return res

    def reset(self):
        return self.call(self.reset_cli, self.Trigger.Request(), 20, 20)


@pytest.fixture
def probe(bridge, peer, ros_node):
    p = Probe(ros_node)
    assert wait_for(lambda: len(p.states) > 200, 60), 'no /eha/state from hardware_bridge'
    wait_matched(p.cmd_pub)
    assert p.wait_diag(lambda d: d.get('link_up') == 'True'), p.diag()
    return p


def speeds_logged(peer, seconds, action):
    """Speed references the PLC applied while ``action`` ran: array of (time, rad/s)."""
    with peer.lock:
        peer.plc.speed_log.clear()
        peer.plc.recording = True
    action()
    time.sleep(seconds)
    with peer.lock:
        peer.plc.recording = False
        log = np.array([(t, w) for _, t, w in peer.plc.speed_log])
    return log


def test_state_stream_through_ads(probe, peer):
    probe.states.clear()
    t0 = time.monotonic()
    with peer.lock:
        c0 = peer.plc.cycles
    assert wait_for(lambda: len(probe.states) > 1000, 30)
    with peer.lock:
        c1 = peer.plc.cycles
    rate = len(probe.states) / (time.monotonic() - t0)
    seqs = np.array([s.seq for s in probe.states])
    s = probe.states[-1]
    with peer.lock:
        x = peer.plc.plant.measure().position
    repeats = 1.0 - np.mean([m.valid for m in probe.states])
    print(f'state rate {rate:.0f} Hz (real time, loaded machine), seq gaps '
          f'{np.sum(np.diff(seqs) != 1)}, not valid (a repeated PLC sample) {100 * repeats:.1f} %')
    # the PLC's and the bridge's 1 kHz clocks are not synchronised: now and then a cycle reads
    # the sample the previous one read, published not valid (the estimator predicts over it).
    # How often depends on this test process (the PLC task shares it): 0.5 % idle, 11.6 % seen
    # under CI load; most samples must still be new
    assert np.all(np.diff(seqs) > 0) and repeats < 0.5
    # seq keeps the PLC's time (core.hardware.staleness): a late bridge cycle moves it on by
    # the PLC cycles it missed; the two spans differ by the stream's start/end latency only
    span, cycles = int(seqs[-1] - seqs[0]), c1 - c0
    print(f'seq span {span}, PLC cycles meanwhile {cycles}')
    assert abs(span - cycles) <= 0.02 * cycles + 50
    assert abs(s.position - x) < 2e-4 and s.drive_enabled[0] and not s.drive_enabled[1]
    assert s.valve_open[0] and 0.5e6 < s.pressure_a < 3e6 and s.active_channel == 0


def test_not_armed_no_speed_reaches_plc(probe, peer):
    probe.arm(False)
    log = speeds_logged(peer, 0.0, lambda: probe.hold(300.0, 1.5))
    print(f'unarmed: {len(log)} PLC cycles, max |speed_ref| {np.max(np.abs(log[:, 1])):.3g} rad/s')
    assert len(log) > 300 and np.all(log[:, 1] == 0.0)
    res = probe.arm_fresh()                          # the controller is not at rest: refused
    assert not res.success and 'latest command 300.0 rad/s' in res.message
    assert abs(probe.states[-1].motor_speed[0]) < 5.0


PLC_STALL = 0.02     # [s] a gap in the PLC task's cycles longer than this: this process stalled


def test_armed_speed_reaches_plc_then_watchdog_zeroes_it(probe, peer):
    """The PLC task runs in this test process: where the process stalls (CI, once: no PLC cycle
    from 1 ms to 193 ms after the last command), its log cannot tell when the watchdog acted or
    how long the stop held. Such an attempt is measured again (at most three)."""
    for attempt in (1, 2, 3):
        probe.hold(0.0, 0.2)
        res = probe.arm_fresh()
        assert res.success, res.message
        log = speeds_logged(peer, 0.3, lambda: probe.hold(100.0, 1.0))   # then commands stop
        t_last = probe.last_cmd_time
        # the window's ends count as cycles: a stall at its end (CI, once: no PLC cycle from
        # 166 ms after the last command until the recording stopped) hides the final stop too
        edges = (t_last - 0.1, t_last + 0.3)
        near = log[(log[:, 0] > edges[0]) & (log[:, 0] < edges[1]), 0]
        stall = np.max(np.diff(np.concatenate(([edges[0]], near, [edges[1]]))))
        if stall <= PLC_STALL:
            break
        print(f'attempt {attempt}: the PLC task stalled {1e3 * stall:.0f} ms near the last '
              f'command; measured again')
        probe.arm(False)
    assert stall <= PLC_STALL, f'the PLC task stalled in all three attempts ({stall:.3f} s)'
    moving = log[log[:, 0] < t_last]
    assert np.max(moving[:, 1]) == pytest.approx(100.0) and np.all(moving[:, 1] >= 0.0)
    after = log[log[:, 0] > t_last]
    nonzero = after[after[:, 1] != 0.0]
    last_moving = nonzero[-1, 0] if len(nonzero) else t_last
    final = after[after[:, 0] > last_moving]
    delay = final[0, 0] - t_last                 # the PLC's first cycle of the final stop
    gap = np.max(np.diff(probe.cmd_times)) if len(probe.cmd_times) > 1 else 0.0
    print(f'watchdog: zero speed at the PLC {1e3 * delay:.1f} ms after the last command '
          f'(command_timeout {1e3 * WATCHDOG:.0f} ms); last non-zero {1e3 * (last_moving - t_last):.1f}'
          f' ms; largest gap between test commands {1e3 * gap:.1f} ms')
    # zero from the watchdog (<= 80 ms) to the window's end (300 ms), no stall over 20 ms
    assert final[-1, 0] - final[0, 0] > 0.15 and np.all(final[:, 1] == 0.0)
    assert delay <= WATCHDOG + 0.03                   # 30 ms slack for DDS + load
    assert last_moving - t_last >= WATCHDOG - 0.01    # held until the watchdog time, not earlier
    assert probe.wait_diag(lambda d: int(d.get('command_timeouts', 0)) >= 1 and
                           d['_message'] == 'commands stale')
    time.sleep(0.2)
    assert abs(probe.states[-1].motor_speed[0]) < 5.0
    probe.arm(False)


def test_channel_select_reaches_plc(probe, peer):
    probe.sel_pub.publish(probe.Sel(channel=1, drive_enable=[False, True],
                                    valve_open=[False, True], bypass_open=False))
    assert wait_for(lambda: probe.states[-1].active_channel == 1 and
                    probe.states[-1].drive_enabled[1] and not probe.states[-1].drive_enabled[0]
                    and probe.states[-1].valve_open[1], 20)
    probe.sel_pub.publish(probe.Sel(channel=0, drive_enable=[True, False],
                                    valve_open=[True, False], bypass_open=False))
    assert wait_for(lambda: probe.states[-1].active_channel == 0 and
                    probe.states[-1].valve_open[0] and not probe.states[-1].valve_open[1], 20)


def test_second_plant_refused(probe, peer):
    # the refusal comes as soon as discovery shows the running bridge; the wait only bounds a
    # discovery slowed by a loaded machine (3 s was once too short in CI). A second bridge that
    # did start is stopped with SIGINT, so that its DDS participant leaves the graph at once
    # (a killed one lingers there and would fail the tests after this one)
    proc = start_process(bridge_cmd(peer.port,
                                    '-p', 'hardware_bridge:bridge.startup_discovery:=20.0'))
    try:
        _, err = proc.communicate(timeout=60)
        code = proc.returncode
    except subprocess.TimeoutExpired:
        code, _, err = stop_process(proc)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert '/eha/state is already published by /hardware_bridge: refusing' in lines[0]


def test_link_dropped_and_restored(probe, peer):
    probe.hold(0.0, 0.2)
    res = probe.arm_fresh()
    assert res.success, res.message
    peer.set_online(False)                       # the PLC stops answering (cable pulled)
    t0 = time.monotonic()
    assert probe.wait_diag(lambda d: d['link_fault_latched'] == 'True' and
                           d['link_up'] == 'False' and d['active'] == 'False'), probe.diag()
    d = probe.diag()
    print(f'link loss reported after {time.monotonic() - t0:.2f} s: {d["_message"]}')
    assert d['_level'] == 2 and 'link fault latched' in d['_message'] and '1861' in d['_message']
    assert not probe.states[-1].valid
    assert not probe.arm(True).success and not probe.reset().success     # link still down
    peer.set_online(True)
    assert probe.wait_diag(lambda d: d['link_up'] == 'True'), probe.diag()
    assert probe.diag()['link_fault_latched'] == 'True'              # latched after reconnect
    assert wait_for(lambda: probe.states[-1].valid, 10)
    res = probe.arm_fresh()
    assert not res.success and 'reset first' in res.message
    res = probe.reset()
    assert res.success, res.message
    assert probe.wait_diag(lambda d: d['link_fault_latched'] == 'False' and d['_level'] == 0)
    res = probe.arm_fresh()
    assert res.success, res.message
    log = speeds_logged(peer, 0.0, lambda: probe.hold(50.0, 0.5))
    assert np.max(log[:, 1]) == pytest.approx(50.0)                 # moving again
    probe.hold(0.0, 0.2)
    probe.arm(False)
