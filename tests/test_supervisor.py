"""The loop supervisor (core.loop.supervisor, in the switch manager): each condition trips it from
the first tick that meets it, names the culprit, and the switch_manager node answers with the
safe state (channel select: drives off, valves closed), one ERROR log line and ERROR on
/diagnostics at once.

Core: synthetic streams, ticks counted by seq. Node: switch_manager as its own process, fed
state/estimate/command over DDS by this test at about 1 kHz (its health monitors off: only
the supervisor judges), each fault from a known tick; detection times printed."""
import dataclasses
import math
import threading
import time

import pytest

from eha_ros.core.loop.supervisor import (LIMIT_CYCLE, REJECTED, STALLED, UNANSWERED,
                                          LoopSupervisor, SupervisorParams)
import probes
from ros_util import start_process, stop_process, wait_for, wait_matched

from eha_ros.core.redundancy.params import SCHEMA

DEFAULTS = SupervisorParams.from_params(SCHEMA.defaults())
TS, WMAX = DEFAULTS.Ts, DEFAULTS.omega_max


def params(**kw) -> SupervisorParams:
    """The switch manager's defaults (1 ms, 837.8 rad/s, 0.2 s stall, 50 ms reject, ...)."""
    return dataclasses.replace(DEFAULTS, **kw)


def feed(fault=None, at=2000, n=5000, realtime=True, every=20, **kw):
    """Run the supervisor over n synthetic ticks; the fault from tick ``at``. Returns the trip
    and the tick it came at."""
    sup = LoopSupervisor(params(realtime=realtime, **kw))
    for k in range(n):
        t = k * TS
        if k % every == 0:
            sup.check(t)
        if sup.trip:
            return sup.trip, k
        late = k >= at
        if fault == 'plant' and late:
            continue
        sup.state(k, t)
        if fault == 'estimator' and late:
            continue
        lag = fault == 'busy_estimator' and late     # its estimate(k) comes a tick later
        sup.estimate(k - lag, fault == 'rejected' and late, False, t)
        if fault in ('controller', 'busy_estimator') and late or fault == 'lossy' and late and k % 4 == 0:
            continue
        u = WMAX * math.copysign(1.0, math.sin(2 * math.pi * 6 * t)) \
            if fault == 'cycle' and late else 300.0 * math.sin(2 * math.pi * 0.5 * t)
        sup.command(k, u, t)
    return sup.trip, None


def test_healthy_loop_never_trips():
    # a one-way saturated slew (a long step) and a sine are not a limit cycle
    sup = LoopSupervisor(params())
    for k in range(4000):
        t = k * TS
        sup.check(t) if k % 20 == 0 else None
        sup.state(k, t)
        sup.estimate(k, False, False, t)
        sup.command(k, WMAX if 1000 <= k < 1800 else 200 * math.sin(2 * math.pi * 3 * t), t)
    assert sup.trip is None
    assert feed()[0] is None


@pytest.mark.parametrize('fault,kind,node,ticks', [
    ('controller', STALLED, 'controller', 200), ('estimator', STALLED, 'estimator', 200),
    ('plant', STALLED, 'plant side', 200), ('rejected', REJECTED, None, 50),
    # real time: the estimator a tick behind but not silent is busy, not the culprit
    ('busy_estimator', STALLED, 'controller', 200),
    # 6 Hz bang-bang: the 4th reversal 3.5 half-periods in (+ the first half-period); a
    # quarter of the ticks unanswered: the 1 s window's share passes 2 % after 80 ticks
    ('cycle', LIMIT_CYCLE, None, 250), ('lossy', UNANSWERED, None, 80)])
def test_each_condition_trips_and_names_the_node(fault, kind, node, ticks):
    trip, k = feed(fault)
    assert trip is not None and trip.kind == kind, trip
    if node:
        assert trip.message.startswith(f'{node} stalled'), trip.message
    # within the stated time (+ one check period for the wall-clock checks)
    print(f'{fault}: {kind} after {k - 2000} ticks: {trip.message}')
    assert ticks - 5 <= k - 2000 <= ticks + 25


def test_a_trip_is_dated_by_the_tick_it_tripped_on():
    """A starved node takes its queues in any order: here the states lag 866 ticks behind the
    estimates (seen on a loaded machine in test_node_trips_to_the_safe_state). The rejected
    trip carries the seq of the estimate that tripped it, the limit cycle that of the command,
    not the newest state's."""
    sup = LoopSupervisor(params())
    for k in range(3000):
        t = k * TS
        sup.state(max(k - 866, 0), t)
        sup.estimate(k, k >= 2000, False, t)
        sup.command(k, 0.0, t)
        if sup.trip:
            break
    assert sup.trip.kind == REJECTED and sup.trip.seq == k == 2000 + sup.reject_n - 1
    trip, k = feed('cycle')
    assert trip.kind == LIMIT_CYCLE and trip.seq == k - 1     # feed sees it a tick later


def test_lockstep_stall_waits_longer_and_no_answer_check():
    trip, k = feed('controller', realtime=False, n=9000, lockstep_stall_timeout=5.0)
    assert trip.kind == STALLED and 5000 <= k - 2000 <= 5025
    assert feed('lossy', realtime=False)[0] is None


def test_own_pause_is_not_an_upstream_stall():
    """The whole process paused (no check, no stream) for 1 s: not a stall once it resumes."""
    sup = LoopSupervisor(params())
    for k in list(range(2000)) + list(range(3000, 4000)):
        t = k * TS
        sup.check(t) if k % 20 == 0 else None
        sup.state(k, t)
        sup.estimate(k, False, False, t)
        sup.command(k, 0.0, t)
    assert sup.trip is None or sup.trip.kind == UNANSWERED   # the lost ticks do count
    sup.reset(5.0)
    assert sup.trip is None


def test_no_command_at_start_names_the_silent_node():
    sup = LoopSupervisor(params(start_timeout=1.0))
    for k in range(1100):
        sup.check(k * TS) if k % 20 == 0 else None
        sup.state(k, k * TS)
        sup.estimate(k, False, False, k * TS)
    assert sup.trip.kind == STALLED and sup.trip.message.startswith('controller: no answer')


# ---------------------------------------------------------------- the node over DDS
MONITORS_OFF = [a for m in ('speed', 'current', 'pressure', 'estimator')
                for a in ('-p', f'switch_manager:switch.health.{m}.enabled:=false')]
# The feeder is a Python thread in the test process. On a loaded 2-core machine the manager
# wakes to a backlog and may take state(k+1) before command(k): CI once saw "unanswered: 10 %
# of the ticks" trip before the limit cycle. The unanswered check is the unit tests' (above)
# and test_run_stack's business; here it is off (share > 1 never holds).
UNANSWERED_OFF = ['-p', 'switch_manager:switch.supervisor.max_unanswered:=1.0']
# A stall of the feeder thread beyond the stall timeout (0.2 s) is a stalled plant side to the
# manager: on a loaded machine this test process can stall that long (the bridge test's did
# 193 ms in CI). The node tests run with 1 s; the 'controller' case measures it.
STALL = 1.0
STALL_SLOW = ['-p', f'switch_manager:switch.supervisor.stall_timeout:={STALL}']


class Feeder(probes.Probe):
    """Publishes state/estimate/command at about 1 kHz from a thread; ``fault`` from tick
    ``fault_at`` on; records the manager's selects and supervisor diagnostics with arrival
    times."""

    def __init__(self, node, fault):
        from eha_msgs.msg import (ActuatorCommand, ActuatorState, ChannelSelect,
                                  PositionEstimate)
        from eha_ros.nodes.common import latched_qos, stream_qos
        super().__init__(node)
        self.State, self.Est, self.Cmd = ActuatorState, PositionEstimate, ActuatorCommand
        self.pubs = [node.create_publisher(t, f'/eha/{n}', stream_qos()) for t, n in
                     ((ActuatorState, 'state'), (PositionEstimate, 'estimate'),
                      (ActuatorCommand, 'command'))]
        self.fault, self.fault_at, self.t_fault = fault, None, None
        self.selects = self.received(ChannelSelect, '/eha/channel_select', latched_qos(),
                                     stamped=True)
        self.stop = threading.Event()
        self.k = 0

    @property
    def errors(self) -> list:
        """(arrival time, message) of every ERROR of the supervisor."""
        return [(s.t, s.message) for s in self.diagnostics.all('switch_manager: supervisor')
                if s.level == 2]

    def run(self):
        ps, pe, pc = self.pubs
        st, es, cm = self.State(), self.Est(), self.Cmd()
        st.valid = True
        st.pressure_a = st.pressure_b = 2.0e6
        st.drive_enabled = [True, False]
        t_next = time.monotonic()
        while not self.stop.is_set():
            k, late = self.k, self.fault_at is not None and self.k >= self.fault_at
            if late and self.t_fault is None:
                self.t_fault = time.monotonic()
            st.seq = es.seq = cm.seq = k
            ps.publish(st)
            es.update_skipped = late and self.fault == 'rejected'
            pe.publish(es)
            if not (late and self.fault == 'controller'):
                cm.motor_speed_ref = WMAX * (1.0 if (k // 80) % 2 else -1.0) \
                    if late and self.fault == 'cycle' else 0.0
                pc.publish(cm)
            self.k += 1
            t_next += TS
            time.sleep(max(0.0, t_next - time.monotonic()))


@pytest.mark.ros
@pytest.mark.parametrize('fault,kind', [('controller', 'stalled'), ('rejected', 'rejected'),
                                        ('cycle', 'limit_cycle')])
def test_node_trips_to_the_safe_state(ros_node, tmp_path, fault, kind):
    from ros_util import Spinner
    feeder = Feeder(ros_node, fault)
    spin = Spinner(ros_node)
    proc = start_process(
        [__import__('eha_ros.stack', fromlist=['node_command']).node_command('switch_manager')[0],
         '--ros-args', '--params-file', _cfg('plant.yaml'), '--params-file',
         _cfg('switch_manager.yaml'), '-p', f'switch_manager:switch.node.log_dir:={tmp_path}']
        + MONITORS_OFF + UNANSWERED_OFF + STALL_SLOW)
    thread = threading.Thread(target=feeder.run, daemon=True)
    try:
        wait_matched(*feeder.pubs)
        assert wait_for(lambda: feeder.selects, 30), 'no channel select from the manager'
        thread.start()
        time.sleep(2.5)                  # healthy beyond the start-up grace (arm_time, 2 s)
        assert not feeder.errors, feeder.errors
        feeder.fault_at = feeder.k + 1
        assert wait_for(lambda: feeder.errors, 10), f'{fault}: no supervisor ERROR'
        assert wait_for(lambda: any(not any(m.drive_enable) and not any(m.valve_open)
                                    for _, m in feeder.selects[1:]), 5)
        t_err, text = feeder.errors[0]
        t_safe = next(t for t, m in feeder.selects[1:]
                      if not any(m.drive_enable) and not any(m.valve_open))
        print(f'{fault}: ERROR after {1e3 * (t_err - feeder.t_fault):.0f} ms, safe state '
              f'(select: drives off, valves closed) after {1e3 * (t_safe - feeder.t_fault):.0f} '
              f'ms: {text}')
        assert text.startswith(kind + ': ')
        limit = {'controller': STALL, 'rejected': 0.05, 'cycle': 0.5}[fault]
        if fault == 'controller':          # a stall is wall time, the manager's clock
            assert STALL - 0.05 < t_err - feeder.t_fault
            assert t_safe - feeder.t_fault < limit + 0.5     # + DDS/scheduling slack
        else:                              # counted in ticks: the seq of the trip
            trip = next(st for st in feeder.diagnostics.all('switch_manager: supervisor')
                        if st.level == 2)
            ticks = int(trip.values['seq']) - feeder.fault_at
            print(f'{fault}: tripped {ticks} ticks after the fault')
            # the feeder, a Python thread, slows on a loaded machine and the trip with it in wall
            # time (2.5 s for the limit cycle once, both cores busy); the ticks it takes do not
            assert 0 <= ticks * TS < limit + 0.05
    finally:
        feeder.stop.set()
        thread.join(timeout=5) if thread.is_alive() else None
        rc, _, err = stop_process(proc)
        spin.close()
    lines = [ln for ln in err.splitlines() if 'loop supervisor' in ln and 'ERROR' in ln]
    assert len(lines) == 1, err[-2000:]                 # logged once
    assert rc == 0, err[-2000:]


def _cfg(name):
    import os
    from eha_ros.core.config.params import default_config_dir
    return os.path.join(default_config_dir(), name)


def test_saturated_share_is_the_share_of_saturated_commands_in_the_window():
    """Kept as a running count (diagnostics read it beside the loop thread: no iteration)."""
    import numpy as np
    sup = LoopSupervisor(params())
    limit = sup.p.saturation * sup.p.omega_max
    rng = np.random.default_rng(3)
    signs = []
    for seq in range(3 * sup.n):
        speed = float(rng.choice([-1.5, -0.5, 0.0, 0.5, 1.5])) * limit
        sup.command(seq, speed, 0.0)
        signs.append((speed >= limit) - (speed <= -limit))
        if seq % 97 == 0:
            window = signs[-sup.n:]
            assert sup.saturated_share == pytest.approx(sum(1 for s in window if s) / sup.n)
    assert len(sup.sat) == sup.n
