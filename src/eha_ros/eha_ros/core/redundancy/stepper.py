"""SwitchManager.update as a compiled call while it would change nothing, for closed-loop
kernels (core.closed_loop): HealthMonitor.update (Hysteresis, LowPass; same operations as the
Python path) and the check that the state machine stays put. Anything else -- a switch
running, a transition due, a command -- is the Python state machine's tick.
A running switch is followed here between its valve/drive steps (nothing changes then).

Monitor j of couple c: constants MK[c, j] = (enabled, trip, clear, trip_time, clear_time),
state MS[c, j] = (healthy, value, since; NaN = None). Scalars in H_* (health) and G_*
(manager) vectors; :func:`pack` / :func:`unpack` move them.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .health import MONITORS
from .state_machine import ACTIVE, DEGRADED, FAILED_SAFE, SWITCHING

STATES = (ACTIVE, SWITCHING, DEGRADED, FAILED_SAFE)
ST_ACTIVE, ST_SWITCHING, ST_DEGRADED, ST_FAILED = range(4)
M_DRIVE, M_CURRENT, M_SPEED, M_PRESSURE, M_ESTIMATOR = (MONITORS.index(n) for n in (
    'drive', 'current', 'speed', 'pressure', 'estimator'))
NMON = len(MONITORS)
# constants
K_IMAX, K_KT, K_DP, K_J, K_B, K_GRACE, K_STANDBY, K_LIMFRAC, K_PLOW0, K_PLOW1, K_PMAX = \
    range(11)
K_A_SPEED, K_A_PRESS, K_A_INNOV, K_BLANK = 11, 13, 15, 16    # filter poles (2, 2, 1)
NK = 17
# health state
H_F_SPEED, H_F_PRESS, H_F_INNOV = 0, 2, 4
H_WPREV_T, H_WPREV_W, H_WPREV_SET = 5, 7, 9
H_ACKED, H_PLAUSIBLE, H_IMPLAUSIBLE = 11, 13, 14
NH = 15
# manager state
G_STATE, G_ACTIVE, G_ENABLE, G_ROLE_SINCE, G_ENABLE_SINCE, G_LATCHED, G_T, G_SEQ = \
    0, 1, 2, 4, 5, 7, 9, 10
G_TARGET, G_NEXT_STEP = 11, 12      # switch target, time of its next valve/drive step (inf)
NG = 13


def pack(mgr):
    """(constants, monitor constants, monitor state, health state, manager state)."""
    h = mgr.health
    k = np.zeros(NK)
    k[K_IMAX], k[K_KT], k[K_DP], k[K_J], k[K_B] = h.i_max, h.k_T, h.D_p, h.J, h.b
    k[K_GRACE], k[K_STANDBY], k[K_LIMFRAC] = h.enable_grace, h.standby_max, h.limit_fraction
    k[K_PLOW0], k[K_PLOW1], k[K_PMAX] = h.p_low[0], h.p_low[1], h.p_max
    k[K_BLANK] = mgr.blank
    mk = np.zeros((2, NMON, 5))
    ms = np.zeros((2, NMON, 3))
    hs = np.zeros(NH)
    for c in range(2):
        for j, name in enumerate(MONITORS):
            m = h.channels[c].monitors[name]
            mk[c, j] = (m.enabled, m.trip, m.clear, m.trip_time, m.clear_time)
            ms[c, j] = (m.healthy, m.value, math.nan if m._since is None else m._since)
        k[K_A_SPEED + c], k[K_A_PRESS + c] = h.f_speed[c].a, h.f_press[c].a
        hs[H_F_SPEED + c], hs[H_F_PRESS + c] = h.f_speed[c].y, h.f_press[c].y
        prev = h.w_prev[c]
        hs[H_WPREV_SET + c] = prev is not None
        if prev is not None:
            hs[H_WPREV_T + c], hs[H_WPREV_W + c] = prev
        hs[H_ACKED + c] = h.acked[c]
    k[K_A_INNOV] = h.f_innov.a
    hs[H_F_INNOV] = h.f_innov.y
    hs[H_PLAUSIBLE], hs[H_IMPLAUSIBLE] = h.pressure_plausible, h.implausible_samples
    g = np.zeros(NG)
    g[G_STATE], g[G_ACTIVE] = STATES.index(mgr.state), mgr.active
    g[G_ROLE_SINCE], g[G_T], g[G_SEQ] = mgr.role_since, mgr.t, mgr.seq
    g[G_TARGET] = mgr.target
    g[G_NEXT_STEP] = mgr.steps[0][0] if mgr.steps else math.inf
    for c in range(2):
        g[G_ENABLE + c] = mgr.select.drive_enable[c]
        g[G_ENABLE_SINCE + c] = mgr.enable_since[c]
        g[G_LATCHED + c] = mgr.latched[c]
    return k, mk, ms, hs, g


def unpack(mgr, ms, hs, g) -> None:
    """Health state, time and seq back into the manager (nothing else changes in a segment)."""
    h = mgr.health
    for c in range(2):
        for j, name in enumerate(MONITORS):
            m = h.channels[c].monitors[name]
            m.healthy, m.value = bool(ms[c, j, 0]), float(ms[c, j, 1])
            m._since = None if math.isnan(ms[c, j, 2]) else float(ms[c, j, 2])
        h.f_speed[c].y, h.f_press[c].y = float(hs[H_F_SPEED + c]), float(hs[H_F_PRESS + c])
        h.w_prev[c] = ((float(hs[H_WPREV_T + c]), float(hs[H_WPREV_W + c]))
                       if hs[H_WPREV_SET + c] else None)
        h.acked[c] = bool(hs[H_ACKED + c])
    h.f_innov.y = float(hs[H_F_INNOV])
    h.pressure_plausible, h.implausible_samples = bool(hs[H_PLAUSIBLE]), int(hs[H_IMPLAUSIBLE])
    mgr.t, mgr.seq = float(g[G_T]), int(g[G_SEQ])


@njit(cache=True)
def hysteresis(mk, ms, c, j, t, value, judge) -> None:
    """Hysteresis.update: trip above ``trip`` held ``trip_time``, clear below ``clear`` held
    ``clear_time``."""
    ms[c, j, 1] = value
    if not (mk[c, j, 0] > 0.5 and judge and math.isfinite(value)):
        ms[c, j, 2] = math.nan
        return
    healthy = ms[c, j, 0] > 0.5
    beyond = value > mk[c, j, 1] if healthy else value < mk[c, j, 2]
    if not beyond:
        ms[c, j, 2] = math.nan
        return
    if math.isnan(ms[c, j, 2]):
        ms[c, j, 2] = t
    if t - ms[c, j, 2] >= (mk[c, j, 3] if healthy else mk[c, j, 4]) - 1e-9:
        ms[c, j, 0] = 0.0 if healthy else 1.0
        ms[c, j, 2] = math.nan


@njit(cache=True)
def lowpass(a, y, u):
    """LowPass.__call__: y <- a y + (1 - a) u."""
    return a * y + (1.0 - a) * u


@njit(cache=True)
def health(k, mk, ms, hs, t, speed_ref, w_meas, i_meas, pa, pb, reported, fault, innovation,
           estimate_ok, cmd, steady, age) -> None:
    """HealthMonitor.update with loop_ok = True and an exact speed reference (batch)."""
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
        rep = reported[c]
        if rep == on:
            hs[H_ACKED + c] = 1.0
        acked = hs[H_ACKED + c] > 0.5
        mismatch = rep != on and (acked or age[c] > k[K_GRACE])
        leaking = acked and not on and abs(i) > k[K_STANDBY]
        hysteresis(mk, ms, c, M_DRIVE, t, 1.0 if (fault[c] or mismatch or leaking) else 0.0,
                   True)
        hysteresis(mk, ms, c, M_CURRENT, t, abs(i) / k[K_IMAX], on)
        limited = abs(i) >= k[K_LIMFRAC] * k[K_IMAX]
        lo = hi = speed_ref
        if not on:
            lo = hi = 0.0
        err = lo - w if w < lo else (hi - w if w > hi else 0.0)
        hs[H_F_SPEED + c] = lowpass(k[K_A_SPEED + c], hs[H_F_SPEED + c], err)
        hysteresis(mk, ms, c, M_SPEED, t, abs(hs[H_F_SPEED + c]), steady[c] and not limited)
        dt = t - hs[H_WPREV_T + c] if hs[H_WPREV_SET + c] > 0.5 else 0.0
        dw = (w - hs[H_WPREV_W + c]) / dt if dt > 0.0 else 0.0
        hs[H_WPREV_T + c] = t
        hs[H_WPREV_W + c] = w
        hs[H_WPREV_SET + c] = 1.0
        r = (k[K_KT] * i - k[K_B] * w - k[K_J] * dw) / k[K_DP] - p_d
        hs[H_F_PRESS + c] = lowpass(k[K_A_PRESS + c], hs[H_F_PRESS + c], r)
        hysteresis(mk, ms, c, M_PRESSURE, t, abs(hs[H_F_PRESS + c]), steady[c] and plausible)
        hysteresis(mk, ms, c, M_ESTIMATOR, t, innov, steady[c] and use)


@njit(cache=True)
def healthy(ms, c) -> bool:
    for j in range(ms.shape[1]):
        if ms[c, j, 0] < 0.5:
            return False
    return True


@njit(cache=True)
def supervise(k, mk, ms, hs, g, t, seq, speed_ref, w_meas, i_meas, pa, pb, reported, fault,
              innovation, estimate_ok, steady, age, cmd) -> bool:
    """SwitchManager.update; False when the state machine would act (a transition, a valve or
    drive step of a running switch): state to be rolled back, the tick done in Python."""
    g[G_T] = t
    g[G_SEQ] = seq
    state = int(g[G_STATE])
    a = int(g[G_ACTIVE])
    for c in range(2):
        steady[c] = ((state == ST_ACTIVE or state == ST_DEGRADED) and c == a and
                     t - g[G_ROLE_SINCE] >= k[K_BLANK])
        age[c] = t - g[G_ENABLE_SINCE + c]
        cmd[c] = g[G_ENABLE + c] > 0.5
    health(k, mk, ms, hs, t, speed_ref, w_meas, i_meas, pa, pb, reported, fault, innovation,
           estimate_ok, cmd, steady, age)
    if state == ST_FAILED:
        return True
    if state == ST_SWITCHING:       # _switching: target still available, no step due
        new = int(g[G_TARGET])
        return (ms[new, M_DRIVE, 0] > 0.5 and ms[new, M_CURRENT, 0] > 0.5 and
                g[G_NEXT_STEP] > t + 1e-9)
    if not healthy(ms, a):
        return False
    o = 1 - a
    ok_o = healthy(ms, o) and g[G_LATCHED + o] < 0.5
    want = ST_ACTIVE if ok_o else ST_DEGRADED
    return want == state
