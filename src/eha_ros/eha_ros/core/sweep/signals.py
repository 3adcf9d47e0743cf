"""Test signals: stepped sine like the TwinCAT Fr_Test block (appendix B.1), chirp, step (of the
reference, or of the load force for a load step), staircase of held levels (a held load).

Each signal is a plan that maps a tick index to a reference, so a node (one tick at a time)
and batch code (whole arrays) produce the identical signal.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..config.cli import UsageError


@dataclass(frozen=True)
class Segment:
    """One frequency of a stepped sine: relax (zero) then ``periods`` whole periods of sine."""

    freq_hz: float
    start: int          # tick where the sine starts
    stop: int           # tick after the last sine sample
    relax_start: int    # tick where the relax (zero output) before it starts
    amplitude: float = 0.0


@dataclass
class SteppedSine:
    """Fr_Test: start frequency, increment, max frequency, periods per frequency, relax time.

    ``freqs`` (a list) replaces the start/increment/max sequence when given. ``max_accel``
    lowers the amplitude where A (2 pi f)^2 would exceed it: the sine stays inside the
    reference acceleration limit of the controller and the drive's current limit, so what is
    measured is the linear closed loop, not a saturation."""

    start_hz: float
    increment_hz: float
    max_hz: float
    periods: int
    relax_s: float
    amplitude: float
    offset: float = 0.0
    Ts: float = 1e-3
    freqs: tuple = ()
    max_accel: float = math.inf
    segments: list = field(init=False)

    def __post_init__(self):
        freqs = [float(f) for f in self.freqs]
        f = self.start_hz
        while not self.freqs and f <= self.max_hz + 1e-9:   # Fr_Test: next while <= max_freq
            freqs.append(round(f, 9))
            f += self.increment_hz
        k = 0
        self.segments = []
        for f in freqs:
            relax = int(round(self.relax_s / self.Ts))
            n = int(round(self.periods / f / self.Ts))
            amp = min(self.amplitude, self.max_accel / (2.0 * math.pi * f) ** 2)
            self.segments.append(Segment(f, k + relax, k + relax + n, k, amp))
            k += relax + n
        self.n_ticks = k + int(round(self.relax_s / self.Ts))

    def value(self, k: int) -> float:
        """Reference at tick k (the sine restarts at phase 0 for every frequency)."""
        for seg in self.segments:
            if seg.start <= k < seg.stop:
                return self.offset + seg.amplitude * math.sin(
                    2.0 * math.pi * seg.freq_hz * (k - seg.start) * self.Ts)
        return self.offset

    def array(self) -> np.ndarray:
        out = np.full(self.n_ticks, self.offset)
        for seg in self.segments:
            k = np.arange(seg.start, seg.stop)
            out[k] += seg.amplitude * np.sin(2.0 * np.pi * seg.freq_hz * (k - seg.start) * self.Ts)
        return out

    def segment_at(self, k: int):
        for i, seg in enumerate(self.segments):
            if seg.relax_start <= k < seg.stop:
                return i
        return None


@dataclass
class Chirp:
    """Logarithmic chirp f0 -> f1 over ``duration`` with raised-cosine fade-in/out."""

    f0_hz: float
    f1_hz: float
    duration_s: float
    amplitude: float
    offset: float = 0.0
    fade_s: float = 0.5
    Ts: float = 1e-3

    def __post_init__(self):
        self.n_ticks = int(round(self.duration_s / self.Ts))

    def array(self) -> np.ndarray:
        t = np.arange(self.n_ticks) * self.Ts
        T = self.duration_s
        ratio = self.f1_hz / self.f0_hz
        phase = 2 * np.pi * self.f0_hz * T / np.log(ratio) * (ratio ** (t / T) - 1.0)
        env = np.ones_like(t)
        if self.fade_s > 0:
            up = t < self.fade_s
            env[up] = 0.5 - 0.5 * np.cos(np.pi * t[up] / self.fade_s)
            down = t > T - self.fade_s
            env[down] = 0.5 - 0.5 * np.cos(np.pi * (T - t[down]) / self.fade_s)
        return self.offset + self.amplitude * env * np.sin(phase)

    def value(self, k: int) -> float:
        if not 0 <= k < self.n_ticks:
            return self.offset
        if not hasattr(self, '_arr'):
            self._arr = self.array()
        return float(self._arr[k])


@dataclass
class Step:
    """Step of ``amplitude`` at ``t_step`` on top of ``offset``, held for ``duration``."""

    amplitude: float
    duration_s: float
    t_step_s: float = 0.1
    offset: float = 0.0
    Ts: float = 1e-3

    def __post_init__(self):
        self.n_ticks = int(round(self.duration_s / self.Ts))

    def value(self, k: int) -> float:
        return self.offset + (self.amplitude if k * self.Ts >= self.t_step_s else 0.0)

    def array(self) -> np.ndarray:
        return np.array([self.value(k) for k in range(self.n_ticks)])


@dataclass
class Staircase:
    """Levels held in turn, each reached by a linear ramp from the one before: ``rest_s`` at 0,
    then for each level a ramp of ``ramp_s`` and a hold of ``hold_s``, then a ramp back to 0
    and ``rest_s`` at 0 (a load held at several levels, thesis Fig. 3.44). ``segments``: one
    Segment per hold (freq_hz 0, amplitude = the level)."""

    levels: tuple
    hold_s: float
    ramp_s: float
    rest_s: float
    Ts: float = 1e-3
    segments: list = field(init=False)

    def __post_init__(self):
        rest, ramp, hold = (int(round(t / self.Ts)) for t in (self.rest_s, self.ramp_s,
                                                                self.hold_s))
        points = [(0, 0.0), (rest, 0.0)]           # (tick, value) corners, linear between
        self.segments = []
        for level in self.levels:
            k = points[-1][0] + ramp
            points += [(k, float(level)), (k + hold, float(level))]
            self.segments.append(Segment(0.0, k, k + hold, k - ramp, float(level)))
        k = points[-1][0] + ramp
        points += [(k, 0.0), (k + rest, 0.0)]
        self.corners = points
        self.n_ticks = k + rest

    def array(self) -> np.ndarray:
        ticks, values = zip(*self.corners)
        return np.interp(np.arange(self.n_ticks), ticks, values)

    def value(self, k: int) -> float:
        return float(np.interp(k, *zip(*self.corners))) if 0 <= k < self.n_ticks else 0.0


def check_sweep(start_hz, increment_hz, max_hz, periods, relax_s, amplitude, offset, stroke, Ts,
                margin=0.005, settle_periods=2):
    """Refuse sweeps that cannot be measured or would hit the end stops: one-line UsageError."""
    if not all(math.isfinite(v) for v in (start_hz, increment_hz, max_hz, relax_s, amplitude, offset)):
        raise UsageError('sweep parameters must be finite numbers')
    if periods <= settle_periods:
        raise UsageError(f'periods {periods}: expected more than the {settle_periods} settling '
                         f'periods (and not negative)')
    if relax_s < 0:
        raise UsageError(f'relax time {relax_s} s: expected >= 0')
    if start_hz <= 0 or max_hz < start_hz:
        raise UsageError(f'frequencies: start {start_hz} Hz, max {max_hz} Hz: expected '
                         f'0 < start <= max')
    if increment_hz <= 0:
        raise UsageError(f'increment {increment_hz} Hz: expected > 0')
    check_limits(max_hz, amplitude, offset, stroke, Ts, margin)


def check_limits(max_hz, amplitude, offset, stroke, Ts, margin=0.005):
    """Highest frequency below Nyquist/10, amplitude + offset inside the stroke minus a margin."""
    nyq = 0.5 / Ts
    if max_hz > nyq / 10:
        raise UsageError(f'max frequency {max_hz} Hz is above Nyquist/10 = {nyq / 10:g} Hz at '
                         f'Ts = {Ts:g} s: expected at most {nyq / 10:g} Hz')
    if amplitude <= 0:
        raise UsageError(f'amplitude {amplitude} m: expected > 0')
    check_reach(amplitude, offset, stroke, margin)


def check_load_step(duration_s, t_step_s, window_end_s, offset, stroke, margin=0.005):
    """A load step run long enough for its steady window (``window_end_s`` after the step at
    ``t_step_s``), held at an offset inside the stroke minus a margin."""
    need = t_step_s + window_end_s
    if duration_s < need - 1e-9:
        raise UsageError(f'load step run of {duration_s:g} s (sweep.load_step_duration): '
                         f'expected at least {need:g} s, the step at {t_step_s:g} s plus the '
                         f'end of the steady window {window_end_s:g} s after it')
    check_reach(0.0, offset, stroke, margin)


def check_reach(amplitude, offset, stroke, margin=0.005):
    """amplitude + offset inside the stroke minus a margin."""
    reach = abs(offset) + amplitude
    limit = stroke / 2 - margin
    if reach > limit:
        raise UsageError(f'amplitude {amplitude * 1e3:g} mm + offset {offset * 1e3:g} mm reaches '
                         f'{reach * 1e3:g} mm: beyond the stroke limit of +-{limit * 1e3:g} mm '
                         f'(stroke {stroke * 1e3:g} mm minus {margin * 1e3:g} mm margin)')
