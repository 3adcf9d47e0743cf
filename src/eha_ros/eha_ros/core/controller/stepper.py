"""PositionController.request + update as compiled calls, for closed-loop kernels
(core.closed_loop): reference shaper (clamp, rate and acceleration limit), prefilter F, Tustin integrator with
hold and conditional anti-windup, lead/lag R, speed clamp (eq. 4.74-4.77), the same operations
as the Python path. Scalars live in a state vector (C_*); F and R states are the objects' own.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit_cache import drop_stale
from .discrete import ss_step

drop_stale(__file__)

# constants
K_LIMIT, K_STEP, K_KDC, K_T, K_AW, K_WMAX, K_FDD, K_RDD, K_VMAX, K_ACCEL, K_TS = range(11)
NK = 11
# state
C_TARGET, C_VALUE, C_STARTED, C_V, C_CLAMPED, C_HOLD, C_N_SAT, C_N_CLAMPREF, C_RATE = range(9)
NC = 9


def pack(ctl):
    """(constants, state, arrays) of a PositionController; arrays are F's and R's own."""
    ref = ctl.ref
    k = np.zeros(NK)
    k[K_LIMIT], k[K_STEP], k[K_KDC], k[K_T] = ref.limit, ref.step, ctl.k_dc, ctl.T
    k[K_AW], k[K_WMAX], k[K_FDD], k[K_RDD] = ctl.antiwindup, ctl.omega_max, ctl.F._dd, ctl.R._dd
    k[K_VMAX], k[K_ACCEL], k[K_TS] = ref.vmax, ref.accel, ref.Ts
    c = np.zeros(NC)
    c[C_TARGET] = ref.target if ref.target is not None else math.nan
    c[C_STARTED] = ref.value is not None
    c[C_VALUE] = ref.value if ref.value is not None else 0.0
    c[C_V], c[C_CLAMPED], c[C_HOLD] = ctl.v, ctl.clamped, ctl.hold
    c[C_RATE] = ref.rate
    F, R = ctl.F, ctl.R
    arrays = (F._ad, F._bd, F._cd, F.x, F._tmp, R._ad, R._bd, R._cd, R.x, R._tmp)
    return k, c, arrays


def unpack(ctl, c) -> None:
    """Scalars back into the controller; counted events added to its counters."""
    ctl.ref.target = float(c[C_TARGET]) if math.isfinite(c[C_TARGET]) else None
    ctl.ref.value = float(c[C_VALUE]) if c[C_STARTED] else None
    ctl.v, ctl.clamped, ctl.hold = float(c[C_V]), int(c[C_CLAMPED]), int(c[C_HOLD])
    ctl.ref.rate = float(c[C_RATE])
    for name, i in (('saturated_ticks', C_N_SAT), ('clamped_references', C_N_CLAMPREF)):
        if c[i]:
            ctl.c.bump(name, int(c[i]))
            c[i] = 0.0


@njit(cache=True)
def ready(c, reference) -> bool:
    """Started and a finite reference (a rejected one is counted by Python)."""
    return c[C_STARTED] > 0.5 and math.isfinite(reference)


@njit(cache=True)
def request(k, c, position) -> None:
    """ReferenceShaper.request of a finite reference: clamp to the stroke (counted)."""
    if abs(position) > k[K_LIMIT]:
        c[C_N_CLAMPREF] += 1
        position = math.copysign(k[K_LIMIT], position)
    c[C_TARGET] = position


@njit(cache=True)
def shape(k, c) -> None:
    """ReferenceShaper.next: rate limit, or the acceleration-limited move to a jumped target."""
    delta = c[C_TARGET] - c[C_VALUE]
    step = k[K_STEP]
    if k[K_ACCEL] == 0.0 or (c[C_RATE] == 0.0 and abs(delta) <= step):
        c[C_VALUE] = c[C_TARGET] if abs(delta) <= step else \
            c[C_VALUE] + math.copysign(step, delta)
        return
    a, Ts = k[K_ACCEL], k[K_TS]
    brake = a * (math.sqrt(0.25 * Ts * Ts + 2.0 * abs(delta) / a) - 0.5 * Ts)
    want = math.copysign(min(k[K_VMAX], brake), delta)
    c[C_RATE] += max(-a * Ts, min(a * Ts, want - c[C_RATE]))
    if abs(delta) <= abs(c[C_RATE]) * Ts or abs(delta) <= a * Ts * Ts:
        c[C_VALUE] = c[C_TARGET]
        c[C_RATE] = 0.0
    else:
        c[C_VALUE] += c[C_RATE] * Ts


@njit(cache=True)
def control(k, c, Fa, Fb, Fc, Fx, Ft, Ra, Rb, Rc, Rx, Rt, x_hat):
    """PositionController.update(x_hat).speed_ref of a started controller."""
    shape(k, c)
    r = ss_step(Fa, Fb, Fc, k[K_FDD], Fx, c[C_VALUE], Ft)
    e = r - x_hat
    w = k[K_KDC] * e
    if c[C_HOLD] > 0:
        c[C_HOLD] -= 1
        w = 0.0
    elif k[K_AW] > 0.5 and c[C_CLAMPED] * w > 0:
        w = 0.0
    v_out = c[C_V] + 0.5 * k[K_T] * w
    c[C_V] += k[K_T] * w
    u = ss_step(Ra, Rb, Rc, k[K_RDD], Rx, v_out, Rt)
    wmax = k[K_WMAX]
    m = u if u < wmax else wmax                          # min(omega_max, u)
    u_sat = m if m > -wmax else -wmax                    # max(-omega_max, .)
    clamped = (1 if u > u_sat else 0) - (1 if u < u_sat else 0)
    c[C_CLAMPED] = clamped
    if clamped != 0:
        c[C_N_SAT] += 1
    return u_sat
