"""Per-channel health of the two motor-pump couples (thesis 3.4, Fig. 3.12) from what a bench
sees: drive status, motor-speed tracking, current against its limit, pressure consistency
(torque balance of eq. 3.17) and the estimator residual (position innovation of the eq. 4.35
Kalman filter).

Each monitor is a :class:`Hysteresis`: a level that must be exceeded for ``trip_time`` to go
unhealthy (debounce) and must fall below a lower ``clear`` level for ``clear_time`` to recover
(hysteresis). Monitors that only mean something on the couple that drives the piston (speed,
pressure, estimator) are judged only while it is the steady driver; otherwise they hold their
verdict. Speed, current, pressure and estimator monitors are judged only while the position
loop is closed (commands answer recent states): a stack that is starting or starved of CPU is
not a couple fault; the drive status is always judged. Time is the plant time t = seq Ts, so
lost or late messages do not shorten a debounce.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

H = 'switch.health.'
DRIVING_ONLY = ('speed', 'pressure', 'estimator')    # judged on the steady driver only
MONITORS = ('drive', 'current') + DRIVING_ONLY


class Hysteresis:
    """Trip above ``trip`` held for ``trip_time``; clear below ``clear`` held for ``clear_time``."""

    def __init__(self, trip: float, clear: float, trip_time: float, clear_time: float,
                 enabled: bool = True):
        if clear > trip:
            raise ValueError(f'clear level {clear} above trip level {trip}')
        self.trip, self.clear = trip, clear
        self.trip_time, self.clear_time = trip_time, clear_time
        self.enabled = enabled
        self.reset()

    def reset(self):
        self.healthy = True
        self.value = 0.0
        self._since = None          # time the level was first beyond the threshold

    def update(self, t: float, value: float, judge: bool = True) -> bool:
        """Feed one sample; returns the verdict (True = healthy). Not judged: verdict held."""
        self.value = value
        if not (self.enabled and judge and math.isfinite(value)):
            self._since = None
            return self.healthy
        beyond = value > self.trip if self.healthy else value < self.clear
        if not beyond:
            self._since = None
            return self.healthy
        if self._since is None:
            self._since = t
        if t - self._since >= (self.trip_time if self.healthy else self.clear_time) - 1e-9:
            self.healthy = not self.healthy
            self._since = None
        return self.healthy

    @classmethod
    def from_params(cls, p: dict, name: str) -> 'Hysteresis':
        k = H + name + '.'
        return cls(p[k + 'trip'], p[k + 'clear'], p[k + 'trip_time'], p[k + 'clear_time'],
                   p[k + 'enabled'])


class LowPass:
    """First-order low-pass at ``hz`` sampled at Ts (exact pole)."""

    def __init__(self, hz: float, Ts: float):
        self.a = math.exp(-2.0 * math.pi * hz * Ts)
        self.y = 0.0

    def __call__(self, u: float) -> float:
        self.y = self.a * self.y + (1.0 - self.a) * u
        return self.y


@dataclass
class ChannelSample:
    """One /eha/state (with the latest command and estimate): bench-visible signals, SI."""

    t: float                                  # plant time seq * Ts [s]
    speed_ref: float                          # latest motor speed reference [rad/s]
    motor_speed: tuple = (0.0, 0.0)           # [rad/s]
    motor_current: tuple = (0.0, 0.0)         # [A]
    pressure_a: float = 1e6                   # [Pa]
    pressure_b: float = 1e6                   # [Pa]
    drive_enabled: tuple = (True, False)
    drive_fault: tuple = (False, False)
    valid: bool = True
    innovation: float = float('nan')          # position innovation [m]; NaN: no estimate
    estimate_ok: bool = False                 # estimate fresh, no sensor fault, update made
    loop_ok: bool = True                      # position loop closed: speed_ref is what the
                                              # drives apply now (commands answer recent states)
    speed_ref_range: tuple | None = None      # (lo, hi) of the references the drives may be
                                              # applying now (unknown command latency); None:
                                              # speed_ref exactly


@dataclass
class ChannelHealth:
    monitors: dict = field(default_factory=dict)     # name -> Hysteresis

    @property
    def healthy(self) -> bool:
        return all(m.healthy for m in self.monitors.values())


class HealthMonitor:
    """Both couples' monitors; :meth:`update` once per measured state."""

    def __init__(self, p: dict):
        self.Ts = p['plant.sim.Ts']
        self.i_max = p['plant.drive.I_max']
        self.k_T, self.D_p = p['plant.motor.k_T'], p['plant.pump.D_p']
        self.J, self.b = p['plant.motor.J_eq'], p['plant.motor.b_eq']
        self.enable_grace = p[H + 'drive.enable_grace']
        self.standby_max = p[H + 'current.standby_max']
        self.limit_fraction = p[H + 'current.clear']
        self.p_low = (p[H + 'pressure.low_side_min'], p[H + 'pressure.low_side_max'])
        self.p_max = p[H + 'pressure.max']
        self.p = p
        self.channels = [ChannelHealth({n: Hysteresis.from_params(p, n) for n in MONITORS})
                         for _ in range(2)]
        self.reset_filters()
        self.pressure_plausible = True
        self.implausible_samples = 0
        self.acked = [True, True]

    def reset_filters(self):
        p, Ts = self.p, self.Ts
        self.f_speed = [LowPass(p[H + 'speed.lowpass'], Ts) for _ in range(2)]
        self.f_press = [LowPass(p[H + 'pressure.lowpass'], Ts) for _ in range(2)]
        self.f_innov = LowPass(p[H + 'estimator.lowpass'], Ts)
        self.w_prev = [None, None]

    def healthy(self, c: int) -> bool:
        return self.channels[c].healthy

    def available(self, c: int) -> bool:
        """Monitors judged in standby too (drive status, current) are healthy."""
        m = self.channels[c].monitors
        return m['drive'].healthy and m['current'].healthy

    def rearm(self, c: int):
        """Forget the driving-only verdicts of couple c (before a commanded retry)."""
        for n in DRIVING_ONLY:
            self.channels[c].monitors[n].reset()

    def command_changed(self, c: int):
        """The commanded enable of drive c changed: wait for its acknowledgement."""
        self.acked[c] = False

    def update(self, s: ChannelSample, cmd_enable, steady, enable_age) -> list[bool]:
        """cmd_enable[c]: drive c commanded on; steady[c]: c drives the piston, valves open,
        past the blanking time; enable_age[c]: time since cmd_enable[c] last changed (s)."""
        t = s.t
        pa, pb = s.pressure_a, s.pressure_b
        plausible = (math.isfinite(pa) and math.isfinite(pb) and
                     self.p_low[0] <= min(pa, pb) <= self.p_low[1] and max(pa, pb) <= self.p_max)
        if not plausible:
            self.implausible_samples += 1
        self.pressure_plausible = plausible
        p_d = pa - pb if plausible else 0.0
        use = s.estimate_ok and math.isfinite(s.innovation)
        innov = self.f_innov(abs(s.innovation)) if use else self.f_innov.y
        for c in range(2):
            m = self.channels[c].monitors
            w, i = float(s.motor_speed[c]), float(s.motor_current[c])
            on = bool(cmd_enable[c])
            # a commanded enable change is acknowledged when the drive first reports it (DDS
            # latency is not a fault); afterwards any difference is, and so is no
            # acknowledgement within enable_grace
            reported = bool(s.drive_enabled[c])
            if reported == on:
                self.acked[c] = True
            mismatch = reported != on and (self.acked[c] or enable_age[c] > self.enable_grace)
            leaking = self.acked[c] and not on and abs(i) > self.standby_max
            m['drive'].update(t, 1.0 if (s.drive_fault[c] or mismatch or leaking) else 0.0)
            m['current'].update(t, abs(i) / self.i_max, judge=on and s.loop_ok)
            # at its current limit a healthy drive lags its reference (k_T I_max / J_eq =
            # 44000 rad/s^2): the current monitor judges a persistent limit, not this one
            limited = abs(i) >= self.limit_fraction * self.i_max
            lo, hi = s.speed_ref_range or (s.speed_ref, s.speed_ref)
            if not on:
                lo = hi = 0.0
            err = lo - w if w < lo else (hi - w if w > hi else 0.0)
            m['speed'].update(t, abs(self.f_speed[c](err if s.loop_ok else 0.0)),
                              judge=steady[c] and s.loop_ok and not limited)
            prev = self.w_prev[c]          # (t, w) of the previous sample: lost states
            dt = t - prev[0] if prev is not None else 0.0      # widen the difference
            dw = (w - prev[1]) / dt if dt > 0.0 else 0.0
            self.w_prev[c] = (t, w)
            r = (self.k_T * i - self.b * w - self.J * dw) / self.D_p - p_d
            m['pressure'].update(t, abs(self.f_press[c](r)),
                                 judge=steady[c] and plausible and s.loop_ok)
            m['estimator'].update(t, innov, judge=steady[c] and use and s.loop_ok)
        return [self.healthy(0), self.healthy(1)]

    def figures(self, c: int) -> dict:
        """Latest monitor levels and verdicts of couple c (for the event log)."""
        m = self.channels[c].monitors
        return {n: {'value': float(np.round(h.value, 6)), 'healthy': h.healthy}
                for n, h in m.items()}

    def why(self, c: int) -> str:
        """The tripped monitors of couple c with their levels, one line."""
        units = {'drive': '', 'current': ' x I_max', 'speed': ' rad/s', 'pressure': ' Pa',
                 'estimator': ' m (innovation)'}
        bad = [f'{n} {h.value:.4g}{units[n]} (trip {h.trip:.4g})'
               for n, h in self.channels[c].monitors.items() if not h.healthy]
        return ', '.join(bad) if bad else 'healthy'
