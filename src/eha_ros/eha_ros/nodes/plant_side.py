"""The plant-side node program: one loop owner for every backend (core.hardware: sim, ads, mock),
a managed (lifecycle) node like ros2_control's hardware components.

Per tick (Ts = plant.sim.Ts): the command gate (core.hardware.gate) turns the latest
eha/command into the speed reference, the backend's ``write`` applies it and ``read`` returns
the next sample, published as eha/state(k+1) (plus eha/sim/truth from the simulator).
Real time: a loop thread with absolute deadlines (overruns counted, catch-up, resynchronised
when more than MAX_CATCH_UP periods behind). Lock-step (<prefix>.lockstep): the loop thread
steps when command(k) arrived, publishes /clock, re-publishes state(k) after lockstep_timeout;
nodes.common.StartGate holds tick 0 (both modes) until a recorder listens; in lock-step,
nodes.common.Pace holds a tick while that recorder is more than Pace.LAG messages behind.

Lifecycle (lifecycle_msgs services ~/change_state, ~/get_state, ...):
- configure: backend connected and checked (ads: link up, symbol table); the loop runs and
  publishes states, commands are not applied (INACTIVE).
- activate: the gate arms (ads: today's arming conditions); commands applied (ACTIVE).
- deactivate: zero speed, disarmed. cleanup: loop stopped, device released.
- error (a transition that raised): zero speed, loop stopped, device released (UNCONFIGURED).
A link loss while ACTIVE disarms the gate at once (in the loop) and deactivates the node.
eha/plant_state (latched lifecycle_msgs/State) says whether commands are applied; the
controller rests while it is not ACTIVE. <prefix>.autostart: the state reached at start-up.
/diagnostics: '<node>: loop' with the same keys for every backend (plus the backend's own).
"""
from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass
from typing import Callable

from builtin_interfaces.msg import Time
from eha_msgs.msg import ActuatorCommand, ActuatorState, ChannelSelect, ExternalLoad, PlantTruth
from eha_msgs.srv import InjectFault
from rclpy.lifecycle import LifecycleNodeMixin, TransitionCallbackReturn as Ret
from rosgraph_msgs.msg import Clock
from std_srvs.srv import SetBool, Trigger

from ..core.config.cli import UsageError
from ..core.hardware.gate import CommandGate
from ..core.hardware.interface import HardwareError
from ..core.config.params import ParamError, Schema
from ..core.stats import Counters, Histogram, RingStats
from . import diag
from .common import (Pace, PlantState, StartGate, bind, channel_ok, declare_and_validate,
                     publish_counted, qos_of, realtime_priority)
from .compose import unlocked
from .managed import state_label, transition
from ..core import topics as T

MAX_CATCH_UP = 20              # periods: further behind, the loop resynchronises
SUPERVISE_PERIOD = 0.02        # s: pending lifecycle transitions are carried out this often


@dataclass(frozen=True)
class Program:
    """One executable built on this program: node name, parameters and their loop prefix, the
    backend factory (params, counters) -> Hardware, whether it serves eha/bridge/*, and whether
    it is exclusive (a real drive: refuses to start beside another eha/state publisher and
    disarms when one appears; a simulator is not: run_stack keeps one stack per domain)."""
    name: str
    schema: Schema
    prefix: str
    hardware: Callable
    bridge_services: bool = False
    exclusive: bool = False


def state_publishers(node, topic: str) -> list[str]:
    """Fully qualified names of the nodes publishing ``topic`` (this node's own included)."""
    return [f'{info.node_namespace.rstrip("/")}/{info.node_name}'
            for info in node.get_publishers_info_by_topic(topic)]


class PlantSide(LifecycleNodeMixin):
    """The plant-side node of a Program (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict, program: Program):
        self.transport.__init__(self, program.name)
        LifecycleNodeMixin.__init__(self)
        self.program = program
        self.p = p = declare_and_validate(self, program.schema, params)
        q = program.prefix + '.'
        self.q = q
        self.priority = 0                     # the loop thread's SCHED_FIFO priority in effect
        self.c = Counters()
        self.hw = program.hardware(p, self.c)
        self.Ts = p['plant.sim.Ts']
        self.lockstep = p[q + 'lockstep']
        self.gate = CommandGate(p['plant.drive.omega_max'], p[q + 'max_speed_rate'],
                                p[q + 'command_timeout'], p[q + 'arm_max_command'], self.c)
        self.lock = threading.Lock()          # the gate and the tick counter (short)
        self.hw_lock = threading.Lock()       # the backend (never held with self.lock)
        self.k = 0
        self.go = threading.Event()
        self.go_seq = -1                      # lock-step: the tick command(k) came for
        self.period, self.exec_time = RingStats(), RingStats()
        self.latency = Histogram()            # state(k) published -> command(k) received
        self.state_time = None
        self.cmd_stale = False
        self.conflict = ''
        self.transition_note = ''             # why the last transition failed
        self.retrying = False                 # an autostart configure being retried
        self.want_active = p[q + 'autostart'] == 'active'
        self.want_configured = p[q + 'autostart'] != 'unconfigured'
        self.next_configure = 0.0
        self.thread = None
        self.running = False
        self.done, self.exit_code = False, 0
        self.fatal = ''                       # start-up: a symbol map the PLC refuses
        self.state_msg, self.truth_msg = ActuatorState(), PlantTruth()
        self.state_topic = self.resolve_topic_name(T.STATE.name)
        if program.exclusive:
            self.refuse_if_other_plant(p[q + 'startup_discovery'])

        self.pub_state = self.create_publisher(ActuatorState, T.STATE.name, qos_of(T.STATE))
        self.pub_truth = (self.create_publisher(PlantTruth, T.TRUTH.name, qos_of(T.TRUTH))
                          if self.hw.has_truth else None)
        self.pub_diag = diag.publisher(self)
        self.pub_clock = self.create_publisher(Clock, '/clock', 10) if self.lockstep else None
        self.plant_state = PlantState(self)
        self.plant_state.set(False)
        self.create_subscription(ActuatorCommand, T.COMMAND.name, self.on_command,
                                 qos_of(T.COMMAND))
        if hasattr(self.hw, 'set_load'):
            self.create_subscription(ExternalLoad, T.LOAD_FORCE.name,
                                     lambda m: self.hw.set_load(m.force), qos_of(T.LOAD_FORCE))
        self.create_subscription(ChannelSelect, T.CHANNEL_SELECT.name, self.on_select,
                                 qos_of(T.CHANNEL_SELECT))
        if hasattr(self.hw, 'inject_fault'):
            self.create_service(InjectFault, T.INJECT_FAULT.name, self.on_fault)
        if program.bridge_services:
            self.create_service(SetBool, T.BRIDGE_ARM.name, self.on_arm)
            self.create_service(Trigger, T.BRIDGE_RESET.name, self.on_reset)
        self.start_gate = StartGate(
            self, p[q + 'start_after'], self.state_topic.rsplit('/', 1)[0] + '/',
            p[q + 'start_timeout'],
            own=(self.pub_state,) + ((self.pub_truth,) if self.pub_truth else ()))
        self.command_topic = self.resolve_topic_name(T.COMMAND.name)
        self.sent = self.got = 0              # states published, commands received
        self.pace = Pace(self, p[q + 'start_after']) if self.lockstep else None
        self.create_timer(p[q + 'diagnostics_period'], self.publish_diagnostics)
        self.create_timer(SUPERVISE_PERIOD, self.supervise)
        if self.want_configured:
            self.configure_now()
        self.get_logger().info(
            f'{program.name}: {self.hw.kind} backend, '
            f'{"lock-step" if self.lockstep else "real time"} at {1.0 / self.Ts:.0f} Hz; '
            f'{state_label(self)} (autostart {p[q + "autostart"]})')

    # ---- lifecycle ----
    def configure_now(self):
        """Autostart: configure; a device not reachable yet is retried every retry_period
        (its reason logged once, again only when it changes)."""
        period = self.hw.retry_period
        self.next_configure = time.monotonic() + period
        first_failure = not self.transition_note
        self.retrying = not first_failure
        try:
            self.trigger_configure()
        finally:
            self.retrying = False
        if self.fatal:
            raise UsageError(self.fatal)      # start-up: one line, exit 2
        if state_label(self) == 'inactive':
            self.want_configured = False
            self.activate_when_allowed()      # autostart active: before the first tick
        elif first_failure:
            self.get_logger().info(f'configure: retried every {period:g} s')

    @transition
    def on_configure(self, state):
        try:
            text = self.hw.configure()
        except HardwareError as err:
            return self.refuse('configure', str(err))
        except ParamError as err:             # the symbol map does not match the PLC
            if self.k == 0 and self.want_configured:
                self.fatal = str(err)         # start-up: the one error line, exit 2
                return Ret.FAILURE
            return self.refuse('configure', str(err))
        now = self.now()
        with self.hw_lock:
            r = self.hw.read(now)
            fresh = self.hw.fresh(now)
        with self.lock:                   # activation may follow before the first tick
            self.gate.set_link(self.hw.link_up)
            self.gate.set_data(fresh, r.active_fault)
        self.fill_state(r)                    # state(k): lock-step publishes it first
        self.running = True
        self.thread = threading.Thread(target=self.loop, name='plant_loop', daemon=True)
        # the real-time loop starts once the executor spins (start-up is no overrun)
        self._starter = self.create_timer(0.05, self.start_loop)
        return self.done_transition('configured', text)

    @transition
    def on_activate(self, state):
        if self.conflict:
            return self.refuse('activate', self.conflict)
        with self.lock:
            ok, text = self.gate.arm()
        if not ok:
            return self.refuse('activate', text.removeprefix('arming refused: '))
        self.plant_state.set(True)
        return self.done_transition('active', 'commands applied')

    @transition
    def on_deactivate(self, state):
        with self.lock:               # the gate may have disarmed itself (link, conflict)
            reason = 'requested' if self.gate.armed else self.gate.disarm_reason
            self.gate.disarm(reason)
        self.plant_state.set(False)
        return self.done_transition('inactive', f'zero speed, disarmed ({reason})')

    @transition
    def on_cleanup(self, state):
        self.stop_loop()
        return self.done_transition('unconfigured', 'loop stopped, device released')

    @transition
    def on_shutdown(self, state):
        self.stop_loop()
        return self.done_transition('finalized', 'loop stopped, device released')

    @transition
    def on_error(self, state):
        self.stop_loop()
        self.c.bump('lifecycle_errors')
        self.get_logger().error(f'lifecycle error in {state.label}: zero speed, loop '
                                'stopped, device released (unconfigured)')
        return Ret.SUCCESS

    def refuse(self, what: str, why: str):
        note = f'{what} refused: {why}'
        self.c.bump('transitions_refused')
        if not (self.retrying and note == self.transition_note):
            self.get_logger().warning(note)
        self.transition_note = note
        self.publish_diagnostics()
        return Ret.FAILURE

    def done_transition(self, label: str, text: str):
        self.transition_note = ''
        self.get_logger().info(f'{label}: {text}')
        self.publish_diagnostics()
        return Ret.SUCCESS

    def stop_loop(self, announce: bool = True):
        """Zero speed, loop thread joined (outside every lock), device released;
        ``announce``: INACTIVE on eha/plant_state (a transition; not at process exit, where
        the controller would answer the last states with zeros depending on timing)."""
        with self.lock:
            self.gate.disarm('stopped')
        if announce:
            self.plant_state.set(False)
        self.running = False
        self.go.set()
        if self.thread is not None and self.thread.is_alive() and \
                self.thread is not threading.current_thread():
            self.thread.join(timeout=2.0)
        self.thread = None
        with self.hw_lock:
            self.hw.cleanup()

    @unlocked
    def supervise(self):
        """Carries out what the loop or autostart asked for (executor thread)."""
        label = state_label(self)
        if label == 'active' and not self.gate.armed:
            self.trigger_deactivate()         # the gate disarmed itself: link, conflict
        elif self.want_configured and label == 'unconfigured' and \
                time.monotonic() >= self.next_configure:
            self.configure_now()
        elif label == 'inactive':
            self.activate_when_allowed()

    def activate_when_allowed(self):
        """Autostart active: activate once the arming conditions hold (a simulator at once,
        so a lock-step run is the same from tick 0 whatever the executor's timing)."""
        if self.want_active and not self.gate.arm_refusal():
            self.want_active = False
            self.trigger_activate()

    # ---- inputs (executor thread) ----
    def on_command(self, msg):
        self.got += 1
        if msg.seq == self.k and self.gate.command_seq != self.k and self.state_time:
            self.latency.add(time.perf_counter() - self.state_time)
        with self.lock:
            if not self.lockstep:
                self.gate.set_command(msg.motor_speed_ref, self.now(), msg.seq)
            elif msg.seq == self.k:       # lock-step: tick k applies command(k), no other
                self.gate.set_command(msg.motor_speed_ref, self.now(), msg.seq)
                self.go_seq = msg.seq
                self.go.set()

    def on_select(self, msg):
        if not channel_ok(self, msg, self.c):
            return
        with self.hw_lock:
            self.hw.select(int(msg.channel), tuple(bool(b) for b in msg.drive_enable),
                           tuple(bool(b) for b in msg.valve_open), bool(msg.bypass_open))
        self.c.bump('channel_selects')

    def on_fault(self, req, resp):
        if state_label(self) == 'unconfigured':
            resp.success, resp.message = False, 'not configured'
            return resp
        with self.hw_lock:
            ok, text = self.hw.inject_fault(req.fault, int(req.channel), req.magnitude,
                                            req.duration)
        resp.success, resp.message = bool(ok), f'{text} (tick {self.k})' if ok else text
        self.c.bump('faults_injected' if ok else 'faults_refused')
        self.get_logger().info(f'inject_fault {req.fault}: {text}')
        return resp

    def on_arm(self, req, resp):
        """eha/bridge/arm: an alias of the activate/deactivate transitions."""
        label = state_label(self)
        if req.data:
            if label == 'active':
                ok, text = True, 'already armed'
            elif label != 'inactive':
                ok, text = False, f'arming refused: {label} (configure first)'
            else:
                self.trigger_activate()
                ok = state_label(self) == 'active'
                text = 'armed' if ok else self.transition_note
        elif label == 'active':
            self.trigger_deactivate()
            ok, text = True, 'disarmed (requested)'
        else:
            ok, text = True, 'already disarmed'
        resp.success, resp.message = bool(ok), text
        return resp

    def on_reset(self, req, resp):
        with self.lock:
            ok, text = self.gate.reset()
        resp.success, resp.message = bool(ok), text
        if ok:               # rclpy: one severity per call site
            self.get_logger().info(f'reset: {text}')
        else:
            self.get_logger().warning(f'reset: {text}')
        return resp

    # ---- the loop thread ----
    def now(self) -> float:
        """The gate's clock: wall time, or plant time k*Ts in lock-step."""
        return self.k * self.Ts if self.lockstep else time.monotonic()

    def start_loop(self):
        self._starter.cancel()
        self.destroy_timer(self._starter)
        if self.thread is not None and self.running:
            self.thread.start()

    def loop(self):
        try:
            if self.lockstep:
                self.lockstep_loop()
            else:
                self.realtime_loop()
        except ParamError as err:     # reconnected to a PLC whose symbol table changed
            print(f'{self.program.name}: error: {err}', file=sys.stderr, flush=True)
            with self.lock:
                self.gate.disarm('symbol table changed')
            self.exit_code, self.done, self.running = 2, True, False

    def link_check(self) -> bool:
        """Link down: report once (the gate disarms and latches), retry; True when up."""
        if self.hw.link_up:
            return True
        if self.gate.link_up:
            with self.lock:
                was = self.gate.armed
                self.gate.set_link(False, self.hw.lost or self.hw.last_error)
            self.plant_state.set(False)             # supervise deactivates the node
            self.get_logger().error(
                f'link to the drive lost: {self.gate.link_fault_reason}'
                f'{"; disarmed" if was else ""}; fault latched: reset with eha/bridge/reset '
                'once the link is back')
        if not self.hw.reconnect():
            return False
        with self.lock:
            self.gate.set_link(True)
        self.get_logger().warning('link to the drive restored' + (
            '; link fault stays latched until eha/bridge/reset'
            if self.gate.link_fault else ''))
        return True

    def realtime_loop(self):
        self.priority = realtime_priority(self.p[self.q + 'thread_priority'], self.get_logger())
        while self.running and not self.start_gate.poll():
            time.sleep(0.02)                  # StartGate: a recorder first
        period_ns = int(round(self.Ts * 1e9))
        deadline = time.monotonic_ns()
        last = None
        while self.running:
            if not self.hw.link_up:
                if not self.link_check():
                    self.state_msg.valid = False      # invalid states at the retry rate
                    self.publish_state()
                    continue
                deadline = time.monotonic_ns()
            deadline += period_ns
            delay = deadline - time.monotonic_ns()
            if delay > 0:
                time.sleep(delay * 1e-9)
            elif -delay > period_ns:
                self.c.bump('overruns')
                behind = -delay // period_ns
                if behind > MAX_CATCH_UP:
                    self.c.bump('skipped_deadlines', int(behind))
                    deadline += behind * period_ns
            now = time.monotonic_ns()
            dt = self.Ts if last is None else min((now - last) * 1e-9, 10 * self.Ts)
            if last is not None:
                self.period.add((now - last) * 1e-9)
            last = now
            try:
                with self.callback_lock:      # composed process: one callback at a time
                    self.tick(dt)
            except ParamError:
                raise
            except Exception as err:  # never die silently in the loop thread
                self.c.bump('tick_errors')
                self.get_logger().error(f'tick failed: {err!r}', throttle_duration_sec=1.0)
                time.sleep(0.01)

    def lockstep_loop(self):
        """Step on command(k); re-publish state(k) when it does not come. With
        lockstep_from_activation, state(0) waits for the first activation and for every
        eha/plant_state subscriber to have ACTIVE (acknowledged), so a lock-step run is the
        same from tick 0 whoever activates it and whenever: the controller has seen ACTIVE
        before estimate(0)."""
        if self.p[self.q + 'lockstep_from_activation']:
            if not self.plant_state.active:
                self.get_logger().info('lock-step: state(0) waits for the activation')
            while self.running and not self.plant_state.active:
                time.sleep(0.01)
            if not self.plant_state.acked(self.p[self.q + 'lockstep_timeout']):
                self.get_logger().warning('lock-step: not every eha/plant_state subscriber '
                                          'acknowledged ACTIVE; stepping anyway')
        self.publish_state()
        while self.running:
            if not self.hw.link_up:
                if self.link_check():
                    with self.hw_lock:
                        r = self.hw.read(self.now())
                    self.fill_state(r)
                    self.publish_state()
                continue
            if not self.go.wait(self.p[self.q + 'lockstep_timeout']):
                if self.running:
                    self.c.bump('lockstep_waits')
                    self.publish_state()      # the same state(k) again
                continue
            self.go.clear()
            with self.lock:
                due = self.go_seq == self.k   # a late duplicate of an older command: no
            while due and self.k == 0 and self.running and not self.start_gate.poll():
                time.sleep(0.02)              # StartGate: tick 0 waits for it
            if due:                           # Pace: nor runs ahead of the recorder
                self.pace.wait({self.state_topic: self.sent, self.command_topic: self.got},
                               lambda: self.running)
            if self.running and due:
                with self.callback_lock:
                    self.tick(self.Ts)

    def tick(self, dt: float):
        """Apply command(k) through the gate, advance one Ts, publish state(k+1)."""
        t0 = time.perf_counter()
        with self.lock:
            now = self.now()
            if self.gate.command_seq is not None and self.gate.command_seq != self.k:
                self.c.bump('commands_not_for_previous_tick')
            speed = self.gate.speed_output(now, dt)
            stale = self.gate.stale
        with self.hw_lock:
            self.hw.write(speed)
            up = self.hw.link_up
            if self.lockstep and not up:
                return                        # no step happened: keep state(k)
            r = self.hw.read(now)
            self.fill_state(r)
            fresh = self.hw.fresh(now)
        with self.lock:
            self.k += r.ticks                 # device cycles (ads: a late cycle skips some)
            self.gate.set_data(fresh, r.active_fault)
            armed = self.gate.armed
        self.publish_state()
        self.plant_state.set(armed)
        if stale != self.cmd_stale:
            self.cmd_stale = stale
            if stale and armed:
                self.get_logger().warning(
                    f'no command for {self.gate.timeout * 1e3:.0f} ms: speed reference '
                    'set to zero')
        self.exec_time.add(time.perf_counter() - t0)

    def fill_state(self, r):
        """Fill the preallocated message in place (the generated array setters are slow)."""
        s = self.state_msg
        s.position = r.position
        s.pressure_a, s.pressure_b = r.pressure_a, r.pressure_b
        s.active_channel = r.active_channel
        s.bypass_open = r.bypass_open
        s.valid = r.valid
        speed, current = s.motor_speed, s.motor_current
        valve, enabled, fault = s.valve_open, s.drive_enabled, s.drive_fault
        for i in (0, 1):
            speed[i] = r.motor_speed[i]
            current[i] = r.motor_current[i]
            valve[i] = r.valve_open[i]
            enabled[i] = r.drive_enabled[i]
            fault[i] = r.drive_fault[i]

    def stamp(self):
        if self.lockstep:
            ns = int(round(self.k * self.Ts * 1e9))
            st = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
            publish_counted(self, self.pub_clock, Clock(clock=st), 'clock', self.k)
            return st
        ns = time.time_ns()                   # wall clock, cheaper than Clock.now()
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def publish_state(self):
        s = self.state_msg
        s.header.stamp = stamp = self.stamp()
        s.seq = self.k
        self.state_time = time.perf_counter()
        self.sent += 1
        publish_counted(self, self.pub_state, s, 'state', self.k)
        if self.pub_truth is None or not self.pub_truth.get_subscription_count():
            return                            # nobody listens: skip building the truth
        with self.hw_lock:
            tr = self.hw.truth()
        t = self.truth_msg
        t.header.stamp = stamp
        t.seq = self.k
        t.position, t.velocity = float(tr.position), float(tr.velocity)
        t.pressure_a, t.pressure_b = float(tr.pressure_a), float(tr.pressure_b)
        t.pressure_acc = float(tr.pressure_acc)
        t.friction_force, t.load_force = float(tr.friction_force), float(tr.load_force)
        t.bypass_fraction = float(tr.bypass_fraction)
        t.position_sensor_offset = float(tr.position_sensor_offset)
        speed, current, valve = t.motor_speed, t.motor_current, t.valve_fraction
        for i in (0, 1):
            speed[i] = tr.motor_speed[i]
            current[i] = tr.motor_current[i]
            valve[i] = tr.valve_fraction[i]
        publish_counted(self, self.pub_truth, t, 'truth', self.k)

    # ---- start-up and diagnostics (executor thread) ----
    def refuse_if_other_plant(self, wait: float):
        """Another plant (plant_sim or a bridge) on eha/state: refuse to start."""
        end = time.monotonic() + wait
        while True:
            others = state_publishers(self, self.state_topic)    # ours does not exist yet
            if others:
                names_by = time.monotonic() + 1.0     # discovery may not know the names yet
                while any('_UNKNOWN_' in n for n in others) and time.monotonic() < names_by:
                    time.sleep(0.05)
                    others = state_publishers(self, self.state_topic) or others
                others = [n if '_UNKNOWN_' not in n else 'a node not yet named'
                          for n in others]
                raise UsageError(f'{self.state_topic} is already published by '
                                 f'{", ".join(others)}: refusing to start a second plant '
                                 f'(stop it first)')
            if time.monotonic() >= end:
                return
            time.sleep(0.05)

    def check_conflict(self):
        """A second eha/state publisher appeared: disarm (deactivated by supervise)."""
        names = state_publishers(self, self.state_topic)
        others = names if len(names) > 1 else []                 # ours is one of them
        with self.lock:
            if others and not self.conflict:
                self.conflict = f'{self.state_topic} also published by {", ".join(others)}'
                self.gate.disarm('second plant on eha/state')
                self.c.bump('plant_conflicts')
                self.get_logger().error(f'{self.conflict}: disarmed')
            elif not others:
                self.conflict = ''

    @diag.reader
    def publish_diagnostics(self):
        if self.program.exclusive:
            self.check_conflict()
        now = self.now()
        g = self.gate
        per, ex = self.period.summary(), self.exec_time.summary()
        label = state_label(self)
        values = {'state': label, 'active': g.armed, 'backend': self.hw.kind,
                  'ticks': self.k, 'sim_time_s': self.k * self.Ts,
                  'period_mean_s': per['mean'], 'period_p99_s': per['p99'],
                  'period_max_s': per['max'], 'exec_mean_s': ex['mean'],
                  'exec_p99_s': ex['p99'], 'exec_max_s': ex['max'],
                  'latency_p50_s': self.latency.percentile(50),
                  'latency_p99_s': self.latency.percentile(99),
                  'latency_max_s': self.latency.max, 'answers': self.latency.n,
                  'command_stale': g.stale, 'speed_ref_out': g.out,
                  'link_up': g.link_up, 'data_fresh': g.fresh,
                  'link_fault_latched': g.link_fault, 'link_fault_reason': g.link_fault_reason,
                  'last_error': self.hw.last_error, 'conflict': self.conflict,
                  'transition_refused': self.transition_note}
        values['thread_priority'] = self.priority
        values.update(self.hw.values(now))
        values.update(self.c)
        if self.pace is not None:
            values['recorder_waits'] = self.pace.waits
        if g.link_fault or self.conflict or (label != 'unconfigured' and not g.link_up):
            level = diag.ERROR
            msg = self.conflict or ('link fault latched: ' + g.link_fault_reason
                                    if g.link_fault else 'no link to the drive')
        elif label == 'unconfigured' and self.want_configured:
            level, msg = diag.WARN, self.transition_note or 'unconfigured'
        elif any(self.c.get(k, 0) for k in ('rejected_commands', 'rejected_loads',
                                             'rejected_selects', 'tick_errors')) or \
                (label != 'unconfigured' and not g.fresh) or (g.armed and g.stale):
            level = diag.WARN
            msg = ('data stale' if label != 'unconfigured' and not g.fresh else
                   'commands stale' if g.armed and g.stale else 'inputs rejected')
        else:
            level, msg = diag.OK, label
        diag.publish(self, self.pub_diag, 'loop', values, level, msg)
        self.plant_state.set(g.armed)

    def close(self):
        if self.running or self.thread is not None:
            self.stop_loop(announce=False)


def make_node(params: dict, program: Program, transport=None):
    """The plant side of ``program`` on ``transport`` (None: DDS; common.bind)."""
    return bind(PlantSide, transport)(params, program)
