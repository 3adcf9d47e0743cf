"""controller node: answers each eha/estimate with one eha/command (same seq) from the QFT
position controller (core.controller.PositionController), follows eha/reference, holds its
integrator through channel switches (eha/redundancy), and goes to zero speed when estimates
stop or go stale for more than watchdog_ticks, or in the safe state (core.loop.safe_state: the
estimate reports a position fault or the switch manager is FAILED_SAFE); it recovers from
both without a jump.

A managed (lifecycle) node (lifecycle_msgs services ~/change_state, ~/get_state, ...;
control.autostart: the state it reaches by itself): it answers every estimate in every state,
so a lock-step plant never waits for it, but it controls only while it is ACTIVE and the plant
side says on eha/plant_state that it applies commands (ACTIVE). Otherwise it is inactive: zero
output, no integration; it starts bumplessly from the piston position when both are active.
configure: nothing to connect (parameters are validated at start-up); activate: controls from
the next fresh estimate; deactivate / cleanup / error: zero output."""
from __future__ import annotations

import math
import sys
import time

from eha_msgs.msg import ActuatorCommand, PositionEstimate, PositionReference, RedundancyStatus
from lifecycle_msgs.msg import State
from rclpy.lifecycle import LifecycleNodeMixin, TransitionCallbackReturn as Ret

from ..core.controller.params import SCHEMA
from ..core.controller.position import PositionController
from ..core.controller.tick_sync import TickSync
from ..core.controller.velocity_loop import drive_mismatch
from ..core.estimator.adapt import VERDICTS
from ..core.loop import safe_state as SAFE
from ..core.stats import Counters, LoopStats
from ..core.redundancy.state_machine import FAILED_SAFE
from . import diag
from .managed import autostart, state_label, transition
from .common import (PLANT_STATE_TOPIC, clock_s, declare_and_validate, factory, publish_counted,
                     qos_of, run)
from ..core import topics as T


class Controller(LifecycleNodeMixin):
    """The controller node (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict):
        self.transport.__init__(self, 'controller')
        LifecycleNodeMixin.__init__(self)
        self.p = p = declare_and_validate(self, SCHEMA, params)
        self.Ts = p['plant.sim.Ts']
        self.c = Counters()
        self.ctl = PositionController.from_params(p, counters=self.c)
        self.mismatch = drive_mismatch(p)
        if self.mismatch > p['control.drive_check_tolerance']:
            self.get_logger().warning(
                f'velocity_controller differs from the drive gains in plant.drive by '
                f'{100 * self.mismatch:.1f} %: the design assumed another velocity loop')
        self.watchdog_s = p['control.watchdog_ticks'] * self.Ts
        self.switch_ticks = int(round(p['control.switch_hold'] / self.Ts))
        self.last_good = None          # monotonic time of the last fresh estimate
        self.tripped = False
        self.safe = None                    # why in the safe state (core.loop.safe_state)
        self.manager_state = None           # from eha/redundancy
        self.last_seq = 0
        self.warned_wait = False            # reference_wait_timeouts logged (once)
        self.last_speed = 0.0
        self.answer = None                  # (seq, speed, saturated, stamp) of the last command
        self.active_channel = None
        self.plant_state = None             # eha/plant_state label; None: not heard (active)
        self.idle = False                   # inactive: the next fresh estimate restarts
        self.enabled = False                # own lifecycle state ACTIVE
        self.lockstep = bool(self.get_parameter('use_sim_time').value)
        self.sync = TickSync(self.lockstep, wait=p['control.reference_wait'],
                             counters=self.c)                 # references <-> estimates
        self.loop = LoopStats(self.Ts)
        self.cmd = ActuatorCommand()
        self.pub = self.create_publisher(ActuatorCommand, T.COMMAND.name, qos_of(T.COMMAND))
        self.pub_diag = diag.publisher(self)
        # eha/plant_state first: the executor takes ready subscriptions in this order, so
        # an ACTIVE that arrived (acknowledged) before a state is seen before its estimate
        self.create_subscription(State, PLANT_STATE_TOPIC, self.on_plant_state,
                                 qos_of(T.PLANT_STATE))
        self.create_subscription(PositionEstimate, T.ESTIMATE.name, self.on_estimate,
                                 qos_of(T.ESTIMATE))
        self.create_subscription(PositionReference, T.REFERENCE.name, self.on_reference,
                                 qos_of(T.REFERENCE))
        self.create_subscription(RedundancyStatus, T.REDUNDANCY.name, self.on_redundancy,
                                 qos_of(T.REDUNDANCY))
        # checking at half the watchdog time keeps the reaction within watchdog_ticks
        # without a second 1 kHz callback in the executor
        self.create_timer(max(self.Ts, 0.5 * self.watchdog_s), self.watchdog)
        self.create_timer(p['control.diagnostics_period'], self.publish_diagnostics)
        if self.lockstep:      # wall-clock timer: sim time stands still while we wait
            from rclpy.clock import Clock, ClockType
            self.create_timer(0.01, self.release_held,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f'controller: QFT G (order {len(p["position_controller.den"]) - 1}) and F at '
            f'{1 / self.Ts:.0f} Hz, Tustin{" prewarped" if p["control.prewarp_hz"] else ""}, '
            f'speed clamp {p["plant.drive.omega_max"]:.0f} rad/s; autostart '
            f'{p["control.autostart"]}')
        autostart(self, p['control.autostart'])

    # ---- lifecycle ----
    @transition
    def on_configure(self, state):
        self.get_logger().info('configured: inactive (zero output) until activated')
        return Ret.SUCCESS

    @transition
    def on_activate(self, state):
        self.enabled, self.idle = True, True
        self.last_good = None          # the watchdog starts with the next fresh estimate
        self.get_logger().info(
            'active: control starts from the piston position' +
            ('' if not self.inactive else
             f' once the plant side is active (it is {self.plant_state})'))
        return Ret.SUCCESS

    @transition
    def on_deactivate(self, state):
        self.rest('inactive')
        return Ret.SUCCESS

    @transition
    def on_cleanup(self, state):
        self.rest('unconfigured')
        return Ret.SUCCESS

    @transition
    def on_shutdown(self, state):
        self.enabled = False
        return Ret.SUCCESS

    @transition
    def on_error(self, state):
        self.rest(f'lifecycle error in {state.label}: unconfigured')
        return Ret.SUCCESS

    def rest(self, why: str):
        """Zero output, no integration; the next activation restarts bumplessly."""
        if self.enabled and not self.inactive:
            self.c.bump('inactive_periods')
        self.enabled, self.idle = False, True
        self.get_logger().info(f'{why}: zero output, no integration')

    def on_reference(self, msg):
        """seq 0: apply now. seq k > 0: a tick-locked source (the sweep) -> apply when the
        estimate of tick k is handled, so reference timing does not depend on DDS order."""
        if self.sync.reference(msg.seq, msg.position, self.last_seq):
            self.apply_reference(msg.position)
        self.release_held()

    def apply_reference(self, position):
        clamped = self.c.get('clamped_references', 0)
        if not self.ctl.request(position):
            self.get_logger().warning('reference rejected (not finite); holding the last '
                                      'good one', throttle_duration_sec=1.0)
        elif self.c.get('clamped_references', 0) > clamped:
            self.get_logger().warning(
                f'reference {position * 1e3:.1f} mm is beyond the stroke: clamped to '
                f'+-{self.ctl.ref.limit * 1e3:.1f} mm', throttle_duration_sec=1.0)

    def on_redundancy(self, msg):
        if self.active_channel is not None and msg.active_channel != self.active_channel:
            self.ctl.hold_integrator(self.switch_ticks)
            self.c.bump('channel_switches')
        elif msg.state == 'SWITCHING':
            self.ctl.hold_integrator(self.switch_ticks)
        self.active_channel = msg.active_channel
        self.manager_state = msg.state
        if msg.pressure_sensors_failed and self.ctl.stop_leakage_compensation():
            self.c.bump('compensation_stops')
            self.get_logger().warning('the switch manager blamed the chamber pressure sensors: '
                                      'leakage compensation off (control.leakage_compensation '
                                      'had it on)')

    def on_plant_state(self, msg):
        """The plant side applies commands only while ACTIVE."""
        label = 'active' if msg.id == State.PRIMARY_STATE_ACTIVE else \
            (msg.label or f'state {msg.id}')
        if label == self.plant_state:
            return
        self.plant_state = label
        if label == 'active':
            self.last_good = None      # the watchdog starts with the next fresh estimate
            self.get_logger().info('plant side active: control starts from the piston '
                                   'position' if self.enabled else
                                   'plant side active; the controller is not (lifecycle '
                                   f'{state_label(self)}): zero output')
        else:
            self.idle = True
            if self.enabled:
                self.c.bump('inactive_periods')
            self.get_logger().info(f'plant side {label}: controller inactive (zero output, '
                                   f'no integration) until it is active')

    @property
    def inactive(self) -> bool:
        """Zero output, no integration: not ACTIVE itself, or the plant side is not."""
        return not self.enabled or self.plant_state not in (None, 'active')

    def on_estimate(self, msg):
        """Lock-step with a tick-locked reference source (the sweep): estimate(k) waits for
        reference(k), so the loop (and its results) do not depend on who runs faster."""
        if not self.sync.hold(msg, time.monotonic()):
            self.process_estimate(msg)

    def release_held(self, force=False):
        while (msg := self.sync.pop_ready(time.monotonic(), force)) is not None:
            if self.c.get('reference_wait_timeouts', 0) == 1 and not self.warned_wait:
                self.warned_wait = True
                self.get_logger().warn(
                    f'seq {msg.seq}: no reference of its tick from the sweep after '
                    f'{self.sync.wait:g} s (control.reference_wait): going on with the '
                    f'last one (counted as reference_wait_timeouts; timing not '
                    f'deterministic from here)')
            self.process_estimate(msg)

    def process_estimate(self, msg):
        if self.lockstep and self.answer is not None and self.answer[0] == msg.seq and \
                not msg.stale:
            # a re-sent estimate (the lock-step plant re-sends a state while it waits):
            # the same command again, controller state untouched (deterministic runs)
            self.c.bump('repeated_estimates')
            self.send(*self.answer)
            return
        t0 = time.perf_counter()
        now = clock_s(self)
        self.loop.arrived(now)
        self.last_seq = msg.seq
        for position in self.sync.due(msg.seq):
            self.apply_reference(position)
        fresh = not msg.stale and math.isfinite(msg.position)
        if not fresh:
            self.c.bump('stale_estimates')
        if fresh:
            self.last_good = now
        if self.inactive:
            speed, saturated = 0.0, False
        elif SAFE.controller_holds(msg.consistency, self.manager_state):
            if self.safe is None:
                self.safe = (f'switch manager {self.manager_state}'
                             if self.manager_state == FAILED_SAFE else
                             f'estimate {VERDICTS[msg.consistency]}')
                self.c.bump('safe_state_entries')
                self.get_logger().error(f'seq {msg.seq}: safe state ({self.safe}): '
                                        f'commanding zero motor speed')
            speed, saturated = 0.0, False
        elif fresh:
            if self.idle:
                self.idle = False
                self.ctl.start(msg.position)       # bumpless: zero output, reference ramps
            if self.tripped or self.safe is not None:
                self.get_logger().info(
                    'estimates back: control resumed from the piston position'
                    if self.tripped else f'safe state left ({self.safe} cleared): control '
                    f'resumed from the piston position')
                self.tripped, self.safe = False, None
                self.ctl.start(msg.position)       # bumpless: zero output, reference ramps
            out = self.ctl.update(msg.position, msg.motor_speed, msg.leak_flow)
            speed, saturated = out.speed_ref, out.saturated
        elif self.tripped or self.last_good is None:
            speed, saturated = 0.0, False
        else:
            speed, saturated = self.last_speed, False    # short gap: hold
        self.send(msg.seq, speed, saturated, msg.header.stamp)
        self.answer = (msg.seq, speed, saturated, msg.header.stamp)
        self.loop.executed(time.perf_counter() - t0)

    def send(self, seq, speed, saturated, stamp=None):
        c = self.cmd
        if stamp is not None:
            c.header.stamp = stamp
        c.seq = int(seq)
        c.motor_speed_ref = float(speed)
        c.saturated = bool(saturated)
        publish_counted(self, self.pub, c, 'command', seq)
        self.last_speed = speed

    def watchdog(self):
        """No fresh estimate for watchdog_ticks while controlling: command zero speed
        (repeated), report. Inactive, the output is zero already (and a stack being brought
        up pauses its loop for the transitions)."""
        if self.last_good is None or (self.inactive and not self.tripped):
            return
        if clock_s(self) - self.last_good > self.watchdog_s:
            if not self.tripped:
                self.tripped = True
                self.c.bump('watchdog_trips')
                self.get_logger().warning(
                    f'no fresh estimate for {self.watchdog_s * 1e3:.0f} ms: commanding zero '
                    f'motor speed')
            self.send(0, 0.0, False)      # seq 0: answers no estimate (contract)

    @diag.reader
    def publish_diagnostics(self):
        values = self.loop.values()
        values.update(watchdog_tripped=self.tripped, drive_gain_mismatch=self.mismatch,
                      safe_state=self.safe or '',
                      plant_state=self.plant_state or 'not heard (taken as active)',
                      lifecycle=state_label(self), active=not self.inactive,
                      leakage_compensation=self.ctl.compensating)
        values.update(self.c)
        if self.safe is not None:
            diag.publish(self, self.pub_diag, 'loop', values, diag.ERROR,
                         f'safe state ({self.safe}): zero motor speed')
            return
        warn = self.tripped or self.c.get('rejected_references', 0) > 0 or \
            self.mismatch > self.p['control.drive_check_tolerance']
        diag.publish(self, self.pub_diag, 'loop', values, diag.WARN if warn else diag.OK,
                     'watchdog tripped' if self.tripped else
                     ('inputs rejected or drive mismatch' if warn else
                      self.inactive_text() if self.inactive else 'ok'))

    def inactive_text(self) -> str:
        return (f'inactive: lifecycle {state_label(self)}' if not self.enabled else
                f'inactive: plant side {self.plant_state}')


make_node = factory(Controller)     # make_node(params, transport=None)


def main(argv=None) -> int:
    return run('controller', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
