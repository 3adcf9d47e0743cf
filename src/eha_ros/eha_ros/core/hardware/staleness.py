"""Freshness of a device's data from its cycle counter (the PLC's task cycle count), and how
many device cycles each sample stands for."""
from __future__ import annotations

import math


class Staleness:
    """Fresh while the counter moved within ``limit`` seconds (reads failing: it stands still).

    ``ticks`` after each :meth:`update`: loop periods this reading stands for, so that the
    readings' seq (advanced by ``ticks``) keeps the device's time. A repeat (the counter did not
    move: the loop ran ahead of the device) is 1 and owed back; a new sample is the counter's
    advance (modulo ``modulus``) less what is owed, at least 1. A late loop cycle that finds the
    counter 5 cycles on is 5 periods, not one (the estimator predicts over them instead of
    taking the move for a sensor jump). A counter that went back (device restarted) is 1,
    counted in ``jumps``."""

    def __init__(self, limit: float, modulus: int | None = None):
        self.limit = limit
        self.modulus = modulus
        self.jumps = 0                   # the counter went back (restarted device)
        self.restart()

    def restart(self):
        """A new connection: the next sample starts the count again."""
        self.cycle = None
        self.changed_at = None
        self.ticks = 1
        self.owed = 0                    # repeats not yet matched by a skipped cycle

    def update(self, cycle: int, now: float) -> bool:
        """True when ``cycle`` is a new sample (the counter moved since the last update)."""
        new = cycle != self.cycle
        if not new:
            self.ticks = 1
            self.owed += 1
            return False
        advance = 1
        if self.cycle is not None and self.modulus:
            advance = (cycle - self.cycle) % self.modulus
            if advance > self.modulus // 2:  # went back: a restarted device
                self.jumps += 1
                advance, self.owed = 1, 0
        self.ticks = max(1, advance - self.owed)
        self.owed -= advance - self.ticks
        self.cycle, self.changed_at = cycle, now
        return new

    def fresh(self, now: float) -> bool:
        return self.changed_at is not None and now - self.changed_at <= self.limit

    def age(self, now: float) -> float:
        return math.inf if self.changed_at is None else now - self.changed_at
