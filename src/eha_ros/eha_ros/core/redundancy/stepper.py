"""SwitchManager.update as a compiled call while it would change nothing, for closed-loop
kernels (core.sim.closed_loop): the health monitors' own kernel (core.redundancy.health.health,
on the HealthMonitor's own arrays) and the check that the state machine stays put. Anything
else -- a switch running, a transition due, a command -- is the Python state machine's tick.
A running switch is followed here between its valve/drive steps (nothing changes then).

The health arrays are the HealthMonitor's (k is a copy with the manager's blanking time);
the manager's scalars are in the G_* vector; :func:`pack` / :func:`unpack` move them. The
kernel takes them as one named record (:class:`Arrays`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..jit_cache import drop_stale
from ..kernel_records import Tensor3, Vector
from .health import K_BLANK, available, health, healthy
from .state_machine import ACTIVE, DEGRADED, FAILED_SAFE, SWITCHING

drop_stale(__file__)         # supervise() inlines health's kernels

STATES = (ACTIVE, SWITCHING, DEGRADED, FAILED_SAFE)
ST_ACTIVE, ST_SWITCHING, ST_DEGRADED, ST_FAILED = range(4)
# manager state
G_STATE, G_ACTIVE, G_ENABLE, G_ROLE_SINCE, G_ENABLE_SINCE, G_LATCHED, G_T, G_SEQ = \
    0, 1, 2, 4, 5, 7, 9, 10
G_TARGET, G_NEXT_STEP = 11, 12      # switch target, time of its next valve/drive step (inf)
NG = 13


class Arrays(NamedTuple):
    """The switch manager's arrays the kernel works on (:func:`pack`)."""
    k: Vector           # the HealthMonitor's constants, a copy with the blanking time
    mk: Tensor3         # per channel and monitor: the monitors' constants
    ms: Tensor3         # per channel and monitor: their state
    hs: Vector          # the HealthMonitor's state
    g: Vector           # the manager's scalars (G_*)


def pack(mgr) -> Arrays:
    """The manager's :class:`Arrays`: the HealthMonitor's own (k: a copy with the blanking
    time) and a new manager vector."""
    h = mgr.health
    k = h.k.copy()
    k[K_BLANK] = mgr.blank
    g = np.zeros(NG)
    g[G_STATE], g[G_ACTIVE] = STATES.index(mgr.state), mgr.active
    g[G_ROLE_SINCE], g[G_T], g[G_SEQ] = mgr.role_since, mgr.t, mgr.seq
    g[G_TARGET] = mgr.target
    g[G_NEXT_STEP] = mgr.steps[0][0] if mgr.steps else math.inf
    for c in range(2):
        g[G_ENABLE + c] = mgr.select.drive_enable[c]
        g[G_ENABLE_SINCE + c] = mgr.enable_since[c]
        g[G_LATCHED + c] = mgr.latched[c]
    return Arrays(k, h.mk, h.ms, h.hs, g)


def unpack(mgr, a: Arrays) -> None:
    """Time and seq back into the manager (the health state is its own arrays already;
    nothing else changes in a segment)."""
    mgr.t, mgr.seq = float(a.g[G_T]), int(a.g[G_SEQ])


@njit(cache=True)
def supervise(a, t, seq, speed_ref, w_meas, i_meas, pa, pb, reported, fault, innovation,
              estimate_ok, steady, age, cmd) -> bool:
    """SwitchManager.update; False when the state machine would act (a transition, a valve or
    drive step of a running switch): state to be rolled back, the tick done in Python.
    ``a``: the :class:`Arrays`."""
    k, mk, ms, hs, g = a.k, a.mk, a.ms, a.hs, a.g
    g[G_T] = t
    g[G_SEQ] = seq
    state = int(g[G_STATE])
    a = int(g[G_ACTIVE])
    for c in range(2):
        steady[c] = ((state == ST_ACTIVE or state == ST_DEGRADED) and c == a and
                     t - g[G_ROLE_SINCE] >= k[K_BLANK])
        age[c] = t - g[G_ENABLE_SINCE + c]
        cmd[c] = g[G_ENABLE + c] > 0.5
    health(k, mk, ms, hs, t, speed_ref, speed_ref, w_meas, i_meas, pa, pb, reported, fault,
           innovation, estimate_ok, True, cmd, steady, age)
    if state == ST_FAILED:
        return True
    if state == ST_SWITCHING:       # _switching: target still available, no step due
        new = int(g[G_TARGET])
        return available(ms, new) and g[G_NEXT_STEP] > t + 1e-9
    if not healthy(ms, a):
        return False
    o = 1 - a
    ok_o = healthy(ms, o) and g[G_LATCHED + o] < 0.5
    want = ST_ACTIVE if ok_o else ST_DEGRADED
    return want == state
