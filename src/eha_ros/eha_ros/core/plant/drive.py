"""Servo drive (AX5118): velocity PI + low-pass (eq. 4.65/4.71) and current PI (eq. 3.34)."""
import math

import numpy as np
from numba import njit

from . import layout as L


@njit(cache=True, error_model='numpy')
def clamp(x, lo, hi):
    return lo if x < lo else (hi if x > hi else x)


@njit(cache=True, error_model='numpy')
def speed_pi(S, b, w_ref, P):
    """Current reference (A) from G_v = (1/k_T)(Kp_w + Ki_w/s)/(s/K_3 + 1), eq. 4.71.

    Discrete at the drive period: exact low-pass for a held input, forward-Euler integral
    with conditional anti-windup, reference clamped to +-I_max (filter state clamped too).
    """
    Td = P[L.P_TD]
    i_max = P[L.P_IMAX]
    w_ref = clamp(w_ref, -P[L.P_WMAX], P[L.P_WMAX])
    e = w_ref - S[b + L.C_W]
    u = (P[L.P_KPW] * e + P[L.P_KIW] * S[b + L.C_IW]) / P[L.P_KT]
    a = P[L.P_EXP_LP]
    i_f = a * S[b + L.C_IF] + (1.0 - a) * u
    if not ((i_f >= i_max and e > 0.0) or (i_f <= -i_max and e < 0.0)):
        S[b + L.C_IW] += Td * e
    i_f = clamp(i_f, -i_max, i_max)
    S[b + L.C_IF] = i_f
    return i_f


@njit(cache=True, error_model='numpy')
def current_pi(S, b, i_ref, P):
    """Voltage from the current PI of eq. 3.34, +-V_max with conditional anti-windup.

    DC model: one loop on i. d-q model: the same PI on i_q (reference i_ref) and on i_d
    (reference 0), voltage vector magnitude limited to V_max.
    """
    Td = P[L.P_TD]
    kp = P[L.P_KPI]
    ki = P[L.P_KII]
    v_max = P[L.P_VMAX]
    e_q = i_ref - S[b + L.C_I]
    v_q = kp * e_q + ki * S[b + L.C_IIQ]
    if P[L.P_DQ] > 0.5:
        e_d = -S[b + L.C_ID]
        v_d = kp * e_d + ki * S[b + L.C_IID]
        mag = math.sqrt(v_q * v_q + v_d * v_d)
        if mag > v_max:
            v_q *= v_max / mag
            v_d *= v_max / mag
        else:
            S[b + L.C_IIQ] += Td * e_q
            S[b + L.C_IID] += Td * e_d
        S[b + L.C_VD] = v_d
        S[b + L.C_VQ] = v_q
        return
    if v_q > v_max:
        v_q = v_max
        if e_q < 0.0:
            S[b + L.C_IIQ] += Td * e_q
    elif v_q < -v_max:
        v_q = -v_max
        if e_q > 0.0:
            S[b + L.C_IIQ] += Td * e_q
    else:
        S[b + L.C_IIQ] += Td * e_q
    S[b + L.C_VQ] = v_q


@njit(cache=True, error_model='numpy')
def disable(S, b):
    """Drive off (disabled or motor fault): bridge open, zero current, integrators reset."""
    S[b + L.C_I] = 0.0
    S[b + L.C_ID] = 0.0
    S[b + L.C_IIQ] = 0.0
    S[b + L.C_IID] = 0.0
    S[b + L.C_IW] = 0.0
    S[b + L.C_IF] = 0.0
    S[b + L.C_VQ] = 0.0
    S[b + L.C_VD] = 0.0


@njit(cache=True)
def delay_push(ring, head, n, w_ref):
    """Drive delay FIFO of n whole ticks on a ring (head[0]: index of the oldest entry):
    insert this tick's reference, return the one applied now (n = 0: itself)."""
    if n == 0:
        return w_ref
    h = int(head[0])
    w = ring[h]
    ring[h] = w_ref
    head[0] = (h + 1) % n
    return w


class SpeedDelay:
    """Drive delay on the speed reference: a FIFO of whole ticks (0 = none) as a ring that the
    plant's compiled step advances with :func:`delay_push`."""

    def __init__(self, ticks: int, head=None):
        """head: a one-element array for the ring index (the plant's aux vector); its own
        when not given."""
        self.ticks = ticks
        self.ring = np.empty(max(ticks, 1))
        self.head = head if head is not None else np.zeros(1)
        self.clear()

    def clear(self) -> None:
        """Empty FIFO (zeros) in the same ring (the plant's kernel record holds it)."""
        self.ring[:] = 0.0
        self.head[0] = 0.0
