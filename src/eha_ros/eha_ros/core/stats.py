"""Loop statistics for 1 kHz nodes: period and execution-time percentiles, overruns, counters."""
from __future__ import annotations

import time

import numpy as np


class RingStats:
    """Last ``n`` samples of a quantity (seconds) with mean / p50 / p99 / max."""

    def __init__(self, n: int = 4096):
        self.buf = [0.0] * n        # a list: a store costs a fifth of a numpy item's
        self.size = n
        self.n = 0
        self.i = 0
        self.max_ever = 0.0

    def add(self, value: float):
        i = self.i
        self.buf[i] = value
        self.i = i + 1 if i + 1 < self.size else 0
        if self.n < self.size:
            self.n += 1
        if value > self.max_ever:
            self.max_ever = value

    def summary(self) -> dict:
        if self.n == 0:
            return {'mean': 0.0, 'p50': 0.0, 'p99': 0.0, 'max': 0.0}
        data = np.array(self.buf[:self.n])
        p50, p99 = np.percentile(data, [50, 99])
        return {'mean': float(data.mean()), 'p50': float(p50), 'p99': float(p99),
                'max': float(self.max_ever)}


class Counters(dict):
    """Named event counters (rejected inputs, overruns ...), zero by default."""

    def bump(self, name: str, by: int = 1):
        self[name] = self.get(name, 0) + by


class Histogram:
    """Whole-run distribution of a time (s) in fixed bins, for percentiles over long runs."""

    def __init__(self, bin_s: float = 10e-6, top_s: float = 0.05):
        self.bin = bin_s
        self.counts = [0] * (int(round(top_s / bin_s)) + 1)     # last: overflow (a list: cheap)
        self.top = len(self.counts) - 1
        self.n = 0
        self.max = 0.0

    def add(self, value: float):
        i = min(int(value / self.bin), self.top)
        self.counts[i] += 1
        self.n += 1
        if value > self.max:
            self.max = value

    def percentile(self, q: float) -> float:
        """Upper edge of the bin holding the q-th percentile (the max if it is in the overflow)."""
        if self.n == 0:
            return 0.0
        i = int(np.searchsorted(np.cumsum(self.counts), q / 100.0 * self.n))
        return self.max if i >= len(self.counts) - 1 else min((i + 1) * self.bin, self.max)

    def fraction_below(self, limit: float) -> float:
        if self.n == 0:
            return 0.0
        return float(sum(self.counts[:int(limit / self.bin)])) / self.n


class LoopStats:
    """Per-node loop figures for /diagnostics: input period, execution time, overruns (a
    callback that took longer than the period ``Ts``)."""

    def __init__(self, Ts: float):
        self.Ts = Ts
        self.period = RingStats()
        self.exec = RingStats()
        self.overruns = 0
        self._last = None

    def arrived(self, now: float):
        """An input of the loop arrived at ``now`` (s, any clock)."""
        if self._last is not None:
            self.period.add(now - self._last)
        self._last = now

    def executed(self, seconds: float):
        self.exec.add(seconds)
        if seconds > self.Ts:
            self.overruns += 1

    def timed(self, handler, msg):
        """Run handler(msg) as one loop input: arrival (perf_counter) and execution time."""
        t0 = time.perf_counter()
        self.arrived(t0)
        handler(msg)
        self.executed(time.perf_counter() - t0)

    def values(self) -> dict:
        per, ex = self.period.summary(), self.exec.summary()
        return {'period_mean_s': per['mean'], 'period_p99_s': per['p99'],
                'period_max_s': per['max'], 'exec_mean_s': ex['mean'], 'exec_p99_s': ex['p99'],
                'exec_max_s': ex['max'], 'overruns': self.overruns}
