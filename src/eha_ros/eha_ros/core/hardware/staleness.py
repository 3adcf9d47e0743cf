"""Freshness of a device's data from its cycle counter (the PLC's task cycle count)."""
from __future__ import annotations

import math


class Staleness:
    """Fresh while the counter moved within ``limit`` seconds (reads failing: it stands still)."""

    def __init__(self, limit: float):
        self.limit = limit
        self.cycle = None
        self.changed_at = None

    def update(self, cycle: int, now: float) -> bool:
        """True when ``cycle`` is a new sample (the counter moved since the last update)."""
        new = cycle != self.cycle
        if new:
            self.cycle, self.changed_at = cycle, now
        return new

    def fresh(self, now: float) -> bool:
        return self.changed_at is not None and now - self.changed_at <= self.limit

    def age(self, now: float) -> float:
        return math.inf if self.changed_at is None else now - self.changed_at
