"""Reference handling: reject non-finite values, clamp to the stroke minus a margin, limit the
rate (Table 3.1, 190 mm/s) and the acceleration (so a large step does not drive the motor-speed
clamp, whose windup of the lead states overshoots: see config/controller_node.yaml)."""
from __future__ import annotations

import math

from ..stats import Counters


class ReferenceShaper:
    """Position reference as the loop may use it (Table 3.1: 120 mm stroke, 190 mm/s)."""

    def __init__(self, stroke: float, margin: float, rate_limit: float, Ts: float,
                 counters: Counters, accel_limit: float = 0.0):
        self.limit = stroke / 2.0 - margin
        self.vmax = rate_limit
        self.step = rate_limit * Ts
        self.accel = accel_limit    # [m/s^2]; 0: rate limit only
        self.Ts = Ts
        self.c = counters
        self.target = None          # last good (clamped) requested reference
        self.value = None           # rate-limited reference the loop follows
        self.rate = 0.0             # its rate while moving to a jumped target [m/s]

    def request(self, position: float) -> bool:
        """A new requested reference; False (and counted) if rejected."""
        if not math.isfinite(position):
            self.c.bump('rejected_references')
            return False
        if abs(position) > self.limit:
            self.c.bump('clamped_references')
            position = math.copysign(self.limit, position)
        self.target = position
        return True

    def start_from(self, position: float):
        """Restart the rate limiter from where the piston is (start-up, watchdog recovery)."""
        self.value = max(-self.limit, min(self.limit, position))
        self.rate = 0.0
        if self.target is None:
            self.target = self.value

    def next(self) -> float:
        """Advance one tick towards the target at the rate limit."""
        if self.value is None:
            raise RuntimeError('ReferenceShaper.next before start_from')
        delta = self.target - self.value
        if not self.accel or (self.rate == 0.0 and abs(delta) <= self.step):
            # rate limit only, or following a target that moves at most vmax Ts per tick
            # (a sine, a ramp): passed through unchanged
            self.value = self.target if abs(delta) <= self.step else \
                self.value + math.copysign(self.step, delta)
            return self.value
        # a jump: time-optimal move with bounded rate and acceleration (the fastest rate from
        # which the reference can still stop on the target, reached at most a Ts per tick)
        a, Ts = self.accel, self.Ts
        # discrete braking: from rate v, steps of a Ts cover v^2/(2a) + v Ts/2
        brake = a * (math.sqrt(0.25 * Ts * Ts + 2.0 * abs(delta) / a) - 0.5 * Ts)
        want = math.copysign(min(self.vmax, brake), delta)
        self.rate += max(-a * Ts, min(a * Ts, want - self.rate))
        if abs(delta) <= abs(self.rate) * Ts or abs(delta) <= a * Ts * Ts:
            self.value, self.rate = self.target, 0.0          # arrived: follow from here
        else:
            self.value += self.rate * Ts
        return self.value
