"""switch_manager node: redundancy switch manager of the dual motor-pump EHA (thesis 3.4,
Fig. 3.12) around core.redundancy.SwitchManager.

Subscribes eha/state (each one is a tick of the manager; time = seq Ts), eha/command (speed
reference for the tracking monitor) and eha/estimate (innovation); publishes eha/channel_select
(latched) whenever the valve/drive command changes, eha/redundancy (latched) on change and
every status_period, /diagnostics; serves eha/switch_channel; appends every transition to
<log_dir>/switch_events.jsonl. Topics only, so it runs with plant_sim and the hardware
bridge alike.
"""
from __future__ import annotations

import math
import sys
import threading
import time

from eha_msgs.msg import (ActuatorCommand, ActuatorState, ChannelSelect, PositionEstimate,
                          RedundancyStatus)
from eha_msgs.srv import SwitchChannel

from ..core.loop import safe_state as SAFE
from ..core.redundancy import EventLog, SwitchManager
from ..core.redundancy import stepper as RS
from ..core.redundancy.params import SCHEMA
from ..core.stats import Counters, LoopStats
from ..core.loop.supervisor import LoopSupervisor, SupervisorParams
from . import diag
from .common import declare_and_validate, factory, publish_counted, qos_of, run
from ..core import topics as T


SUPERVISOR_CHECK = 0.02      # [s] wall-clock period of the supervisor's stall check


class SwitchManagerNode:
    """The switch manager node (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict):
        super().__init__('switch_manager')
        self.p = p = declare_and_validate(self, SCHEMA, params)
        self.Ts = p['plant.sim.Ts']
        self.max_cmd_age_ticks = int(round(p['switch.health.speed.max_command_age'] /
                                           self.Ts))
        self.arm_ticks = int(round(p['switch.node.arm_time'] / self.Ts))
        self.fresh_since, self.armed = None, False
        self.mgr = SwitchManager(p)
        # per state, compiled; every change of the manager goes through it
        self.tick = RS.ManagerTick(self.mgr, self.max_cmd_age_ticks)
        self.log = EventLog(p['switch.node.log_dir'])
        self.lock = threading.Lock()
        self.c = Counters()
        self.loop = LoopStats(self.Ts)
        self.speed_ref = 0.0
        self.cmd_seq = None
        self.innovation, self.estimate_ok = float('nan'), False
        self.last_state_time = None
        self.state_stale = False
        self.last_seq = None
        self.sent_select = None
        self.sent_status = None
        self.logged = 0
        realtime = not self.get_parameter('use_sim_time').value
        self.lockstep = not realtime
        self.sup = LoopSupervisor(SupervisorParams.from_params(p, realtime))
        self.sup_reported = None
        self.pub_select = self.create_publisher(ChannelSelect, T.CHANNEL_SELECT.name,
                                                qos_of(T.CHANNEL_SELECT))
        self.pub_status = self.create_publisher(RedundancyStatus, T.REDUNDANCY.name,
                                                qos_of(T.REDUNDANCY))
        self.pub_diag = diag.publisher(self)
        # the state's queue deeper: a starved executor catches up instead of dropping
        self.create_subscription(ActuatorState, T.STATE.name, self.on_state,
                                 qos_of(T.STATE, depth=200))
        self.create_subscription(ActuatorCommand, T.COMMAND.name, self.on_command,
                                 qos_of(T.COMMAND, depth=200))   # and the commands with them
        self.create_subscription(PositionEstimate, T.ESTIMATE.name, self.on_estimate,
                                 qos_of(T.ESTIMATE))
        self.create_service(SwitchChannel, T.SWITCH_CHANNEL.name, self.on_switch)
        from rclpy.clock import Clock, ClockType
        # wall time, also in lock-step: a stalled loop stops the simulated clock, and on the
        # simulated clock rclpy's EventsExecutor stopped firing these timers in most lock-step
        # runs under load (docs/nodes/switch_manager.md)
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(p['switch.node.status_period'], self.on_status_timer, clock=wall)
        self.create_timer(p['switch.node.diagnostics_period'], self.publish_diagnostics,
                          clock=wall)
        self.create_timer(SUPERVISOR_CHECK, self.on_supervisor_timer, clock=wall)
        self.Select, self.Status = ChannelSelect, RedundancyStatus
        self.flush()
        self.get_logger().info(
            f'switch_manager: {self.mgr.name}, valve time '
            f'{p["plant.valves.onoff_time"] * 1e3:.0f} ms, safe mode {p["switch.safe_mode"]}, '
            f'event log {self.log.path or "off"}')

    # ---- inputs ----
    def on_command(self, msg):
        if not math.isfinite(msg.motor_speed_ref):
            self.c.bump('rejected_commands')
            return
        self.speed_ref = float(msg.motor_speed_ref)
        self.cmd_seq = int(msg.seq)
        self.tick.command(self.cmd_seq, self.speed_ref)
        self.sup.command(self.cmd_seq, self.speed_ref, time.monotonic())
        self.supervise()

    def on_estimate(self, msg):
        if not math.isfinite(msg.innovation):
            self.c.bump('rejected_estimates')
            self.estimate_ok = False
            return
        self.innovation = float(msg.innovation)
        self.estimate_ok = not (msg.stale or msg.update_skipped or msg.sensor_fault)
        self.sup.estimate(int(msg.seq), msg.update_skipped and not msg.sensor_fault,
                          msg.stale, time.monotonic())
        self.supervise()
        if SAFE.position_fault(msg.consistency):
            with self.lock:
                entered = self.tick.safe_state(SAFE.manager_reason(msg.consistency))
            if entered:
                self.c.bump('position_faults')
                self.flush()                 # the lock goes out now, logged once

    def on_state(self, msg):
        self.loop.timed(self.handle_state, msg)

    def handle_state(self, msg):
        speed, current = msg.motor_speed, msg.motor_current
        if self.last_seq is not None and msg.seq > self.last_seq + 1:
            self.c.bump('lost_states', int(msg.seq - self.last_seq - 1))
        self.last_seq = msg.seq
        self.last_state_time = now = time.monotonic()
        self.sup.state(int(msg.seq), now)      # arrived: the loop's timing counts it
        finite = math.isfinite
        if not (msg.valid and finite(speed[0]) and finite(speed[1]) and finite(current[0])
                and finite(current[1])):
            # speeds/currents are what the monitors judge: a bad sample is not evidence
            # (a repeated device sample is published not valid: the bridge's catch-up)
            self.c.bump('rejected_states')
            return
        # the loop is closed (and the speed reference known) only while commands answer
        # recent states (a stale command is zeroed in the plant/bridge, unseen from here)
        fresh = self.cmd_seq is not None and \
            msg.seq - self.cmd_seq <= self.max_cmd_age_ticks
        if not fresh:
            self.fresh_since = None
        elif self.fresh_since is None:
            self.fresh_since = msg.seq
        if not self.armed and fresh and msg.seq - self.fresh_since >= self.arm_ticks:
            self.armed = True               # once: the start-up transient is over
            self.get_logger().info(f'position loop closed for '
                                   f'{self.p["switch.node.arm_time"]:g} s: monitors armed')
        if not fresh:
            self.c.bump('states_without_fresh_command')
        # lock-step: the plant stepped to this state on its previous tick's command; handled
        # before that command reached us (a starved executor takes its queued states first),
        # the band would hold older references only, so the state is not judged (CI: a
        # 3 Hz sine tripped both couples' speed monitors, 181 and 258 rad/s against 150)
        behind = self.lockstep and fresh and self.cmd_seq < msg.seq - 1
        if behind:
            self.c.bump('states_before_their_command')
        with self.lock:     # the speed error from the band of recent references (ManagerTick)
            self.tick.update(msg.seq * self.Ts, int(msg.seq), self.speed_ref,
                             self.armed and fresh and not behind, speed, current,
                             float(msg.pressure_a), float(msg.pressure_b), msg.drive_enabled,
                             msg.drive_fault, self.innovation, self.estimate_ok)
        self.supervise()
        self.flush()

    def on_switch(self, req, resp):
        with self.lock:
            was_safe = self.mgr.name == 'FAILED_SAFE'
            ok, text = self.tick.request(int(req.channel), req.reason)
            if ok and was_safe and self.sup.trip is not None:
                self.sup.reset(time.monotonic())      # the operator left the safe state
                self.sup_reported = None
        resp.success, resp.message = bool(ok), text
        self.c.bump('switch_requests' if ok else 'switch_requests_refused')
        self.get_logger().info(f'switch_channel {req.channel} ({req.reason!r}): {text}')
        self.flush()
        return resp

    # ---- loop supervisor ----
    def on_supervisor_timer(self):
        self.sup.check(time.monotonic())
        self.supervise()

    def supervise(self):
        """A new supervisor trip: the safe state (latched like a position fault), one ERROR
        line, ERROR on /diagnostics at once."""
        trip = self.sup.trip
        if trip is None or trip is self.sup_reported:
            return
        self.sup_reported = trip
        with self.lock:
            entered = self.tick.safe_state(f'loop supervisor: {trip.message}')
        self.c.bump('supervisor_trips')
        then = f'safe state {self.p["switch.safe_mode"]}' if entered else \
            'already in the safe state'
        self.get_logger().error(f'loop supervisor ({trip.kind}): {trip.message}; {then}')
        self.flush()
        self.publish_supervisor()

    @diag.reader
    def publish_supervisor(self):
        trip = self.sup.trip
        values = dict(self.sup.values(), seq=trip.seq if trip else self.last_seq or 0)
        diag.publish(self, self.pub_diag, 'supervisor', values,
                     diag.ERROR if trip else diag.OK,
                     f'{trip.kind}: {trip.message}' if trip else 'ok')

    # ---- outputs ----
    def flush(self):
        """Publish select/status when they changed; append new events to the log."""
        with self.lock:
            sel = self.mgr.select
            status = self.status_now()
            events = self.mgr.events[self.logged:]
            self.logged = len(self.mgr.events)
            seq = self.mgr.seq
        if sel is not self.sent_select and sel != self.sent_select:
            m = self.Select()
            m.header.stamp = self.get_clock().now().to_msg()
            m.seq = int(seq)
            m.channel = int(sel.channel)
            m.drive_enable = [bool(b) for b in sel.drive_enable]
            m.valve_open = [bool(b) for b in sel.valve_open]
            m.bypass_open = bool(sel.bypass_open)
            publish_counted(self, self.pub_select, m, 'channel_select', seq)
            self.sent_select = sel
        if status != self.sent_status:
            self.publish_status(status, seq)
        for ev in events:
            try:
                self.log.append(ev)
            except OSError as err:
                self.c.bump('log_errors')
                self.get_logger().error(f'switch-event log {self.log.path}: {err.strerror}',
                                        throttle_duration_sec=5.0)
            text = (f'{ev.kind} at t={ev.t:.3f} s (seq {ev.seq}): {ev.from_state} -> '
                    f'{ev.to_state}: {ev.reason}')
            if ev.kind in ('switch_start', 'safe', 'degraded', 'refused'):
                self.get_logger().warning(text)      # one call site per severity (rclpy)
            else:
                self.get_logger().info(text)
            if ev.kind == 'safe':
                self.publish_diagnostics()

    def status_now(self) -> tuple:
        """What /eha/redundancy carries (publish_status), compared to tell a change; under
        self.lock."""
        m = self.mgr
        return (m.select.channel, tuple(m.channel_healthy), m.switch_count, m.name, m.reason,
                m.pressure_sensor_fault)

    def publish_status(self, status, seq):
        m = self.Status()
        m.header.stamp = self.get_clock().now().to_msg()
        m.seq = int(seq)
        m.active_channel, healthy, m.switch_count, m.state, m.reason, failed = status
        m.pressure_sensors_failed = bool(failed)
        m.channel_healthy = [bool(b) for b in healthy]
        publish_counted(self, self.pub_status, m, 'redundancy status', seq)
        self.sent_status = status

    def on_status_timer(self):
        with self.lock:
            status = self.status_now()
            seq = self.mgr.seq
        self.publish_status(status, seq)
        t = self.last_state_time
        stale = t is not None and time.monotonic() - t > self.p['switch.node.state_timeout']
        if stale and not self.state_stale:
            self.c.bump('state_timeouts')
            self.get_logger().warning('no /eha/state: health is not being monitored')
        self.state_stale = stale

    @diag.reader
    def publish_diagnostics(self):
        with self.lock:
            mgr = self.mgr
            values = {'state': mgr.name, 'active_channel': mgr.active,
                      'switch_count': mgr.switch_count, 'reason': mgr.reason,
                      'healthy_A': mgr.channel_healthy[0],
                      'healthy_B': mgr.channel_healthy[1],
                      'why_A': mgr.health.why(0), 'why_B': mgr.health.why(1),
                      'pressure_plausible': mgr.health.pressure_plausible,
                      'pressure_sensors_failed': mgr.pressure_sensor_fault,
                      'state_stale': self.state_stale, 'armed': self.armed,
                      'events': len(mgr.events),
                      'last_event': mgr.events[-1].line() if mgr.events else ''}
            name, reason, sensors = mgr.name, mgr.reason, mgr.pressure_sensor_fault
        values.update(self.c)
        values.update(self.loop.values())
        if name == 'FAILED_SAFE':
            level, text = diag.ERROR, reason      # why; safe state <switch.safe_mode>
        elif name == 'DEGRADED' or self.state_stale or sensors:
            level, text = diag.WARN, ('no redundancy left' if name == 'DEGRADED' else
                                      'no /eha/state' if self.state_stale else
                                      'pressure sensors failed: pressure monitor off')
        else:
            level, text = diag.OK, name
        diag.publish(self, self.pub_diag, 'redundancy', values, level, text)
        self.publish_supervisor()


make_node = factory(SwitchManagerNode)     # make_node(params, transport=None)


def main(argv=None) -> int:
    return run('switch_manager', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
