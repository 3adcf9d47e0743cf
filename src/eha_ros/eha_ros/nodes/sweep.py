"""sweep node: stepped sine (TwinCAT Fr_Test semantics, appendix B.1), chirp or step on
eha/reference, locked to the plant's ticks; records state, estimate, truth and command by seq,
analyses each finished frequency (appendix B.2) and writes out/<run>/ as it goes. The stepped
sine stops after the first frequency below -3 dB (sweep.stop_at_bandwidth). Mode stiffness:
a stepped sine of the external load on eha/sim/load_force with the reference held at the
offset; |F_L|/|x| per frequency against the bound of eq. 4.60 (the applied force is taken from
eha/sim/truth). Mode load_step: a step of the load force at 0.5 s with the reference held; the
batch campaigns' load step figures from eha/sim/truth (position and the position sensor's
Gauss-Markov offset) and eha/estimate. The loop's safe state (switch manager FAILED_SAFE on
eha/redundancy) aborts the sweep (before its start: it never starts): summary incomplete, exit 1.

On each eha/state(k) it publishes the reference of tick k + lead_ticks stamped with that seq;
the controller applies it when it handles tick k + lead_ticks, so the reference timing is exact
in real time and lock-step alike. A frequency is analysed, and the run ends, once every stream
has its ticks (STREAM_WAIT_S: a reliable reader repairing a lost sample). Ctrl-C mid-sweep
keeps every finished frequency and marks the summary incomplete. It starts once a controller
answers and the plant side applies commands (eha/plant_state ACTIVE; not heard: taken as
active) for sweep.start_delay.
"""
from __future__ import annotations

import os
import sys
import time

from eha_msgs.msg import (ActuatorCommand, ActuatorState, ExternalLoad, PlantTruth,
                          PositionEstimate, PositionReference, RedundancyStatus)
from lifecycle_msgs.msg import State

from ..core.config.params import default_config_dir, load
from ..core.io.report import run_dir
from ..core.sweep.params import SCHEMA, build_plan
from ..core.stats import LoopStats
from ..core.sweep.session import from_params, print_table
from . import diag
from .common import declare_and_validate, factory, publish_counted, qos_of, run
from ..core import topics as T

MARGIN_TICKS = 30           # data of a tick is complete this many ticks after its state ...
STREAMS = ('estimate', 'command', 'truth')
# ... and once every other stream still heard (within this wall time) has reached it: a
# reliable reader that lost a sample on its socket holds every later one until the writer's
# heartbeat (Fast DDS: 3 s) repairs the gap, while the state stream goes on (CI: estimates
# missing on over 5 % of a load step's ticks when the sweep ended on the states alone)
STREAM_WAIT_S = 5.0


def model_overlay(p: dict):
    """Closed-loop model from the controller YAML, or None if it cannot be loaded."""
    from ..core.controller.params import TF
    from ..core.config.params import Schema
    from ..core.sweep.model import closed_loop
    path = p['sweep.controller_file'] or os.path.join(default_config_dir(), 'controller.yaml')
    try:
        c = load(Schema('controller', TF), [path])
    except Exception:
        return None, path
    G = (c['position_controller.num'], c['position_controller.den'])
    F = (c['prefilter.num'], c['prefilter.den'])
    return (lambda f: closed_loop(p, G, F, f)), path


class Sweep:
    """The sweep node (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict):
        plan = build_plan(params)          # one-line error for a bad sweep, before ROS starts
        super().__init__('sweep')
        self.p = p = declare_and_validate(self, SCHEMA, params)
        self.plan = plan
        self.lead = p['sweep.lead_ticks']
        model, ctl_file = model_overlay(p)
        self.out = run_dir(p['sweep.out_dir'], p['sweep.run_name'] or None)
        meta = {'mode': p['sweep.mode'], 'amplitude_m': p['sweep.amplitude'],
                'offset_m': p['sweep.offset'], 'source': 'sweep node over DDS',
                'controller_file': ctl_file}
        self.session = from_params(p, plan, self.out, meta, model)
        self.ref_msg = PositionReference()
        self.load_msg = ExternalLoad()
        self.pub_load = None
        if self.session.excite == 'load':
            self.pub_load = self.create_publisher(ExternalLoad, T.LOAD_FORCE.name,
                                                  qos_of(T.LOAD_FORCE))
        self.loop = LoopStats(plan.Ts)
        self.ready_since = None
        self.commands_seen = 0
        self.streams = {name: (-1, None) for name in STREAMS}   # (newest seq, monotonic heard)
        self.end_by = None                 # wall time the end waits for lagging streams until
        self.plant_active = True           # eha/plant_state; not heard: taken as active
        self.done = False
        self.exit_code = 0
        self.pub = self.create_publisher(PositionReference, T.REFERENCE.name,
                                         qos_of(T.REFERENCE))
        self.pub_diag = diag.publisher(self)
        for topic, msg, callback in ((T.PLANT_STATE, State, self.on_plant_state),
                                     (T.STATE, ActuatorState, self.on_state),
                                     (T.ESTIMATE, PositionEstimate, self.on_estimate),
                                     (T.TRUTH, PlantTruth, self.on_truth),
                                     (T.COMMAND, ActuatorCommand, self.on_command),
                                     (T.REDUNDANCY, RedundancyStatus, self.on_redundancy)):
            self.create_subscription(msg, topic.name, callback, qos_of(topic))
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f'sweep: {p["sweep.mode"]}, {plan.n_ticks * plan.Ts:.1f} s planned, writing '
            f'{self.out}/')

    def on_plant_state(self, msg):
        self.plant_active = msg.id == State.PRIMARY_STATE_ACTIVE

    def on_redundancy(self, msg):
        if self.session.check_manager(msg.state, msg.reason):
            self.get_logger().error(f'sweep {self.session.aborted}; reference back to the '
                                    f'offset')
            self.end()

    def heard(self, stream: str, seq: int):
        self.streams[stream] = (max(self.streams[stream][0], seq), time.monotonic())

    @property
    def newest(self) -> int:
        """The newest seq of an estimate, command or truth."""
        return max(seq for seq, _ in self.streams.values())

    def complete_through(self, k: int) -> int:
        """The tick up to which every stream's data is in, at state k (module comment)."""
        now = time.monotonic()
        return min([k - MARGIN_TICKS] + [seq for seq, at in self.streams.values()
                                         if at is not None and now - at < STREAM_WAIT_S])

    def on_command(self, msg):
        self.commands_seen += 1
        self.heard('command', msg.seq)
        self.session.record('command', msg.seq, msg.motor_speed_ref)

    def on_truth(self, msg):
        self.heard('truth', msg.seq)
        self.session.record('truth', msg.seq, msg.position)
        self.session.record('load', msg.seq, msg.load_force)
        self.session.record('sensor_offset', msg.seq, msg.position_sensor_offset)

    def on_estimate(self, msg):
        self.heard('estimate', msg.seq)
        self.session.record('estimate', msg.seq, msg.position)
        if self.session.check_error(msg.seq, msg.position):
            self.get_logger().error(f'sweep {self.session.aborted}; reference back to the '
                                    f'offset')
            self.end()

    def on_state(self, msg):
        self.loop.timed(self.handle_state, msg)

    def handle_state(self, msg):
        s = self.session
        k = msg.seq
        if s.seq0 is None:
            if s.aborted:
                return                         # the safe state came first: never started
            if self.commands_seen == 0 or not self.plant_active:
                self.ready_since = None
                return                         # wait for an active loop
            now = time.monotonic()
            self.ready_since = self.ready_since or now
            if now - self.ready_since < self.p['sweep.start_delay']:
                self.send(k + self.lead, s.reference_for(k + self.lead))
                return
            # after every tick already seen on any stream: a state handled late (its queue
            # behind the others') must not start the plan on ticks whose estimates, commands
            # or truth were already handled, and dropped, before the start (CI: 610 ticks)
            start = max(k, self.newest) + self.lead
            s.start(start)
            self.get_logger().info(f'sweep started at tick {start}')
        s.record('measured', k, msg.position)
        s.record('motor_speed_0', k, msg.motor_speed[0])
        s.record('motor_speed_1', k, msg.motor_speed[1])
        s.record('active_channel', k, msg.active_channel)
        s.record('reference', k, s.reference_for(k))
        self.send(k + self.lead, s.reference_for(k + self.lead), s.load_for(k + self.lead))
        done = self.complete_through(k)
        for point in s.progress(done):
            self.get_logger().info(s.describe(point))
        if not s.finished and k - s.seq0 >= s.n_run + MARGIN_TICKS:
            self.end_by = self.end_by or time.monotonic() + STREAM_WAIT_S
            if done - s.seq0 >= s.n_run or time.monotonic() >= self.end_by:
                self.warn_lagging(s.seq0 + s.n_run - 1)
                self.end()

    def warn_lagging(self, last: int):
        """One line per stream that has not reached the run's last tick (the analysis then
        says what the missing ticks cost)."""
        for name, (seq, at) in self.streams.items():
            if at is not None and seq < last:
                self.get_logger().warn(f'sweep: {name} reached tick {seq}, the run ends at tick '
                                       f'{last}: ended without its last {last - seq} ticks')

    def send(self, seq, position, load=0.0):
        m = self.ref_msg
        m.seq = int(seq)
        m.position = float(position)
        publish_counted(self, self.pub, m, 'reference', seq)
        if self.pub_load is not None:
            self.load_msg.force = float(load)
            publish_counted(self, self.pub_load, self.load_msg, 'load', seq)

    def end(self, reason=None):
        """Finish the report; reference back to the offset; exit if asked to."""
        if self.session.finished:
            return
        self.send(0, self.session.position)
        if self.session.seq0 is None:          # stopped before the start: nothing measured
            summary = self.session.finish(complete=False, reason=reason or self.session.aborted)
        else:
            summary = self.session.finish(reason=reason)
        print_table(summary, lambda line: self.get_logger().info(line))
        self.get_logger().info(f'report: {self.out}/ ({", ".join(self.session.files)})')
        if not summary['complete']:
            self.get_logger().error(f'sweep incomplete: {summary["status"]}')   # the last line
            self.exit_code = 1
        if self.p['sweep.exit_when_done']:
            self.done = True

    def publish_diagnostics(self):
        s = self.session
        values = {'started': s.seq0 is not None, 'points': len(s.points),
                  'planned_points': len(getattr(self.plan, 'segments', [])),
                  'finished': s.finished, 'status': s.aborted or 'running',
                  'out_dir': self.out, **self.loop.values()}
        diag.publish(self, self.pub_diag, 'sweep', values,
                     diag.ERROR if s.aborted else diag.OK, s.aborted or 'ok')

    def close(self):
        """Ctrl-C: keep every finished frequency, mark the summary incomplete."""
        if self.session.seq0 is not None and not self.session.finished:
            self.end(reason='interrupted')
        elif not self.session.finished:
            self.session.finish(complete=False, reason='interrupted before the start')


make_node = factory(Sweep)     # make_node(params, transport=None)


def main(argv=None) -> int:
    return run('sweep', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
