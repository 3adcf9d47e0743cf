"""Reference handling: reject non-finite values, clamp to the stroke minus a margin, rate-limit."""
from __future__ import annotations

import math

from ..stats import Counters


class ReferenceShaper:
    """Position reference as the loop may use it (Table 3.1: 120 mm stroke, 190 mm/s)."""

    def __init__(self, stroke: float, margin: float, rate_limit: float, Ts: float,
                 counters: Counters):
        self.limit = stroke / 2.0 - margin
        self.step = rate_limit * Ts
        self.c = counters
        self.target = None          # last good (clamped) requested reference
        self.value = None           # rate-limited reference the loop follows

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
        if self.target is None:
            self.target = self.value

    def next(self) -> float:
        """Advance one tick towards the target at the rate limit."""
        if self.value is None:
            raise RuntimeError('ReferenceShaper.next before start_from')
        delta = self.target - self.value
        self.value += max(-self.step, min(self.step, delta))
        return self.value
