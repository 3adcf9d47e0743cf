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
from ..kernel_records import Tensor3, Vector, entry_point
from .health import K_BLANK, ChannelSample, available, health, healthy
from .state_machine import ACTIVE, DEGRADED, FAILED_SAFE, SWITCHING, speeds_match

drop_stale(__file__)         # supervise() inlines health's and state_machine's kernels

STATES = (ACTIVE, SWITCHING, DEGRADED, FAILED_SAFE)
ST_ACTIVE, ST_SWITCHING, ST_DEGRADED, ST_FAILED = range(4)
# manager state
G_STATE, G_ACTIVE, G_ENABLE, G_ROLE_SINCE, G_ENABLE_SINCE, G_LATCHED, G_T, G_SEQ = \
    0, 1, 2, 4, 5, 7, 9, 10
G_TARGET, G_NEXT_STEP = 11, 12      # switch target, time of its next valve/drive step (inf)
G_FROM, G_MATCH = 13, 14    # the couple switched from; prespin_match while a switch waits for
NG = 15                     # the speeds to match (SwitchManager.waiting), else 0


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
    g[G_FROM] = mgr.switch_from
    g[G_MATCH] = mgr.match if mgr.waiting else 0.0
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
def supervise(a, t, seq, lo_ref, hi_ref, loop_ok, w_meas, i_meas, pa, pb, reported, fault,
              innovation, estimate_ok, steady, age, cmd) -> bool:
    """SwitchManager.update; False when the state machine would act (a transition, a valve or
    drive step of a running switch): state to be rolled back, the tick done in Python.
    ``a``: the :class:`Arrays`; lo_ref, hi_ref, loop_ok: as :func:`health` (a closed-loop
    kernel knows the reference the drives apply: lo_ref = hi_ref, loop_ok True)."""
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
    health(k, mk, ms, hs, t, lo_ref, hi_ref, w_meas, i_meas, pa, pb, reported, fault,
           innovation, estimate_ok, loop_ok, cmd, steady, age)
    if state == ST_FAILED:
        return True
    if state == ST_SWITCHING:       # _switching: target still available, no step due
        new = int(g[G_TARGET])
        if g[G_MATCH] > 0.0 and speeds_match(reported[new], w_meas[new],
                                             w_meas[int(g[G_FROM])], g[G_MATCH]):
            return False            # the valves open now
        return available(ms, new) and g[G_NEXT_STEP] > t + 1e-9
    if not healthy(ms, a):
        return False
    o = 1 - a
    ok_o = healthy(ms, o) and g[G_LATCHED + o] < 0.5
    want = ST_ACTIVE if ok_o else ST_DEGRADED
    return want == state


WINDOW = 256          # commands kept for the speed-reference band (ManagerTick)


@njit(cache=True)
def band(seqs, refs, n, scan, oldest):
    """(count, lo, hi) of the references of the newest ``scan`` of the ``n`` commands in the
    ring (seqs, refs; entry (n - 1) % WINDOW the newest) whose seq is at least ``oldest``."""
    lo, hi, count = math.inf, -math.inf, 0
    for j in range(min(scan, n, WINDOW)):
        i = (n - 1 - j) % WINDOW
        if seqs[i] >= oldest:
            r = refs[i]
            lo, hi, count = min(lo, r), max(hi, r), count + 1
    return count, lo, hi


@njit(cache=True)
def node_update(a, keep_ms, keep_hs, seqs, refs, n, scan, oldest, t, seq, speed_ref, loop_ok,
                w_meas, i_meas, pa, pb, reported, fault, innovation, estimate_ok, steady, age,
                cmd) -> bool:
    """The switch_manager node's SwitchManager.update on one state: :func:`supervise` with the
    :func:`band` of the recent commands (none: speed_ref exactly), and where it returns False
    the health state as it was before (keep_*: scratch of ms's and hs's shapes), for the
    Python state machine to take the tick."""
    count, lo, hi = band(seqs, refs, n, scan, oldest)
    if count == 0:
        lo = hi = speed_ref
    keep_ms[:] = a.ms
    keep_hs[:] = a.hs
    if supervise(a, t, seq, lo, hi, loop_ok, w_meas, i_meas, pa, pb, reported, fault,
                 innovation, estimate_ok, steady, age, cmd):
        return True
    a.ms[:] = keep_ms
    a.hs[:] = keep_hs
    return False


class ManagerTick:
    """A SwitchManager fed one state at a time from its raw fields (the switch_manager node):
    :func:`node_update` while the state machine would not act, else the Python
    ``SwitchManager.update`` on a :class:`ChannelSample` of the same values (same numbers:
    the same kernels on the same arrays). The manager's other changes go through
    :meth:`safe_state` and :meth:`request`, which re-pack its :class:`Arrays`.

    The drives may be applying any of the references of the last ``max_age`` ticks (which
    command a drive applies now is unknown, DDS latency): :meth:`command` keeps the recent
    ones, the speed monitor measures from the range of those at most ``max_age`` older than
    the state (among the newest ``2 max_age + 8``, at most WINDOW: commands come once per
    tick)."""

    def __init__(self, mgr, max_age: int):
        self.mgr = mgr
        self.a = pack(mgr)
        self.max_age, self.scan = max_age, min(WINDOW, 2 * max_age + 8)
        self.seqs, self.refs, self.n = np.zeros(WINDOW, np.int64), np.zeros(WINDOW), 0
        self.keep_ms, self.keep_hs = np.empty_like(self.a.ms), np.empty_like(self.a.hs)
        self.reported, self.fault = np.zeros(2, np.bool_), np.zeros(2, np.bool_)
        self.steady, self.cmd, self.age = np.zeros(2, np.bool_), np.zeros(2, np.bool_), \
            np.zeros(2)
        # per state from Python: the compiled function for these types (no dispatch)
        self._update = entry_point(node_update, self.a, self.keep_ms, self.keep_hs, self.seqs,
                                   self.refs, 0, 0, 0, 0.0, 0, 0.0, True, np.zeros(2),
                                   np.zeros(2), 0.0, 0.0, self.reported, self.fault, 0.0, True,
                                   self.steady, self.age, self.cmd)

    def command(self, seq: int, speed_ref: float) -> None:
        i = self.n % WINDOW
        self.seqs[i], self.refs[i] = seq, speed_ref
        self.n += 1

    def update(self, t: float, seq: int, speed_ref: float, loop_ok: bool, speed, current,
               pa: float, pb: float, enabled, fault, innovation: float,
               estimate_ok: bool) -> None:
        """One state: ``speed``, ``current`` float64 arrays of both couples (the message's
        own), ``enabled``, ``fault`` pairs of bools, ``speed_ref`` the latest command's."""
        r, f = self.reported, self.fault
        r[0], r[1], f[0], f[1] = enabled[0], enabled[1], fault[0], fault[1]
        oldest = seq - self.max_age
        if self._update(self.a, self.keep_ms, self.keep_hs, self.seqs, self.refs, self.n,
                        self.scan, oldest, t, seq, speed_ref, loop_ok, speed, current, pa, pb,
                        r, f, innovation, estimate_ok, self.steady, self.age, self.cmd):
            self.mgr.t, self.mgr.seq = t, seq
            return
        count, lo, hi = band(self.seqs, self.refs, self.n, self.scan, oldest)
        self.mgr.update(ChannelSample(t, speed_ref, tuple(speed), tuple(current), pa, pb,
                                      (bool(r[0]), bool(r[1])), (bool(f[0]), bool(f[1])),
                                      True, innovation, estimate_ok, loop_ok,
                                      (lo, hi) if count else None), seq)
        self.a = pack(self.mgr)

    def safe_state(self, reason: str) -> bool:
        entered = self.mgr.safe_state(reason)
        self.a = pack(self.mgr)
        return entered

    def request(self, channel: int, reason: str = '') -> tuple:
        out = self.mgr.request(channel, reason)
        self.a = pack(self.mgr)
        return out
