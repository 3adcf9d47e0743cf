"""experiment node: one identification experiment of thesis section 3.6 (issue 43) against the
running loop, around core.ident.run.ExperimentRun and the plans of core.ident.experiments.

Closed-loop kinds (friction, leakage, validation): on each eha/state(k) it publishes the
reference (and, where the plan has one, the load on eha/sim/load_force) of tick
k + experiment.lead_ticks stamped with that seq, as the sweep node does; the controller runs.
Kind drive: no controller runs (run_stack --no-controller); the node takes its place and
answers each eha/estimate(k) with eha/command(k), the plan's motor-speed sine plus a slow
proportional loop on the measured position of state(k): the loop's order state(k) ->
estimate(k) -> command(k) is kept, so in lock-step the plant steps on its commands and the
estimator (the sensor-fault half of the safe state) stays in step with the plant.

At the plan's start it publishes eha/experiment (std_msgs/String, latched): one JSON message
{"experiment", "version", "plant_side", "params"} (core.ident.experiments.Plan.message), which
the recorder keeps with the run. It stops early, commanding zero speed or the reference 0 and no
load, on the loop's safe state (switch manager FAILED_SAFE on eha/redundancy, an estimate
calling for it), the measured position beyond the stroke margin, a lost track, or the plant
side no longer active; the last log line says why and the exit code is 1. Done: exit 0.
"""
from __future__ import annotations

import json
import sys
import time

from eha_msgs.msg import (ActuatorCommand, ActuatorState, ExternalLoad, PositionEstimate,
                          PositionReference, RedundancyStatus)
from builtin_interfaces.msg import Time
from lifecycle_msgs.msg import State
from std_msgs.msg import String

from ..core.ident.experiments import Limits, build
from ..core.ident.params import SCHEMA
from ..core.ident.run import ExperimentRun
from ..core.stats import LoopStats
from . import diag
from .common import (PLANT_STATE_TOPIC, StartGate, declare_and_validate, factory,
                     publish_counted, qos_of, run)
from ..core import topics as T

TOPIC = T.EXPERIMENT.name
START_TIMEOUT = 30.0        # [s] experiment.start_after: start anyway (warned) after this


class Experiment:
    """The experiment node (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict):
        plan = build(params)              # one-line error for a plan beyond the limits
        super().__init__('experiment')
        self.p = p = declare_and_validate(self, SCHEMA, params)
        self.plan = plan
        self.run = ExperimentRun(plan, Limits.from_params(p), p['experiment.abort_error'],
                                 p['experiment.abort_ticks'])
        self.drive = plan.speed is not None
        self.lead = p['experiment.lead_ticks']
        self.loop = LoopStats(plan.Ts)
        self.ready_since = None
        self.measured = (-1, 0.0)          # (seq, position) of the last state
        self.stamped = (0, 0)              # (seq, header stamp in ns) of the last state
        self.commands_seen = 0
        self.plant_active = True           # eha/plant_state; not heard: taken as active
        self.done = False
        self.exit_code = 0
        self.pub_info = self.create_publisher(String, TOPIC, qos_of(T.EXPERIMENT))
        self.pub_cmd = self.pub_ref = self.pub_load = None
        if self.drive:
            self.cmd = ActuatorCommand()
            self.pub_cmd = self.create_publisher(ActuatorCommand, T.COMMAND.name, qos_of(T.COMMAND))
        else:
            self.ref = PositionReference()
            self.pub_ref = self.create_publisher(PositionReference, T.REFERENCE.name,
                                                 qos_of(T.REFERENCE))
            self.create_subscription(ActuatorCommand, T.COMMAND.name, self.on_command,
                                     qos_of(T.COMMAND))
        if plan.load is not None:
            self.load = ExternalLoad()
            self.pub_load = self.create_publisher(ExternalLoad, T.LOAD_FORCE.name,
                                                  qos_of(T.LOAD_FORCE))
        self.pub_diag = diag.publisher(self)
        self.create_subscription(State, PLANT_STATE_TOPIC, self.on_plant_state,
                                 qos_of(T.PLANT_STATE))
        self.create_subscription(ActuatorState, T.STATE.name, self.on_state, qos_of(T.STATE))
        self.create_subscription(PositionEstimate, T.ESTIMATE.name, self.on_estimate,
                                 qos_of(T.ESTIMATE))
        self.create_subscription(RedundancyStatus, T.REDUNDANCY.name, self.on_redundancy,
                                 qos_of(T.REDUNDANCY))
        own = [x for x in (self.pub_info, self.pub_cmd, self.pub_ref, self.pub_load) if x]
        self.gate = StartGate(self, p['experiment.start_after'],
                              self.resolve_topic_name(T.STATE.name).rsplit('/', 1)[0] + '/',
                              START_TIMEOUT, own=own)
        self.create_timer(p['experiment.diagnostics_period'], self.publish_diagnostics)
        self.get_logger().info(f'experiment {plan.kind}: {plan.summary}; '
                               f'{plan.duration_s:.1f} s planned')

    # ---- the loop's state
    def on_plant_state(self, msg):
        self.plant_active = msg.id == State.PRIMARY_STATE_ACTIVE
        self.stopped(self.run.on_plant_active(self.plant_active))

    def on_redundancy(self, msg):
        self.stopped(self.run.on_manager(msg.state, msg.reason))

    def on_estimate(self, msg):
        r = self.run
        if self.drive:                     # answer estimate(k) first: the plant waits for it
            seq, x = self.measured
            self.send_command(msg, r.command_for(msg.seq, x if seq == msg.seq else msg.position))
        self.stopped(r.on_estimate(msg.seq, msg.position, msg.consistency))

    def on_command(self, msg):
        self.commands_seen += 1

    def on_state(self, msg):
        self.loop.timed(self.handle_state, msg)

    def handle_state(self, msg):
        k, r = msg.seq, self.run
        self.measured = (k, msg.position)
        self.stamped = (k, msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
        self.stopped(r.on_state(k, msg.position))
        if r.seq0 is None and not r.stopped and self.ready(k):
            r.start(k + self.lead)
            info = r.plan.message(self.p['experiment.plant_side'], r.seq0)
            self.pub_info.publish(String(data=json.dumps(info)))
            self.get_logger().info(f'experiment {r.plan.kind} started at tick {r.seq0}')
        if not self.drive:
            self.send(k + self.lead)
        part = r.new_part(k)
        if part is not None:
            self.get_logger().info(r.describe(part))
        if r.done(k) and not self.done:
            self.finish()

    def ready(self, k: int) -> bool:
        """The loop runs (a controller answers, unless we are the one) with the plant side
        active, for experiment.start_delay, and the recorder has matched every stream."""
        if not self.plant_active or not (self.drive or self.commands_seen) or \
                not self.gate.poll():
            self.ready_since = None
            return False
        now = time.monotonic()
        self.ready_since = self.ready_since or now
        return now - self.ready_since >= self.p['experiment.start_delay']

    # ---- outputs
    def send_command(self, estimate, speed: float):
        m = self.cmd
        m.header.stamp = estimate.header.stamp
        m.seq = estimate.seq
        m.motor_speed_ref = float(speed)
        m.saturated = abs(speed) >= self.run.limits.omega_max
        publish_counted(self, self.pub_cmd, m, 'command', estimate.seq)

    def send(self, seq: int):
        """Reference (and load) of plant tick ``seq``: its seq, and the time it is meant for in
        the header (the last state's stamp + the ticks between, Ts each); seq 0: untimed (the
        controller applies it at once and stops waiting for tick-locked references)."""
        r = self.run
        k, ns = self.stamped
        ns += int(round(max(0, seq - k) * self.plan.Ts * 1e9))
        stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        self.ref.header.stamp, self.ref.seq = stamp, int(seq)
        self.ref.position = r.reference_for(seq)
        publish_counted(self, self.pub_ref, self.ref, 'reference', seq)
        if self.pub_load is not None:
            self.load.header.stamp, self.load.seq = stamp, int(seq)
            self.load.force = r.load_for(seq)
            publish_counted(self, self.pub_load, self.load, 'load', seq)

    def stopped(self, why: str):
        """A guard of the run stopped it: zero load, reference 0, say why, exit 1."""
        if not why or self.done:
            return
        self.get_logger().error(f'experiment {self.plan.kind} stopped: {why}')
        self.exit_code = 1
        self.publish_diagnostics()             # ERROR with the reason, before the node ends
        self.end()

    def finish(self):
        self.get_logger().info(f'experiment {self.plan.kind}: done ({self.plan.n_ticks} ticks)')
        self.end()

    def end(self):
        if self.pub_ref is not None:
            self.send(0)                      # untimed: the reference 0 (and no load) at once
        if self.p['experiment.exit_when_done']:
            self.done = True

    def publish_diagnostics(self):
        r = self.run
        values = {'kind': self.plan.kind, 'started': r.seq0 is not None,
                  'planned_s': self.plan.duration_s, 'part': r.part + 1,
                  'parts': len(self.plan.parts), 'finished': self.done,
                  'stopped': r.stopped or '', **self.loop.values()}
        diag.publish(self, self.pub_diag, 'experiment', values,
                     diag.ERROR if r.stopped else diag.OK, r.stopped or 'ok')


make_node = factory(Experiment)     # make_node(params, transport=None)


def main(argv=None) -> int:
    return run('experiment', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
