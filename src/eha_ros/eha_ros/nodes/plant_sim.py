"""plant_sim node: the nonlinear EHA model (core.plant.EhaPlant) on the ROS graph at 1 kHz.

Publishes eha/state and eha/sim/truth each tick, applies the latest eha/command at the next
tick, takes eha/sim/load_force and eha/channel_select, serves eha/inject_fault and reports
on /diagnostics; eha/plant_state (latched) says ACTIVE: commands are applied. Real time: a
loop thread with absolute deadlines (overruns counted).
Lock-step (sim_node.lockstep): publishes /clock and steps only when command(k) arrived.
"""
from __future__ import annotations

import math
import sys
import threading
import time

from ..core.plant import EhaPlant
from ..core.plant_sim_params import SCHEMA
from ..core.stats import Counters, Histogram, RingStats
from . import diag
from .common import (PlantState, StartGate, channel_ok, declare_and_validate, latched_qos,
                     node_base, publish_counted, run, stream_qos)


class CommandGate:
    """Validate incoming commands and loads: reject non-finite, saturate out-of-range, hold last good."""

    def __init__(self, max_speed: float, max_load: float, counters: Counters):
        self.max_speed = max_speed
        self.max_load = max_load
        self.c = counters
        self.speed_ref = 0.0
        self.cmd_seq = None
        self.cmd_time = None
        self.load = 0.0

    def command(self, value: float, seq: int, now: float):
        if not math.isfinite(value):
            self.c.bump('rejected_commands')
            return
        if abs(value) > self.max_speed:
            self.c.bump('saturated_commands')
            value = math.copysign(self.max_speed, value)
        self.speed_ref, self.cmd_seq, self.cmd_time = value, seq, now

    def load_force(self, value: float):
        if not math.isfinite(value):
            self.c.bump('rejected_loads')
            return
        if abs(value) > self.max_load:
            self.c.bump('saturated_loads')
            value = math.copysign(self.max_load, value)
        self.load = value


def make_node(params: dict):
    Node = node_base()
    from eha_msgs.msg import (ActuatorCommand, ActuatorState, ChannelSelect, ExternalLoad,
                              PlantTruth)
    from eha_msgs.srv import InjectFault
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock

    class PlantSim(Node):
        def __init__(self):
            super().__init__('plant_sim')
            self.p = declare_and_validate(self, SCHEMA, params)
            self.plant = EhaPlant(self.p, seed=self.p['sim_node.seed'])
            self.plant.reset(position=self.p['sim_node.initial_position'])
            self.Ts = self.plant.Ts
            self.lock = threading.Lock()
            self.k = 0
            self.c = Counters()
            self.gate = CommandGate(self.p['sim_node.max_abs_speed_ref'],
                                    self.p['sim_node.max_abs_load'], self.c)
            self.period = RingStats()
            self.exec_time = RingStats()
            self.latency = Histogram()        # state(k) published -> command(k) received
            self.state_time = None            # perf_counter when state(self.k) went out
            self.lockstep = self.p['sim_node.lockstep']
            self.cmd_stale = False
            self.state_msg, self.truth_msg = ActuatorState(), PlantTruth()

            qos = stream_qos()
            self.pub_state = self.create_publisher(ActuatorState, 'eha/state', qos)
            self.pub_truth = self.create_publisher(PlantTruth, 'eha/sim/truth', qos)
            self.pub_diag = diag.publisher(self)
            self.pub_clock = self.create_publisher(Clock, '/clock', 10) if self.lockstep else None
            self.create_subscription(ActuatorCommand, 'eha/command', self.on_command, qos)
            self.create_subscription(ExternalLoad, 'eha/sim/load_force', self.on_load, qos)
            self.create_subscription(ChannelSelect, 'eha/channel_select', self.on_select,
                                     latched_qos())
            self.create_service(InjectFault, 'eha/inject_fault', self.on_fault)
            self.create_timer(self.p['sim_node.diagnostics_period'], self.publish_diagnostics)
            PlantState(self).set(True)            # the simulation applies every command

            self.running = True
            self.publish(self.now_stamp())
            self.start_gate = StartGate(
                self, self.p['sim_node.start_after'],
                self.pub_state.topic_name.rsplit('/', 1)[0] + '/',
                self.p['sim_node.start_timeout'], own=(self.pub_state, self.pub_truth))
            if self.lockstep:
                self.last_publish = time.monotonic()
                self.create_timer(0.01, self.lockstep_watchdog)
                if not self.start_gate.open:
                    self.start_timer = self.create_timer(0.02, self.poll_start)
                self.thread = None
            else:
                # start the loop once the executor spins (start-up is not counted as overruns)
                # and the start gate is open (a recorder has every stream from tick 1)
                self.thread = threading.Thread(target=self.realtime_loop, name='plant_loop',
                                               daemon=True)
                self._starter = self.create_timer(0.05, self.start_loop)
            self.get_logger().info(
                f'plant_sim: {"lock-step" if self.lockstep else "real time"} at '
                f'{1.0 / self.Ts:.0f} Hz, {self.plant_summary()}')

        def plant_summary(self) -> str:
            return (f'A_p={self.p["plant.cylinder.A_p"]:.4g} m^2, '
                    f'D_p={self.p["plant.pump.D_p"]:.4g} m^3/rad, '
                    f'substeps={self.p["plant.sim.substeps"]}')

        # ---- inputs (executor thread) ----
        def on_command(self, msg):
            if msg.seq == self.k and self.gate.cmd_seq != self.k and self.state_time:
                self.latency.add(time.perf_counter() - self.state_time)
            self.gate.command(msg.motor_speed_ref, msg.seq, time.monotonic())
            if self.lockstep and msg.seq == self.k and self.start_gate.open:
                self.tick()

        def poll_start(self):
            """Lock-step, tick 0 held (StartGate): polled once command(0) is in (the loop's
            topics all exist then); steps when it opens."""
            if self.gate.cmd_seq == 0 and self.start_gate.poll():
                self.start_timer.cancel()
                self.tick()

        def on_load(self, msg):
            self.gate.load_force(msg.force)

        def on_select(self, msg):
            if not channel_ok(self, msg, self.c):
                return
            with self.lock:
                self.plant.select(int(msg.channel), tuple(bool(b) for b in msg.drive_enable),
                                  tuple(bool(b) for b in msg.valve_open), bool(msg.bypass_open))
            self.c.bump('channel_selects')

        def on_fault(self, req, resp):
            with self.lock:
                ok, text = self.plant.inject_fault(req.fault, int(req.channel), req.magnitude,
                                                   req.duration)
                tick = self.k
            resp.success, resp.message = bool(ok), f'{text} (tick {tick})' if ok else text
            self.c.bump('faults_injected' if ok else 'faults_refused')
            self.get_logger().info(f'inject_fault {req.fault}: {text}')
            return resp

        # ---- stepping ----
        def speed_reference(self) -> float:
            """Latest good command; zero (and reported) when commands went stale."""
            t = self.gate.cmd_time
            stale = t is not None and not self.lockstep and \
                time.monotonic() - t > self.p['sim_node.command_timeout']
            if stale != self.cmd_stale:
                self.cmd_stale = stale
                if stale:
                    self.c.bump('command_timeouts')
                    self.get_logger().warning('no command for '
                                              f'{self.p["sim_node.command_timeout"]*1e3:.0f} ms: '
                                              'speed reference set to zero')
            return 0.0 if stale else self.gate.speed_ref

        def tick(self):
            """Apply command(k), advance one Ts, publish state(k+1)."""
            t0 = time.perf_counter()
            if self.gate.cmd_seq is not None and self.gate.cmd_seq != self.k:
                self.c.bump('commands_not_for_previous_tick')
            with self.lock:
                self.plant.step(self.speed_reference(), self.gate.load)
                self.k += 1
            stamp = self.now_stamp()
            self.publish(stamp)
            self.exec_time.add(time.perf_counter() - t0)
            if self.lockstep:
                self.last_publish = time.monotonic()

        def now_stamp(self):
            if self.lockstep:
                ns = int(round(self.k * self.Ts * 1e9))
                stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
                self.pub_clock.publish(Clock(clock=stamp))
                return stamp
            ns = time.time_ns()                   # wall clock, cheaper than Clock.now()
            return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

        def publish(self, stamp):
            """Fill the preallocated messages in place (the generated array setters are slow)."""
            with self.lock:
                m, tr = self.plant.measure(), self.plant.truth()
            s = self.state_msg
            s.header.stamp = stamp
            s.seq = self.k
            s.position = float(m.position)
            s.pressure_a, s.pressure_b = float(m.pressure_a), float(m.pressure_b)
            s.active_channel = int(m.active_channel)
            s.bypass_open = float(tr.bypass_fraction) > 0.5
            s.valid = bool(m.valid)
            speed, current = s.motor_speed, s.motor_current
            valve, enabled, fault = s.valve_open, s.drive_enabled, s.drive_fault
            for i in (0, 1):
                speed[i] = m.motor_speed[i]
                current[i] = m.motor_current[i]
                valve[i] = bool(m.valve_open[i] > 0.5)      # fractions -> open/closed
                enabled[i] = bool(m.drive_enabled[i])
                fault[i] = bool(m.drive_fault[i])
            self.state_time = time.perf_counter()
            publish_counted(self, self.pub_state, s, f'state {self.k}')
            if not self.pub_truth.get_subscription_count():
                return                            # nobody listens: skip building the truth
            t = self.truth_msg
            t.header.stamp = stamp
            t.seq = self.k
            t.position, t.velocity = float(tr.position), float(tr.velocity)
            t.pressure_a, t.pressure_b = float(tr.pressure_a), float(tr.pressure_b)
            t.pressure_acc = float(tr.pressure_acc)
            t.friction_force, t.load_force = float(tr.friction_force), float(tr.load_force)
            t.bypass_fraction = float(tr.bypass_fraction)
            speed, current, valve = t.motor_speed, t.motor_current, t.valve_fraction
            for i in (0, 1):
                speed[i] = tr.motor_speed[i]
                current[i] = tr.motor_current[i]
                valve[i] = tr.valve_fraction[i]
            self.pub_truth.publish(t)

        def start_loop(self):
            if not self.start_gate.poll():
                return
            self._starter.cancel()
            self.destroy_timer(self._starter)
            self.thread.start()

        def realtime_loop(self):
            """Absolute deadlines at Ts: plant time stays locked to wall time.

            A tick that starts more than one period late counts as an overrun; the loop then
            catches up (ticks back to back) unless it is more than MAX_CATCH_UP periods
            behind, in which case it resynchronises and counts the skipped deadlines.
            """
            MAX_CATCH_UP = 20
            period_ns = int(round(self.Ts * 1e9))
            deadline = time.monotonic_ns()
            last = None
            while self.running:
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
                if last is not None:
                    self.period.add((now - last) * 1e-9)
                last = now
                try:
                    with self.callback_lock:      # composed process: one callback at a time
                        self.tick()
                except Exception as err:  # never die silently in the loop thread
                    self.c.bump('tick_errors')
                    self.get_logger().error(f'tick failed: {err!r}')
                    time.sleep(0.01)

        def lockstep_watchdog(self):
            """No command(k) for lockstep_timeout: publish state(k) again (controller may be late)."""
            if time.monotonic() - self.last_publish > self.p['sim_node.lockstep_timeout']:
                self.c.bump('lockstep_waits')
                self.publish(self.now_stamp())
                self.last_publish = time.monotonic()

        @diag.reader
        def publish_diagnostics(self):
            per, ex = self.period.summary(), self.exec_time.summary()
            values = {'ticks': self.k, 'sim_time_s': self.k * self.Ts,
                      'period_mean_s': per['mean'], 'period_p99_s': per['p99'],
                      'period_max_s': per['max'], 'exec_mean_s': ex['mean'],
                      'exec_p99_s': ex['p99'], 'exec_max_s': ex['max'],
                      'command_stale': self.cmd_stale,
                      'latency_p50_s': self.latency.percentile(50),
                      'latency_p99_s': self.latency.percentile(99),
                      'latency_max_s': self.latency.max, 'answers': self.latency.n}
            values.update(self.c)
            bad = any(self.c.get(k, 0) for k in ('rejected_commands', 'rejected_loads',
                                                  'rejected_selects', 'tick_errors'))
            level = diag.WARN if bad or self.cmd_stale else diag.OK
            msg = 'ok' if level == diag.OK else 'inputs rejected or commands stale'
            diag.publish(self, self.pub_diag, 'loop', values, level, msg)

        def close(self):
            self.running = False
            if self.thread is not None and self.thread.is_alive():
                self.thread.join(timeout=1.0)

    return PlantSim()


def main(argv=None) -> int:
    return run('plant_sim', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
