"""The position controller's per-tick operations, compiled: reference shaper (clamp, rate and
acceleration limit), prefilter F, controller G with observer-form anti-windup, speed clamp
(eqs. 4.74-4.77). This module is the implementation: PositionController and ReferenceShaper
(Python, one call per tick) and the closed-loop kernels of core.sim.closed_loop (many ticks per
call) run these same functions on the same arrays, so both paths agree bit for bit.

Scalars live in two vectors owned by the controller: constants ``k`` (K_*) and state ``c``
(C_*); F's and G's matrices and states are the DiscreteSS objects' own arrays, named in one
record (:class:`Arrays`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..jit_cache import drop_stale
from ..kernel_records import Matrix, Vector
from .discrete import ss_advance, ss_output, ss_step

drop_stale(__file__)

# constants; K_REACH: the drive's reach (rad/s) beyond the measured motor speed (0: not used);
# K_LEAK: the leakage compensation's gain alpha / D_p (rad/s per m^3/s of leak flow; 0: off)
K_LIMIT, K_STEP, K_WMAX, K_FDD, K_GDD, K_VMAX, K_ACCEL, K_TS, K_REACH, K_LEAK = range(10)
NK = 10
# state; C_R, C_E, C_U: the last tick's prefiltered reference, error, unclamped output;
# C_N_REACH: ticks the drive's reach bounded the anti-windup's actuator
(C_TARGET, C_VALUE, C_STARTED, C_CLAMPED, C_HOLD, C_N_SAT, C_N_CLAMPREF, C_RATE,
 C_R, C_E, C_U, C_N_REACH) = range(12)
NC = 12


def new_arrays(limit: float, step: float, vmax: float, accel: float, Ts: float):
    """(k, c) of a controller that has not started (no target, no value)."""
    k = np.zeros(NK)
    k[K_LIMIT], k[K_STEP], k[K_VMAX], k[K_ACCEL], k[K_TS] = limit, step, vmax, accel, Ts
    c = np.zeros(NC)
    c[C_TARGET] = math.nan
    return k, c


class Arrays(NamedTuple):
    """The prefilter's and the controller's arrays (DiscreteSS: A, B, C, state, scratch) and
    the anti-windup gain L: the PositionController's own (:func:`pack`)."""
    Fa: Matrix
    Fb: Vector
    Fc: Vector
    Fx: Vector
    Ft: Vector
    Ga: Matrix
    Gb: Vector
    Gc: Vector
    Gl: Vector
    Gx: Vector
    Gt: Vector


def pack(ctl):
    """(constants, state, arrays) of a PositionController: its own arrays, not copies."""
    F, G = ctl.F, ctl.G
    return ctl.k, ctl.s, Arrays(F._ad, F._bd, F._cd, F.x, F._tmp,
                                G._ad, G._bd, G._cd, ctl.L, G.x, G._tmp)


def unpack(ctl, c) -> None:
    """Counted events of the kernels added to the controller's counters (and cleared)."""
    for name, i in (('saturated_ticks', C_N_SAT), ('clamped_references', C_N_CLAMPREF),
                    ('drive_limited_ticks', C_N_REACH)):
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
def shape(k, c) -> float:
    """ReferenceShaper.next: one tick towards the target; returns the shaped reference.

    A target that moves at most vmax Ts per tick (a sine, a ramp) passes unchanged; a jump is a
    time-optimal move with bounded rate and acceleration: the fastest rate from which the
    reference can still stop on the target (discrete braking: from rate v, steps of a Ts cover
    v^2/(2a) + v Ts/2), reached at most a Ts per tick."""
    delta = c[C_TARGET] - c[C_VALUE]
    step = k[K_STEP]
    if k[K_ACCEL] == 0.0 or (c[C_RATE] == 0.0 and abs(delta) <= step):
        c[C_VALUE] = c[C_TARGET] if abs(delta) <= step else \
            c[C_VALUE] + math.copysign(step, delta)
        return c[C_VALUE]
    a, Ts = k[K_ACCEL], k[K_TS]
    brake = a * (math.sqrt(0.25 * Ts * Ts + 2.0 * abs(delta) / a) - 0.5 * Ts)
    want = math.copysign(min(k[K_VMAX], brake), delta)
    c[C_RATE] += max(-a * Ts, min(a * Ts, want - c[C_RATE]))
    if abs(delta) <= abs(c[C_RATE]) * Ts or abs(delta) <= a * Ts * Ts:
        c[C_VALUE] = c[C_TARGET]                        # arrived: follow from here
        c[C_RATE] = 0.0
    else:
        c[C_VALUE] += c[C_RATE] * Ts
    return c[C_VALUE]


@njit(cache=True)
def control(k, c, a, x_hat, motor_speed, q_leak):
    """PositionController.update(x_hat, motor_speed, q_leak) of a started controller; returns
    the clamped speed.

    u[k] = C x[k] + D e[k] + alpha q_L[k] / D_p,  u_s[k] = clip(u[k], +-omega_max)
    u_a[k] = clip(u_s[k], omega_m[k] -+ reach)          (what the drive can make of u_s)
    x[k+1] = A x[k] + B e[k] + L (u_a[k] - u[k])       (observer form, core.controller.antiwindup)
    Unclamped and within the drive's reach, L (u_a - u) = 0: exactly Tustin(G). The motor
    speed omega_m (the estimate's model input) bounds the actuator the anti-windup sees: the
    drive's current limit lets the motor follow a reference at most ``reach`` ahead of it
    (antiwindup.drive_reach), so a piston held, or a motor starting from rest, does not wind
    up G. A NaN speed or reach 0: the clamp only. During an integrator hold (channel switch)
    x is frozen and the output follows e through D only. alpha q_L / D_p: the leakage
    compensation, the pump speed that supplies the fraction alpha of the leak flow q_L the
    estimator reports (core.estimator.adapt.leak_flow), at once, where G would wait for the
    position error the leak causes (a NaN q_L adds nothing). ``a``: the :class:`Arrays`."""
    Fa, Fb, Fc, Fx, Ft, Ga, Gb, Gc, Gl, Gx, Gt = a
    r = ss_step(Fa, Fb, Fc, k[K_FDD], Fx, shape(k, c), Ft)
    e = r - x_hat
    u = ss_output(Gc, k[K_GDD], Gx, e)
    if k[K_LEAK] != 0.0 and math.isfinite(q_leak):
        u += k[K_LEAK] * q_leak             # D_p omega = alpha q_L
    wmax = k[K_WMAX]
    m = u if u < wmax else wmax                          # min(omega_max, u)
    u_sat = m if m > -wmax else -wmax                    # max(-omega_max, .)
    u_act = u_sat
    reach = k[K_REACH]
    if reach > 0.0 and math.isfinite(motor_speed):
        if u_act > motor_speed + reach:
            u_act = motor_speed + reach
            c[C_N_REACH] += 1
        elif u_act < motor_speed - reach:
            u_act = motor_speed - reach
            c[C_N_REACH] += 1
    if c[C_HOLD] > 0:
        c[C_HOLD] -= 1
    else:
        ss_advance(Ga, Gb, Gx, e, Gt)
        d = u_act - u
        for i in range(Gx.shape[0]):
            Gx[i] += Gl[i] * d
    clamped = (1 if u > u_sat else 0) - (1 if u < u_sat else 0)
    c[C_CLAMPED] = clamped
    if clamped != 0:
        c[C_N_SAT] += 1
    c[C_R] = r
    c[C_E] = e
    c[C_U] = u
    return u_sat
