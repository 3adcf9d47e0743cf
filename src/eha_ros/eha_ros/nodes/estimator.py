"""estimator node: Kalman position estimate (core.estimator.Estimator) on the ROS graph.

Subscribes eha/state, publishes one eha/estimate per state with the same seq and header stamp
(position, velocity, p_D, variance, innovation, NIS, sensor fault). The filter uses the active
channel's motor speed. A NaN or out-of-range measurement gives a predict-only estimate with
update_skipped = true, and so does a sample held back as a suspected sensor jump's; each is
counted and reported on /diagnostics. A 1 ms timer watches the stream: no state for more
than estimator.node.stale_time (5 ms) -> predict-only estimates marked stale = true, one per
timer tick, with the seq the missing states would have had.
Subscribes eha/redundancy: once the switch manager blames the chamber pressure sensors
(pressure_sensors_failed) the filter updates on the position alone from then on.
"""
from __future__ import annotations

import sys
import time

from eha_msgs.msg import ActuatorState, PositionEstimate, RedundancyStatus

from ..core.estimator.estimator import Estimator
from ..core.estimator.fault_detector import NAMES
from ..core.estimator.params import SCHEMA
from ..core.stats import Counters, LoopStats
from . import diag
from .common import clock_s, declare_and_validate, factory, publish_counted, qos_of, run
from ..core import topics as T

STATE_QUEUE_DEPTH = 20      # states (20 ms at 1 kHz): rides out short stalls without a long backlog


class EstimatorNode:
    """The estimator node (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict):
        super().__init__('estimator')
        self.p = declare_and_validate(self, SCHEMA, params)
        self.est = Estimator(self.p)
        self.stale_time = self.p['estimator.node.stale_time']
        self.c = Counters()
        self.loop = LoopStats(self.est.Ts)
        self.last_arrival = None
        self.last_seq = None
        self.verdict = 0                  # core.estimator.adapt verdict last logged
        self.suspect_logged = 0           # the detector's suspect samples last logged
        self.stale = False
        self.stale_seq = 0
        self.msg = PositionEstimate()
        self.pub = self.create_publisher(PositionEstimate, T.ESTIMATE.name, qos_of(T.ESTIMATE))
        # a deeper input queue: after a scheduling stall the queued states are still
        # answered (their provisional stale predictions are replaced), not dropped
        self.pub_diag = diag.publisher(self)
        self.create_subscription(ActuatorState, T.STATE.name, self.on_state,
                                 qos_of(T.STATE, depth=STATE_QUEUE_DEPTH))
        self.create_subscription(RedundancyStatus, T.REDUNDANCY.name, self.on_redundancy,
                                 qos_of(T.REDUNDANCY))
        self.create_timer(self.p['estimator.node.timer_period'], self.on_timer)
        self.create_timer(self.p['estimator.node.diagnostics_period'],
                          self.publish_diagnostics)
        self.get_logger().info(
            f'estimator: filter={self.p["estimator.filter"]}, '
            f'measurements={self.p["estimator.measurements"]}, '
            f'stale after {self.stale_time * 1e3:.1f} ms')

    def on_state(self, msg):
        if self.last_seq is not None and msg.seq == self.last_seq == self.msg.seq and \
                not self.msg.stale:
            # a re-sent state (lock-step plant waiting for its command): the same answer
            # again, filter untouched, so lock-step runs stay deterministic
            self.c.bump('repeated_states')
            publish_counted(self, self.pub, self.msg, 'estimate', msg.seq)
            return
        t0 = time.perf_counter()
        now = clock_s(self)
        self.loop.arrived(now)
        self.last_arrival = now
        ticks = 1
        if self.last_seq is not None:
            if msg.seq > self.last_seq + 1:
                self.c.bump('lost_states', int(msg.seq - self.last_seq - 1))
                ticks = int(msg.seq - self.last_seq)
            elif msg.seq <= self.last_seq:
                self.c.bump('out_of_order_states')
        if self.stale:
            self.stale = False
            self.get_logger().info(f'states back at seq {msg.seq}',
                                   throttle_duration_sec=1.0)
        self.last_seq = msg.seq
        r = self.est.update(msg.position, msg.motor_speed, msg.pressure_a, msg.pressure_b,
                            msg.active_channel, ticks, msg.valid, msg.motor_current)
        self.c.bump('estimates')
        if r.consistency != self.verdict:      # one log line per verdict change (issue 15)
            self.on_verdict(r.consistency, msg.seq)
        if r.rejected and msg.valid:     # invalid states: counted, not warned (repeats)
            self.c.bump('rejected_states')
            self.get_logger().warning(
                f'state seq {msg.seq}: rejected {r.rejected} '
                f'({"predict only" if r.update_skipped else "partial update"})',
                throttle_duration_sec=1.0)
        self.publish(r, msg.header.stamp, msg.seq, False)
        self.loop.executed(time.perf_counter() - t0)

    def on_redundancy(self, msg):
        if msg.pressure_sensors_failed and self.est.stop_pressures():
            self.c.bump('pressure_stops')
            self.get_logger().warning('the switch manager blamed the chamber pressure sensors: '
                                      'the filter updates on the position alone from now on')

    def on_verdict(self, verdict: int, seq: int):
        from ..core.estimator import adapt
        self.verdict = verdict
        name = adapt.VERDICTS[verdict]
        if adapt.safe_state(verdict):
            self.get_logger().error(f'seq {seq}: {name}: the position sensor is faulty '
                                    f'(safe state required: core.loop.safe_state)')
        elif adapt.alarm(verdict):
            self.get_logger().error(f'seq {seq}: {name}: filter and position sensor disagree '
                                    f'beyond the sensor band (the estimate falls back on '
                                    f'the sensor)')
        elif verdict == adapt.MODEL:
            self.get_logger().warning(f'seq {seq}: model_mismatch (adaptive model at its '
                                      f'bound, persistent innovation bias, or an '
                                      f'unmodelled flow: under load a leak or a drifting '
                                      f'position sensor)')
        else:
            self.get_logger().info(f'seq {seq}: consistency ok')
        if adapt.alarm(verdict):         # on /diagnostics now: an alarm shorter than the
            self.publish_diagnostics()   # diagnostics period would otherwise be missed

    def on_timer(self):
        if self.last_arrival is None:
            return
        if clock_s(self) - self.last_arrival <= self.stale_time:
            return
        if not self.stale:
            self.stale = True
            self.stale_seq = self.last_seq
            self.c.bump('stale_events')
            self.get_logger().warning(
                f'no state for {self.stale_time * 1e3:.1f} ms after seq {self.last_seq}: '
                f'publishing predict-only estimates marked stale',
                throttle_duration_sec=1.0)
        self.stale_seq += 1
        r = self.est.predict_only()
        self.c.bump('stale_estimates')
        self.publish(r, self.get_clock().now().to_msg(), self.stale_seq, True)

    def publish(self, r, stamp, seq, stale):
        m = self.msg
        m.header.stamp = stamp
        m.seq = int(seq)
        m.position, m.velocity = r.position, r.velocity
        m.pressure_diff, m.position_variance = r.pressure_diff, r.position_variance
        m.leak_flow = r.leak_flow
        m.innovation, m.nis = r.innovation, r.nis
        m.motor_speed = r.motor_speed
        m.stale, m.update_skipped = stale, r.update_skipped
        m.sensor_fault = int(r.sensor_fault)
        m.consistency = int(r.consistency)
        publish_counted(self, self.pub, m, 'estimate', seq)

    @diag.reader
    def publish_diagnostics(self):
        values = self.loop.values()
        values.update({'stale': self.stale,
                       'last_seq': self.last_seq if self.last_seq is not None else -1,
                       'sensor_fault': NAMES[self.est.detector.code],
                       'position_variance_m2': self.est.kf.position_variance,
                       'pressures_used': self.est.use_pressure})
        values.update(self.c)
        # the loop thread adds keys: each dict taken in one step (diag.reader)
        values.update({f'estimator_{k}': v for k, v in dict(self.est.counters).items()})
        values['estimator_updates'] = self.est.updates      # beside skipped/isolated_updates
        for code, n in dict(self.est.detector.detections).items():
            values[f'detections_{NAMES[code]}'] = n
        suspect = values['jump_suspect_samples'] = self.est.detector.suspect_samples
        if suspect > self.suspect_logged:     # once per diagnostics period that had any
            self.get_logger().warning(f'{suspect - self.suspect_logged} position samples held '
                                      f'back as a suspected sensor jump (jump_suspect_samples '
                                      f'{suspect})')
        self.suspect_logged = suspect
        if self.est.is_model and self.est.kf.i_leak is not None:
            values['leak_correction_m3_per_s_pa'] = self.est.kf.leak_correction
        alphas = self.est.friction_alphas
        if alphas is not None:
            values.update(alpha_1=alphas[0], alpha_2=alphas[1], alpha_3=alphas[2])
        from ..core.estimator import adapt
        values['consistency'] = adapt.VERDICTS[self.est.consistency]
        values['safe_state_required'] = self.est.safe_state_required
        kf = self.est.kf
        for name in ('leakage', 'displacement', 'compliance'):
            if hasattr(kf, f'{name}_correction'):
                values[f'{name}_correction'] = getattr(kf, f'{name}_correction')
        bad = self.stale or self.est.detector.code or self.c.get('rejected_states', 0)
        level = diag.WARN if bad else diag.OK
        msg = 'ok' if level == diag.OK else 'stale, sensor fault or measurements rejected'
        levels = self.est.noise_levels
        if levels is not None:
            values['noise_level_position'], values['noise_level_pressure'] = levels[:2]
            if levels[2] and level == diag.OK:
                level, msg = diag.WARN, ('sensor noise at the top of '
                                         'estimator.noise.adapt_range: R no longer matches it')
        if adapt.alarm(self.est.consistency):
            level = diag.ERROR
            msg = (f'{values["consistency"]}: ' +
                   ('position sensor faulty, safe state required'
                    if self.est.safe_state_required else
                    'filter and sensor disagree beyond the band'))
        diag.publish(self, self.pub_diag, f'filter {self.get_namespace()}', values, level, msg)


make_node = factory(EstimatorNode)     # make_node(params, transport=None)


def main(argv=None) -> int:
    return run('estimator', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
