"""Reference handling: reject non-finite values, clamp to the stroke minus a margin, limit the
rate (Table 3.1, 190 mm/s) and the acceleration (so a large step does not run into the drive's
current limit: see config/controller_node.yaml). The per-tick move is controller.stepper.shape;
this class keeps its state in the controller's scalar vectors (stepper.C_*)."""
from __future__ import annotations

import math

from ..stats import Counters
from . import stepper as S


class ReferenceShaper:
    """Position reference as the loop may use it (Table 3.1: 120 mm stroke, 190 mm/s)."""

    def __init__(self, stroke: float, margin: float, rate_limit: float, Ts: float,
                 counters: Counters, accel_limit: float = 0.0):
        self.c = counters
        # accel_limit [m/s^2]; 0: rate limit only
        self.k, self.s = S.new_arrays(stroke / 2.0 - margin, rate_limit * Ts, rate_limit,
                                      accel_limit, Ts)

    @property
    def limit(self) -> float:
        """References are clamped to +-limit (stroke/2 - margin) [m]."""
        return float(self.k[S.K_LIMIT])

    @property
    def target(self):
        """Last good (clamped) requested reference, None before any."""
        v = self.s[S.C_TARGET]
        return float(v) if math.isfinite(v) else None

    @property
    def value(self):
        """Rate-limited reference the loop follows, None before start_from."""
        return float(self.s[S.C_VALUE]) if self.s[S.C_STARTED] else None

    @property
    def rate(self) -> float:
        """Its rate while moving to a jumped target [m/s]."""
        return float(self.s[S.C_RATE])

    def request(self, position: float) -> bool:
        """A new requested reference; False (and counted) if rejected."""
        if not math.isfinite(position):
            self.c.bump('rejected_references')
            return False
        S.request(self.k, self.s, position)          # clamp to the stroke, counted there
        if self.s[S.C_N_CLAMPREF]:
            self.c.bump('clamped_references', int(self.s[S.C_N_CLAMPREF]))
            self.s[S.C_N_CLAMPREF] = 0.0
        return True

    def start_from(self, position: float):
        """Restart the rate limiter from where the piston is (start-up, watchdog recovery)."""
        self.s[S.C_VALUE] = max(-self.limit, min(self.limit, position))
        self.s[S.C_STARTED] = 1.0
        self.s[S.C_RATE] = 0.0
        if not math.isfinite(self.s[S.C_TARGET]):
            self.s[S.C_TARGET] = self.s[S.C_VALUE]

    def next(self) -> float:
        """Advance one tick towards the target (stepper.shape)."""
        if not self.s[S.C_STARTED]:
            raise RuntimeError('ReferenceShaper.next before start_from')
        return float(S.shape(self.k, self.s))
