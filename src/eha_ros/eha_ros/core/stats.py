"""Loop statistics for 1 kHz nodes: period and execution-time percentiles, overruns, counters."""
from __future__ import annotations

import numpy as np


class RingStats:
    """Last ``n`` samples of a quantity (seconds) with mean / p50 / p99 / max."""

    def __init__(self, n: int = 4096):
        self.buf = np.zeros(n)
        self.n = 0
        self.i = 0
        self.max_ever = 0.0

    def add(self, value: float):
        self.buf[self.i] = value
        self.i = (self.i + 1) % len(self.buf)
        self.n = min(self.n + 1, len(self.buf))
        if value > self.max_ever:
            self.max_ever = value

    def summary(self) -> dict:
        if self.n == 0:
            return {'mean': 0.0, 'p50': 0.0, 'p99': 0.0, 'max': 0.0}
        data = self.buf[:self.n]
        p50, p99 = np.percentile(data, [50, 99])
        return {'mean': float(data.mean()), 'p50': float(p50), 'p99': float(p99),
                'max': float(self.max_ever)}


class Counters(dict):
    """Named event counters (rejected inputs, overruns ...), zero by default."""

    def bump(self, name: str, by: int = 1):
        self[name] = self.get(name, 0) + by
