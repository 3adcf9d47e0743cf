"""switch_manager over DDS with the full simulated stack (plant_sim, estimator, controller,
switch_manager, each its own process, in lock-step: the plant steps when command(k) arrived,
so the figures measure the loop, not the machine's load, like the issue 6 figures; the same
scenario in real time on the composed stack gave the same figures within noise): Table 3.4
sine (3 Hz, 3 mm) published on /eha/reference 20 ticks ahead, 10 kN on /eha/sim/load_force at 1 s, commanded switch A -> B at 3 s,
motor_fail on the active couple B at 5 s (automatic switch to A), motor_fail on A at 7 s (both
failed: safe state). Figures from /eha/sim/truth and /eha/state matched by seq (plant ticks),
not from wall-clock arrival, so a loaded machine delays the run but does not change them."""
import json
import math
import os
import re
import time

import numpy as np
import pytest

from eha_ros.core.sim import switchover as B
from eha_ros.core.redundancy.events import EventLog, read_log
from eha_ros.stack import Stack
from eha_ros.tools.plot_switch import plot_switches, write_csv
import probes
from ros_util import Spinner, wait_for

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, 'out', 'redundancy', 'dds')
TS = 1e-3
AMP, FREQ, LOAD = 3e-3, 3.0, 10e3
T_LOAD, T_CMD, T_FAIL_B, T_FAIL_A, T_END = 1.0, 3.0, 5.0, 7.0, 8.5
PERIOD = 1.0 / FREQ
MANAGER_LAG = 20      # ticks: the most the manager's statuses may lag the plant for the figures


class EventsSpinner(Spinner):
    """Spinner on rclpy's EventsExecutor: about a third of the CPU of the default executor
    for the 2 kHz of recorded topics (the machine is shared; see nodes/common.py)."""

    def __init__(self, node):
        from eha_ros.nodes.common import make_executor
        super().__init__(node, make_executor())


REF_LEAD = 20         # ticks: references are sent this far ahead with their seq, so a catch-up
                      # burst of the plant's loop after a stall still finds them


def ref_at(t):
    return AMP * math.sin(2 * math.pi * FREQ * t) if t > 0 else 0.0


class Recorder(probes.Probe):
    """Test-side node: records truth/state/status/select/diagnostics and publishes the
    reference REF_LEAD ticks ahead on every truth sample (1 kHz, locked to plant ticks)."""

    def __init__(self, node):
        from eha_msgs.msg import (ActuatorCommand, ActuatorState, ChannelSelect, ExternalLoad,
                                  PlantTruth, PositionReference, RedundancyStatus)
        from rclpy.qos import QoSProfile
        from eha_ros.nodes.common import latched_qos
        super().__init__(node)
        self.seq0 = None
        self.truth, self.state = {}, {}
        self.commands = 0
        self.last_seq = 0
        big = QoSProfile(depth=2000)
        self.Ref, self.Load = PositionReference, ExternalLoad
        self.ref_pub = node.create_publisher(PositionReference, '/eha/reference', 10)
        self.load_pub = node.create_publisher(ExternalLoad, '/eha/sim/load_force', 10)
        self.subscribe(PlantTruth, '/eha/sim/truth', self.on_truth, big)
        self.subscribe(ActuatorState, '/eha/state', self.on_state, big)
        keep = latched_qos()
        keep.depth = 200                        # every status, not only the latest
        self.status = []
        self.lags = []          # per status in the scenario: (its seq, newest truth seq - it)
        self.subscribe(RedundancyStatus, '/eha/redundancy', self.on_status, keep)
        self.selects = self.received(ChannelSelect, '/eha/channel_select', keep)
        self.cmd_sub = self.subscribe(ActuatorCommand, '/eha/command', self.on_command, 10)

    def on_command(self, msg):
        self.commands += 1

    def on_truth(self, m):
        self.last_seq = m.seq
        if self.seq0 is not None:
            k = m.seq + REF_LEAD                # tick-locked, ahead of the DDS hop
            self.ref_pub.publish(self.Ref(seq=k, position=ref_at((k - self.seq0) * TS)))
            self.truth[m.seq] = (m.position, m.motor_speed[0], m.motor_speed[1],
                                 m.valve_fraction[0], m.valve_fraction[1], m.bypass_fraction)

    def on_status(self, m):
        self.status.append(m)
        if self.seq0 is not None:
            self.lags.append((m.seq, self.last_seq - m.seq))

    def on_state(self, m):
        if self.seq0 is not None:
            self.state[m.seq] = (bool(m.drive_enabled[0]), bool(m.drive_enabled[1]),
                                 int(m.active_channel))

    @property
    def plant_diag(self) -> dict:
        """The plant's newest status values."""
        return self.diagnostics.values('plant_sim', prefix=True)

    @property
    def diags(self) -> list:
        """(level, message, values) of every status of the switch manager's redundancy."""
        return [(s.msg.level, s.message, s.values)
                for s in self.diagnostics.all('switch_manager: redundancy')]

    def tau(self):
        return (self.last_seq - self.seq0) * TS if self.seq0 is not None else -1.0

    def wait_tau(self, tau, timeout=60.0):
        self.wait(lambda: self.tau() >= tau, timeout,
                  lambda: f'plant time {self.tau():.3f} s did not reach {tau} s', period=0.001)

    def arrays(self):
        """Truth and state matched by seq: t (scenario time), x, ref, w[2], valve[2], enable[2]."""
        seqs = sorted(k for k in self.truth if k in self.state)
        tr = np.array([self.truth[k] for k in seqs])
        st = np.array([self.state[k] for k in seqs])
        t = (np.array(seqs) - self.seq0) * TS
        return {'seq': np.array(seqs), 't': t, 'x': tr[:, 0],
                'ref': np.array([ref_at(v) for v in t]), 'w': tr[:, 1:3].T,
                'valve': tr[:, 3:5].T, 'bypass': tr[:, 5], 'enable': st[:, :2].T.astype(bool),
                'active': st[:, 2]}


@pytest.fixture(scope='module')
def run(rclpy_session, tmp_path_factory):
    from eha_msgs.srv import InjectFault, SwitchChannel
    tmp = tmp_path_factory.mktemp('sm')
    log_dir = str(tmp / 'redundancy')
    extra = {'switch_manager': ['-p', f'switch_manager:switch.node.log_dir:={log_dir}'],
             # the controller's integrator hold opens its K/s R(s) loop for 20 ms and steps
             # R's feed-through (measured: 1.9 mm extra deviation in the batch test); the
             # pre-spun valve cross-over needs no hold
             'controller': ['-p', 'controller:control.switch_hold:=0.0']}
    # A 1 kHz real-time stack on a shared 2-core machine: the nodes (and this recorder)
    # inherit a raised priority so batch jobs running next to the test do not starve the loop
    # (only where permitted; otherwise normal priority).
    nice0 = os.nice(0)
    try:
        os.nice(-5)
    except OSError:
        pass
    node = rclpy_session.create_node(f'test_sm_{os.getpid()}')
    rec = Recorder(node)
    spinner = EventsSpinner(node)
    stack = Stack(['plant_sim', 'estimator', 'controller', 'switch_manager'], extra=extra,
                  log_dir=str(tmp / 'logs'), lockstep=True).start()
    out = {'rec': rec, 'log_dir': log_dir, 'responses': {}}
    try:
        ready = wait_for(lambda: rec.commands > 200 and rec.status and rec.selects and
                         rec.ref_pub.get_subscription_count() > 0 and
                         rec.load_pub.get_subscription_count() > 0, 90, 0.05)
        assert ready, f'stack not up: dead {stack.dead()}, commands {rec.commands}'
        node.destroy_subscription(rec.cmd_sub)
        time.sleep(1.0)                         # let the loop settle at the rest position
        assert rec.status[-1].state == 'ACTIVE_A', \
            f'switch manager not in ACTIVE_A before the scenario: {rec.status[-1].reason}'
        out['diag0'] = dict(rec.plant_diag)
        rec.seq0 = rec.last_seq + 1
        rec.wait_tau(T_LOAD)
        rec.load_pub.publish(rec.Load(force=LOAD))
        rec.wait_tau(T_CMD)
        out['responses']['switch'] = rec.service(SwitchChannel, '/eha/switch_channel', channel=1,
                                                 reason='Table 3.4 switch at 3 s')
        for tau, ch, key in ((T_FAIL_B, 1, 'fail_b'), (T_FAIL_A, 0, 'fail_a')):
            rec.wait_tau(tau)
            out['responses'][key] = rec.service(InjectFault, '/eha/inject_fault',
                                                fault='motor_fail', channel=ch, magnitude=0.0,
                                                duration=0.0)
        rec.wait_tau(T_END)
        time.sleep(1.5)                        # a diagnostics period after the end
        out['diag1'] = dict(rec.plant_diag)
        out['dead'] = stack.dead()
    finally:
        results = stack.stop()
        try:
            os.nice(nice0 - os.nice(0))
        except OSError:
            pass
        spinner.close()
        node.destroy_node()
    out['stderr'] = {n: err for n, (code, err) in results.items()}
    out['data'] = rec.arrays()
    out['events'] = read_log(os.path.join(log_dir, EventLog.FILE))
    return out


def realtime(run) -> tuple[bool, str]:
    """Did the stack run as a real-time 1 kHz loop during the scenario? From the plant's
    /diagnostics counters (deltas over the scenario) and the tracking before the events."""
    d0, d1 = run['diag0'], run['diag1']

    def delta(key):
        return int(d1.get(key, 0)) - int(d0.get(key, 0))
    ticks = max(delta('ticks'), 1)
    over = delta('overruns') / ticks
    zeroed = delta('command_timeouts')
    d = run['data']
    band = B.tracking_figures(d['t'], d['x'], d['ref'], T_CMD, PERIOD)['band_m']
    rec = run['rec']
    lag = max((lag for k, lag in rec.lags if any(
        -0.05 <= (k - rec.seq0) * TS - t <= 0.5 for t in (T_CMD, T_FAIL_B, T_FAIL_A))),
        default=0)
    text = (f'{ticks} ticks: {100 * over:.1f} % overran, {zeroed} stale-command zeroings, '
            f'{100 * delta("commands_not_for_previous_tick") / ticks:.1f} % on a command '
            f'older than the previous tick; tracking band before the switch {band * 1e3:.2f} mm; '
            f'the switch manager up to {lag} ticks behind the plant around the events')
    # batch closed loop: band 0.96 mm; overruns and zeroed commands are plant-side hiccups;
    # in lock-step the plant keeps no deadline and the manager is off the loop's chain: its
    # selects reach the plant as many ticks late as it lags (a starved process)
    return over <= 0.1 and zeroed == 0 and band <= 2e-3 and lag <= MANAGER_LAG, text


def figures_valid(run, name):
    ok, text = realtime(run)
    print(f'{name}: real-time check: {text}')
    if not ok:
        pytest.skip(f'{name}: the DDS stack did not keep real time on this machine ({text}); '
                    f'the deviation figures would measure the overload, not the switch '
                    f'(batch figures: tests/test_redundancy_core.py)')


def first(mask):
    idx = np.nonzero(mask)[0]
    return int(idx[0]) if len(idx) else None


def tick_of(resp) -> int:
    m = re.search(r'\(tick (\d+)\)', resp.message)
    assert resp.success and m, resp.message
    return int(m.group(1))


def report(name, fig):
    os.makedirs(OUT, exist_ok=True)
    slug = re.sub(r'[^a-z0-9]+', '_', name.lower()).strip('_')
    with open(os.path.join(OUT, f'{slug}.json'), 'w') as fh:
        json.dump({'scenario': name, **fig}, fh, indent=1)
    print(f'{name} (DDS): ' + ', '.join(
        f'{k} = {v * 1e3:.3f} {"mm" if k.endswith("_m") else "ms"}' for k, v in fig.items()))


def scenario_ran(run):
    """The scenario needs ACTIVE_A until the commanded switch: no event logged before it (by
    the log's order, not by time: the manager stamps an event with the newest state it has
    handled, which may lag the tick at which this process asked for the switch; under load
    the commanded switch itself was stamped before T_CMD). An earlier event on a stack that
    did not keep real time is an overload artefact (skip, reported); otherwise a false alarm
    (fail)."""
    events = run['events']
    early = events[:next((i for i, e in enumerate(events) if e['commanded']), len(events))]
    if early:
        ok, text = realtime(run)
        msg = f'event before the commanded switch: {early[0]["kind"]}: {early[0]["reason"]}'
        if not ok:
            pytest.skip(f'{msg}; the DDS stack did not keep real time ({text})')
        pytest.fail(f'false alarm: {msg}')


def test_stack_ran_clean(run):
    print(f'plant real time over the scenario: {realtime(run)[1]}')
    assert not run['dead'], f'nodes died: {run["dead"]}'
    for name, err in run['stderr'].items():
        assert 'Traceback' not in err, f'{name}: {err}'
    d = run['data']
    assert len(d['t']) > 0.9 * T_END / TS, 'truth/state not matched for most ticks'
    # no event before the commanded switch: the load step is no false alarm
    scenario_ran(run)


def test_commanded_switch_table_3_4(run):
    scenario_ran(run)
    resp = run['responses']['switch']
    assert resp.success, resp.message
    ev = [e for e in run['events'] if e['kind'] == 'switch_start' and e['commanded']]
    assert len(ev) == 1 and ev[0]['from_channel'] == 0 and ev[0]['to_channel'] == 1
    assert 'Table 3.4' in ev[0]['reason']
    t_s = ev[0]['seq'] * TS - run['rec'].seq0 * TS
    d = run['data']
    fig = B.tracking_figures(d['t'], d['x'], d['ref'], t_s, PERIOD)
    done = [e for e in run['events'] if e['kind'] == 'switch_done'][0]
    report('Table 3.4 commanded switch', dict(fig, switch_duration_s=done['t'] - ev[0]['t']))
    # B drives afterwards: from the tick the plant shows the finished sequence until the fault
    # (when it shows it depends on DDS latency; the sequence itself is timed in plant ticks)
    b_only = (d['active'] == 1) & (d['valve'][1] == 1.0) & (d['valve'][0] == 0.0) & \
        ~d['enable'][0] & d['enable'][1]
    k0 = first(b_only & (d['t'] >= t_s))
    assert k0 is not None and d['t'][k0] < T_FAIL_B, 'the switch never completed in the plant'
    print(f'commanded switch: sequence complete in the plant {1e3 * (d["t"][k0] - t_s):.0f} ms '
          f'after the request')
    assert np.all(b_only[k0:][d['t'][k0:] < T_FAIL_B])
    figures_valid(run, 'commanded switch')
    assert fig['extra_deviation_m'] <= 1e-3
    assert fig['recovery_time_s'] <= 0.05


def test_motor_fail_automatic_switch(run):
    scenario_ran(run)
    rec, d = run['rec'], run['data']
    t_f = (tick_of(run['responses']['fail_b']) - rec.seq0) * TS
    auto = [e for e in run['events'] if e['kind'] == 'switch_start' and not e['commanded']]
    assert auto and auto[0]['from_channel'] == 1 and auto[0]['to_channel'] == 0
    assert 'drive' in auto[0]['reason'] and auto[0]['health']['B']['drive']['healthy'] is False
    t_drive = B.driving_time(d['t'], d['valve'], d['enable'], 0, t_f)
    fig = B.tracking_figures(d['t'], d['x'], d['ref'], t_f, PERIOD)
    report('motor_fail on active B', dict(fig, fault_to_A_driving_s=t_drive,
                                          detection_s=auto[0]['seq'] * TS - rec.seq0 * TS - t_f))
    # reported on /eha/redundancy
    st = [s for s in rec.status if s.reason.startswith('channel B unhealthy: drive')]
    assert st and all(list(s.channel_healthy) == [True, False] for s in st)
    assert 'SWITCHING' in {s.state for s in st}
    assert any(s.state == 'DEGRADED' and list(s.channel_healthy) == [True, False]
               for s in rec.status)
    figures_valid(run, 'motor_fail')
    assert t_drive <= 0.1
    assert fig['extra_deviation_m'] <= 3e-3


def test_both_failed_safe_state_reported_no_oscillation(run):
    scenario_ran(run)
    figures_valid(run, 'both failed')      # health verdicts need a stack that kept real time
    rec, d = run['rec'], run['data']
    t_f = (tick_of(run['responses']['fail_a']) - rec.seq0) * TS
    kinds = [e['kind'] for e in run['events']]
    print(f'events (DDS): {kinds}')
    assert kinds.count('safe') == 1 and kinds[-1] == 'safe'
    assert kinds.count('switch_start') == 2
    safe = run['events'][-1]
    t_safe = safe['seq'] * TS - rec.seq0 * TS
    assert 0.0 <= t_safe - t_f <= 0.05 and safe['to_state'] == 'FAILED_SAFE', \
        f'fault at {t_f:.3f} s, safe state at {t_safe:.3f} s'
    final = rec.status[-1]
    assert final.state == 'FAILED_SAFE' and final.switch_count == 2
    assert list(final.channel_healthy) == [False, False]
    sel = rec.selects[-1]
    assert list(sel.drive_enable) == [False, False] and list(sel.valve_open) == [False, False]
    assert not sel.bypass_open                           # default safe_mode: hold
    # no switching after the safe state: once the plant shows it, valves stay closed, drives off
    safe_in_plant = np.all(d['valve'] == 0.0, axis=0) & ~d['enable'].any(axis=0)
    k0 = first(safe_in_plant & (d['t'] >= t_safe))
    assert k0 is not None, 'the safe state never reached the plant'
    print(f'safe state in the plant {1e3 * (d["t"][k0] - t_safe):.0f} ms after the decision')
    assert np.all(safe_in_plant[k0:])
    after = np.arange(len(d['t'])) >= k0
    x = d['x'][after]
    print(f'hold under 10 kN (DDS): piston moved {1e3 * (x[-1] - x[0]):.3f} mm in '
          f'{d["t"][after][-1] - d["t"][after][0]:.2f} s')
    level, text, values = rec.diags[-1]
    assert level == b'\x02' and text.endswith('; safe state hold') and 'not available' in text
    assert values['state'] == 'FAILED_SAFE'


def test_switch_plots(run):
    scenario_ran(run)
    d, rec = run['data'], run['rec']
    starts = [e for e in run['events'] if e['kind'] in ('switch_start', 'safe')]
    times = [e['seq'] * TS - rec.seq0 * TS for e in starts]
    recd = {'t': d['t'], 'ref': d['ref'], 'x': d['x'], 'w0': d['w'][0], 'w1': d['w'][1],
            'valve0': d['valve'][0], 'valve1': d['valve'][1], 'bypass': d['bypass'],
            'active': d['active']}
    os.makedirs(OUT, exist_ok=True)
    for old in os.listdir(OUT):                  # plots of this run only
        if old.startswith('switch_') and old.endswith('.png'):
            os.remove(os.path.join(OUT, old))
    write_csv(os.path.join(OUT, 'recording.csv'), recd)
    paths = plot_switches(recd, times, OUT, labels=[
        f'DDS: {e["kind"]} {e["from_state"]} -> {e["to_state"]}' for e in starts])
    assert len(paths) == 3
    print('plots: ' + ', '.join(os.path.relpath(p, ROOT) for p in paths))


def test_lock_step_state_handled_before_its_command_is_not_judged(rclpy_session):
    """Lock-step: the plant steps to state k on command k - 1. A starved manager that takes
    its queued states before the commands must not judge them against the older references
    (CI: a 3 Hz sine of the identification tripped both couples, 181 and 258 rad/s against
    150); once the commands are in, the same speed error trips couple A."""
    from eha_msgs.msg import ActuatorCommand, ActuatorState
    from eha_ros.core.redundancy.params import SCHEMA
    from eha_ros.core.sim.batch import node_params
    from eha_ros.nodes import switch_manager

    def state(seq, w):
        node.handle_state(ActuatorState(
            seq=seq, motor_speed=[w, 0.0], motor_current=[0.0, 0.0], pressure_a=1.2e6,
            pressure_b=1.0e6, active_channel=0, valid=True, drive_enabled=[True, False],
            drive_fault=[False, False]))

    def command(seq, w):
        node.on_command(ActuatorCommand(seq=seq, motor_speed_ref=w))

    for lockstep, trips_while_behind in ((True, False), (False, True)):
        node = switch_manager.make_node(node_params('switch_manager', SCHEMA))
        try:
            node.lockstep = lockstep
            for k in range(1, 2600):            # the loop closed at rest: armed after 2 s
                command(k - 1, 0.0)
                state(k, 0.0)
            assert node.armed and node.mgr.name == 'ACTIVE_A'
            for k in range(2600, 2700):         # 400 rad/s off, the commands not yet in
                state(k, 400.0)
            assert (node.mgr.name != 'ACTIVE_A') == trips_while_behind, node.mgr.name
            if lockstep:
                assert node.c['states_before_their_command'] == 49   # then no fresh command
                for k in range(2600, 2800):
                    command(k - 1, 0.0)
                    if k >= 2700:
                        state(k, 400.0)
                assert node.mgr.name == 'DEGRADED'      # judged: A tripped, B took over
        finally:
            node.destroy_node()
