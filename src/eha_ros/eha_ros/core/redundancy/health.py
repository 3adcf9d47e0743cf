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

The per-tick arithmetic is written once, compiled (:func:`health`, :func:`hysteresis`,
:func:`lowpass`): HealthMonitor keeps its state in the arrays these kernels read (constants
``k`` K_*, monitor constants ``mk``, monitor state ``ms``, health state ``hs`` H_*), and the
closed-loop kernels (core.redundancy.stepper, core.sim.closed_loop) run the same functions on
the same arrays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..jit_cache import drop_stale

drop_stale(__file__)

H = 'switch.health.'
DRIVING_ONLY = ('speed', 'pressure', 'estimator')    # judged on the steady driver only
MONITORS = ('drive', 'current') + DRIVING_ONLY
NMON = len(MONITORS)
M_DRIVE, M_CURRENT, M_SPEED, M_PRESSURE, M_ESTIMATOR = range(NMON)
# monitor j of couple c: constants mk[c, j] (MK_*), state ms[c, j] (MS_*; since NaN: None)
MK_ENABLED, MK_TRIP, MK_CLEAR, MK_TRIP_TIME, MK_CLEAR_TIME = range(5)
MS_HEALTHY, MS_VALUE, MS_SINCE = range(3)
# constants (K_BLANK: the switch manager's blanking time, for core.redundancy.stepper)
K_IMAX, K_KT, K_DP, K_J, K_B, K_GRACE, K_STANDBY, K_LIMFRAC, K_PLOW0, K_PLOW1, K_PMAX = \
    range(11)
K_A_SPEED, K_A_PRESS, K_A_INNOV, K_BLANK = 11, 13, 15, 16    # filter poles (2, 2, 1)
NK = 17
# health state
H_F_SPEED, H_F_PRESS, H_F_INNOV = 0, 2, 4
H_WPREV_T, H_WPREV_W, H_WPREV_SET = 5, 7, 9
H_ACKED, H_PLAUSIBLE, H_IMPLAUSIBLE = 11, 13, 14
NH = 15


def pole(hz: float, Ts: float) -> float:
    """Exact pole of a first-order low-pass at ``hz`` sampled at Ts."""
    return math.exp(-2.0 * math.pi * hz * Ts)


@njit(cache=True)
def lowpass(a, y, u):
    """y <- a y + (1 - a) u."""
    return a * y + (1.0 - a) * u


@njit(cache=True)
def hysteresis(mk, ms, c, j, t, value, judge) -> None:
    """Monitor (c, j): trip above ``trip`` held ``trip_time``, clear below ``clear`` held
    ``clear_time``; not judged (or a non-finite level): verdict held, timer reset."""
    ms[c, j, MS_VALUE] = value
    if not (mk[c, j, MK_ENABLED] > 0.5 and judge and math.isfinite(value)):
        ms[c, j, MS_SINCE] = math.nan
        return
    healthy = ms[c, j, MS_HEALTHY] > 0.5
    beyond = value > mk[c, j, MK_TRIP] if healthy else value < mk[c, j, MK_CLEAR]
    if not beyond:
        ms[c, j, MS_SINCE] = math.nan
        return
    if math.isnan(ms[c, j, MS_SINCE]):
        ms[c, j, MS_SINCE] = t
    if t - ms[c, j, MS_SINCE] >= (mk[c, j, MK_TRIP_TIME] if healthy
                                  else mk[c, j, MK_CLEAR_TIME]) - 1e-9:
        ms[c, j, MS_HEALTHY] = 0.0 if healthy else 1.0
        ms[c, j, MS_SINCE] = math.nan


@njit(cache=True)
def shaft_pressure(i, w, dw_dt, k_T, b_eq, J_eq, D_p) -> float:
    """The pressure difference the pump's torque implies from the shaft's torque balance
    (eq. 3.17): p_D = (k_T i - b_eq w - J_eq dw/dt) / D_p (the pressure monitor here, the
    estimator's fault detector)."""
    return (k_T * i - b_eq * w - J_eq * dw_dt) / D_p


@njit(cache=True)
def health(k, mk, ms, hs, t, lo_ref, hi_ref, w_meas, i_meas, pa, pb, reported, fault,
           innovation, estimate_ok, loop_ok, cmd, steady, age) -> None:
    """One measured state: every monitor of both couples.

    lo_ref, hi_ref: the range of speed references the drives may be applying now (equal: the
    reference exactly); cmd[c]: drive c commanded on; steady[c]: c drives the piston past the
    blanking time; age[c]: time since cmd[c] last changed (s); loop_ok: the position loop is
    closed (speed, current, pressure and estimator are judged only then).
    Pressure residual (torque balance of eq. 3.17): r = (k_T i - b w - J dw/dt) / D_p - p_D."""
    plausible = (math.isfinite(pa) and math.isfinite(pb) and
                 k[K_PLOW0] <= min(pa, pb) <= k[K_PLOW1] and max(pa, pb) <= k[K_PMAX])
    if not plausible:
        hs[H_IMPLAUSIBLE] += 1
    hs[H_PLAUSIBLE] = plausible
    p_d = pa - pb if plausible else 0.0
    use = estimate_ok and math.isfinite(innovation)
    if use:
        hs[H_F_INNOV] = lowpass(k[K_A_INNOV], hs[H_F_INNOV], abs(innovation))
    innov = hs[H_F_INNOV]
    for c in range(2):
        w, i = w_meas[c], i_meas[c]
        on = cmd[c]
        # a commanded enable change is acknowledged when the drive first reports it (DDS
        # latency is not a fault); afterwards any difference is, and so is no
        # acknowledgement within enable_grace
        rep = reported[c]
        if rep == on:
            hs[H_ACKED + c] = 1.0
        acked = hs[H_ACKED + c] > 0.5
        mismatch = rep != on and (acked or age[c] > k[K_GRACE])
        leaking = acked and not on and abs(i) > k[K_STANDBY]
        hysteresis(mk, ms, c, M_DRIVE, t, 1.0 if (fault[c] or mismatch or leaking) else 0.0,
                   True)
        hysteresis(mk, ms, c, M_CURRENT, t, abs(i) / k[K_IMAX], on and loop_ok)
        # at its current limit a healthy drive lags its reference (k_T I_max / J_eq =
        # 44000 rad/s^2): the current monitor judges a persistent limit, not this one
        limited = abs(i) >= k[K_LIMFRAC] * k[K_IMAX]
        lo, hi = lo_ref, hi_ref
        if not on:
            lo = hi = 0.0
        err = lo - w if w < lo else (hi - w if w > hi else 0.0)
        hs[H_F_SPEED + c] = lowpass(k[K_A_SPEED + c], hs[H_F_SPEED + c],
                                    err if loop_ok else 0.0)
        hysteresis(mk, ms, c, M_SPEED, t, abs(hs[H_F_SPEED + c]),
                   steady[c] and loop_ok and not limited)
        # (t, w) of the previous sample: lost states widen the difference
        dt = t - hs[H_WPREV_T + c] if hs[H_WPREV_SET + c] > 0.5 else 0.0
        dw = (w - hs[H_WPREV_W + c]) / dt if dt > 0.0 else 0.0
        hs[H_WPREV_T + c] = t
        hs[H_WPREV_W + c] = w
        hs[H_WPREV_SET + c] = 1.0
        r = shaft_pressure(i, w, dw, k[K_KT], k[K_B], k[K_J], k[K_DP]) - p_d
        hs[H_F_PRESS + c] = lowpass(k[K_A_PRESS + c], hs[H_F_PRESS + c], r)
        hysteresis(mk, ms, c, M_PRESSURE, t, abs(hs[H_F_PRESS + c]),
                   steady[c] and plausible and loop_ok)
        hysteresis(mk, ms, c, M_ESTIMATOR, t, innov, steady[c] and use and loop_ok)


@njit(cache=True)
def healthy(ms, c) -> bool:
    """Every monitor of couple c is healthy."""
    for j in range(ms.shape[1]):
        if ms[c, j, MS_HEALTHY] < 0.5:
            return False
    return True


@njit(cache=True)
def available(ms, c) -> bool:
    """The monitors judged in standby too (drive status, current) of couple c are healthy."""
    return ms[c, M_DRIVE, MS_HEALTHY] > 0.5 and ms[c, M_CURRENT, MS_HEALTHY] > 0.5


class Hysteresis:
    """Trip above ``trip`` held for ``trip_time``; clear below ``clear`` held for ``clear_time``
    (:func:`hysteresis` on row (c, j) of the arrays ``mk``, ``ms``; its own when not given)."""

    def __init__(self, trip: float, clear: float, trip_time: float, clear_time: float,
                 enabled: bool = True, arrays=None, c: int = 0, j: int = 0):
        if clear > trip:
            raise ValueError(f'clear level {clear} above trip level {trip}')
        if arrays is None:
            arrays, c, j = (np.zeros((1, 1, 5)), np.zeros((1, 1, 3))), 0, 0
        self._mk, self._ms, self._c, self._j = arrays[0], arrays[1], c, j
        self._mk[c, j] = (float(enabled), trip, clear, trip_time, clear_time)
        self.reset()

    def reset(self):
        self._ms[self._c, self._j] = (1.0, 0.0, math.nan)

    def update(self, t: float, value: float, judge: bool = True) -> bool:
        """Feed one sample; returns the verdict (True = healthy). Not judged: verdict held."""
        hysteresis(self._mk, self._ms, self._c, self._j, float(t), float(value), bool(judge))
        return self.healthy

    @property
    def healthy(self) -> bool:
        return bool(self._ms[self._c, self._j, MS_HEALTHY] > 0.5)

    @property
    def value(self) -> float:
        return float(self._ms[self._c, self._j, MS_VALUE])

    @property
    def trip(self) -> float:
        return float(self._mk[self._c, self._j, MK_TRIP])

    @classmethod
    def from_params(cls, p: dict, name: str, arrays=None, c: int = 0,
                    j: int = 0) -> 'Hysteresis':
        k = H + name + '.'
        return cls(p[k + 'trip'], p[k + 'clear'], p[k + 'trip_time'], p[k + 'clear_time'],
                   p[k + 'enabled'], arrays, c, j)


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


class HealthMonitor:
    """Both couples' monitors; :meth:`update` once per measured state (:func:`health`)."""

    def __init__(self, p: dict):
        self.Ts = p['plant.sim.Ts']
        self.p = p
        k = self.k = np.zeros(NK)
        k[K_IMAX], k[K_KT], k[K_DP] = p['plant.drive.I_max'], p['plant.motor.k_T'], \
            p['plant.pump.D_p']
        k[K_J], k[K_B] = p['plant.motor.J_eq'], p['plant.motor.b_eq']
        k[K_GRACE], k[K_STANDBY] = p[H + 'drive.enable_grace'], p[H + 'current.standby_max']
        k[K_LIMFRAC] = p[H + 'current.clear']
        k[K_PLOW0], k[K_PLOW1] = p[H + 'pressure.low_side_min'], p[H + 'pressure.low_side_max']
        k[K_PMAX] = p[H + 'pressure.max']
        self.mk = np.zeros((2, NMON, 5))
        self.ms = np.zeros((2, NMON, 3))
        self.hs = np.zeros(NH)
        self.channels = [ChannelHealth({n: Hysteresis.from_params(p, n, (self.mk, self.ms), c, j)
                                        for j, n in enumerate(MONITORS)}) for c in range(2)]
        self.reset_filters()
        self.hs[H_PLAUSIBLE] = 1.0
        self.hs[H_ACKED:H_ACKED + 2] = 1.0
        # compiled (or loaded) now: available() is first called by a switch, mid-run
        healthy(self.ms, 0), available(self.ms, 0)
        # per-call argument arrays of health(), filled in place
        self._w, self._i, self._age = np.zeros(2), np.zeros(2), np.zeros(2)
        self._rep, self._fault = np.zeros(2, np.bool_), np.zeros(2, np.bool_)
        self._cmd, self._steady = np.zeros(2, np.bool_), np.zeros(2, np.bool_)

    def reset_filters(self):
        p, Ts, k, hs = self.p, self.Ts, self.k, self.hs
        for c in range(2):
            k[K_A_SPEED + c] = pole(p[H + 'speed.lowpass'], Ts)
            k[K_A_PRESS + c] = pole(p[H + 'pressure.lowpass'], Ts)
            hs[H_F_SPEED + c] = hs[H_F_PRESS + c] = 0.0
            hs[H_WPREV_SET + c] = 0.0
        k[K_A_INNOV] = pole(p[H + 'estimator.lowpass'], Ts)
        hs[H_F_INNOV] = 0.0

    @property
    def pressure_plausible(self) -> bool:
        return bool(self.hs[H_PLAUSIBLE] > 0.5)

    @property
    def implausible_samples(self) -> int:
        return int(self.hs[H_IMPLAUSIBLE])

    def healthy(self, c: int) -> bool:
        return bool(healthy(self.ms, c))

    def available(self, c: int) -> bool:
        """Monitors judged in standby too (drive status, current) are healthy."""
        return bool(available(self.ms, c))

    def failed(self, c: int) -> list[str]:
        """The names of couple c's tripped monitors."""
        return [n for n, h in self.channels[c].monitors.items() if not h.healthy]

    def pressure_residual(self, c: int) -> float:
        """Couple c's low-passed torque-balance residual (Pa): the pressure monitor's signal."""
        return float(self.hs[H_F_PRESS + c])

    def disable(self, name: str):
        """Monitor ``name`` off on both couples, its verdicts healthy (until a new monitor)."""
        j = MONITORS.index(name)
        for c in range(2):
            self.mk[c, j, MK_ENABLED] = 0.0
            self.channels[c].monitors[name].reset()

    def rearm(self, c: int):
        """Forget the driving-only verdicts of couple c (before a commanded retry)."""
        for n in DRIVING_ONLY:
            self.channels[c].monitors[n].reset()

    def command_changed(self, c: int):
        """The commanded enable of drive c changed: wait for its acknowledgement."""
        self.hs[H_ACKED + c] = 0.0

    def update(self, s: ChannelSample, cmd_enable, steady, enable_age) -> list[bool]:
        """cmd_enable[c]: drive c commanded on; steady[c]: c drives the piston, valves open,
        past the blanking time; enable_age[c]: time since cmd_enable[c] last changed (s)."""
        lo, hi = s.speed_ref_range or (s.speed_ref, s.speed_ref)
        for c in range(2):
            self._w[c], self._i[c] = s.motor_speed[c], s.motor_current[c]
            self._rep[c], self._fault[c] = bool(s.drive_enabled[c]), bool(s.drive_fault[c])
            self._cmd[c], self._steady[c] = bool(cmd_enable[c]), bool(steady[c])
            self._age[c] = enable_age[c]
        health(self.k, self.mk, self.ms, self.hs, float(s.t), float(lo), float(hi), self._w,
               self._i, float(s.pressure_a), float(s.pressure_b), self._rep, self._fault,
               float(s.innovation), bool(s.estimate_ok), bool(s.loop_ok), self._cmd,
               self._steady, self._age)
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
