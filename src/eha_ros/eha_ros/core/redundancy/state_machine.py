"""Switch state machine of the dual motor-pump EHA (thesis 3.4, Fig. 3.12, Fig. 3.17).

States: ACTIVE (reported ACTIVE_A / ACTIVE_B: active couple healthy, standby healthy),
SWITCHING (valve sequence running), DEGRADED (active healthy, standby not: no redundancy left),
FAILED_SAFE (both couples failed).

Valve/drive sequence of a switch old -> new (on-off valves at each pump's inlet and outlet,
Fig. 3.12; opening time T_v = plant.valves.onoff_time):
  t = 0           new drive enabled, its valves still closed: it spins up unloaded to the same
                  speed reference ("pre-spin"); for an automatic switch the faulty drive is
                  disabled here and the pre-spin is normally 0 (isolate at once).
  t = T_pre       channel := new; new valves open and old valves close together: the two
                  fractions cross over, so the total pump displacement seen by the piston
                  stays D_p (same speed on both shafts) and the flow hand-over is smooth.
                  A commanded switch: T_pre is the first sample on which the new drive reports
                  enabled and its speed is within switch.prespin_match of the old one's, at
                  most switch.prespin_time (the estimator's model input, the active couple's
                  speed, then stays the pump's: docs/nodes/switch_manager.md).
  t = T_pre+T_v+m old drive disabled (its valves are closed): switch complete.

Safe state (both failed), ``switch.safe_mode``:
  hold (default): both drives disabled, all pump valves closed, bypass closed. The chambers
      are sealed: hydraulic lock, the piston holds its last position and creeps only by the
      cross-piston leakage (C_c dp/A_p: about 0.8 mm/s under 10 kN). A failed (back-drivable)
      pump with open valves would instead let the load drive the piston at pump speed.
      A single actuator per surface on this bench: a locked surface is the safe choice.
  bypass: drives disabled, pump valves closed, A-B bypass open: the piston is free and damped
      (the flight-control "damped bypass" mode when another actuator on the same surface
      takes over); under load it moves to the end stop.
The safe state is latched: only a commanded switch to a couple whose drive and current are
healthy leaves it, so there is no switching back and forth between two failed couples.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from numba import njit

from .events import SwitchEvent
from .health import ChannelSample, HealthMonitor

ACTIVE, SWITCHING, DEGRADED, FAILED_SAFE = 'ACTIVE', 'SWITCHING', 'DEGRADED', 'FAILED_SAFE'
NAMES = ('A', 'B')
# the state names of name() as numbers, for recorded arrays (batch, campaigns)
STATE_CODES = {'ACTIVE_A': 0, 'ACTIVE_B': 1, 'SWITCHING': 2, 'DEGRADED': 3, 'FAILED_SAFE': 4}


@njit(cache=True)
def speeds_match(enabled_new: bool, w_new: float, w_old: float, tolerance: float) -> bool:
    """A commanded switch's pre-spin is over: the new couple's drive reports enabled and its
    measured speed is within ``tolerance`` (switch.prespin_match) of the old couple's (a
    non-finite speed never matches). SwitchManager and its compiled tick (stepper) both ask
    here."""
    return enabled_new and abs(w_new - w_old) <= tolerance


def state_name(state: str, channel: int) -> str:
    """Reported state: ACTIVE_A / ACTIVE_B for ACTIVE, the state itself otherwise."""
    return f'ACTIVE_{NAMES[channel]}' if state == ACTIVE else state


def _pair(c: int, value: bool = True) -> tuple:
    return (value if c == 0 else not value, value if c == 1 else not value)


@dataclass(frozen=True)
class Select:
    """Contents of eha_msgs/ChannelSelect."""

    channel: int
    drive_enable: tuple
    valve_open: tuple
    bypass_open: bool = False

    @classmethod
    def only(cls, c: int) -> 'Select':
        return cls(c, _pair(c), _pair(c), False)


class SwitchManager:
    """Core of the switch_manager node; ``update(sample)`` once per /eha/state."""

    def __init__(self, p: dict):
        s = 'switch.'
        self.p = p
        self.Ts = p['plant.sim.Ts']
        self.valve_time = p['plant.valves.onoff_time']
        self.prespin = p[s + 'prespin_time']
        self.match = p[s + 'prespin_match']
        self.fault_prespin = p[s + 'fault_prespin_time']
        self.margin = p[s + 'valve_margin']
        self.blank = p[s + 'blank_time']
        self.min_dwell = p[s + 'min_dwell']
        self.latch_failed = p[s + 'latch_failed']
        self.safe_mode = p[s + 'safe_mode']
        self.reset(p[s + 'initial_channel'])

    def reset(self, channel: int = 0):
        self.health = HealthMonitor(self.p)
        self.state = ACTIVE
        self.select = Select.only(channel)
        self.t, self.seq = 0.0, 0
        self.steps: list[tuple[float, Select]] = []
        self.target = channel
        self.commanded = False
        self.switch_from = channel
        self.switch_t0 = 0.0
        self.open_t = 0.0            # time the new couple's valves were told to open
        self.switch_count = 0
        self.latched = [False, False]
        self.last_auto = -math.inf
        self.role_since = -math.inf          # time the active couple became the steady driver
        self.enable_since = [-math.inf, -math.inf]
        self.reason = 'start'
        self.events: list[SwitchEvent] = []
        # the pressure residual that switched away from each couple (NaN: none) and whether
        # the shared pressure sensors have been found faulty (pressure monitor off)
        self.pressure_trip = [math.nan, math.nan]
        self.pressure_sensor_fault = False

    # ------------------------------------------------------------------ queries
    @property
    def active(self) -> int:
        return self.select.channel

    @property
    def name(self) -> str:
        return state_name(self.state, self.active)

    def ok(self, c: int) -> bool:
        """Couple c may drive: all monitors healthy and not latched failed."""
        return self.health.healthy(c) and not self.latched[c]

    @property
    def channel_healthy(self) -> list[bool]:
        return [self.ok(0), self.ok(1)]

    # ------------------------------------------------------------------ per tick
    @property
    def waiting(self) -> bool:
        """A commanded switch's pre-spin runs with speed matching on: its valve change-over
        (steps[0]) not applied yet."""
        return self.commanded and self.match > 0.0 and len(self.steps) == 2

    def matched(self, s: ChannelSample) -> bool:
        """:func:`speeds_match` of this switch's couples on sample s (its Python source: no
        compile or cache load at a node's first switch)."""
        new, old = self.target, self.switch_from
        return speeds_match.py_func(bool(s.drive_enabled[new]), float(s.motor_speed[new]),
                                    float(s.motor_speed[old]), self.match)

    def update(self, s: ChannelSample, seq: int = 0) -> bool:
        """One measured state; returns True when the channel select changed."""
        self.t, self.seq = s.t, seq
        before = self.select
        steady = [self.state in (ACTIVE, DEGRADED) and c == self.active and
                  s.t - self.role_since >= self.blank for c in range(2)]
        age = [s.t - self.enable_since[c] for c in range(2)]
        self.health.update(s, self.select.drive_enable, steady, age)
        if self.state == SWITCHING:
            self._switching(s)
        elif self.state in (ACTIVE, DEGRADED):
            self._supervise()
        return self.select != before

    def _supervise(self):
        a, o = self.active, 1 - self.active
        if not self.health.healthy(a):
            if self._pressure_sensors_faulty(a, o):
                return
            why = f'channel {NAMES[a]} unhealthy: {self.health.why(a)}'
            if self.ok(o):
                if self.t - self.last_auto >= self.min_dwell - 1e-9:
                    self._start(o, why, commanded=False)
            else:
                self._safe(f'{why}; channel {NAMES[o]} not available: '
                           f'{self._why_not(o)}')
            return
        want = ACTIVE if self.ok(o) else DEGRADED
        if want != self.state:
            kind = 'restored' if want == ACTIVE else 'degraded'
            why = (f'channel {NAMES[o]} healthy again' if want == ACTIVE else
                   f'standby channel {NAMES[o]} not available: {self._why_not(o)}')
            self._transition(want, kind, why, a, a)

    def _pressure_sensors_faulty(self, a: int, o: int) -> bool:
        """Both couples failed on the pressure monitor alone, the residual on the active one of
        the sign and within a factor 2 of the one that switched away from the other: the
        torque balance of eq. 3.17 is wrong on both through what they share, the chamber
        pressure sensors (a couple's own fault shows on that couple only). The pressure
        monitor goes off on both couples, the standby is cleared, the active one keeps
        driving; reported as a ``sensor_fault`` event."""
        h = self.health
        trip = self.pressure_trip[o]
        if not (h.failed(a) == ['pressure'] == h.failed(o) and math.isfinite(trip)):
            return False
        r = h.pressure_residual(a)
        if not (r * trip > 0.0 and 0.5 <= r / trip <= 2.0):
            return False
        h.disable('pressure')
        self.latched[o] = False
        self.pressure_trip = [math.nan, math.nan]
        self.pressure_sensor_fault = True
        self._transition(ACTIVE if self.ok(o) else DEGRADED, 'sensor_fault',
                         f'channels A and B both failed the pressure monitor alone (residual '
                         f'{trip:.3g} Pa on {NAMES[o]}, {r:.3g} Pa on {NAMES[a]}): the '
                         f'pressure sensors they share; pressure monitor off, channel '
                         f'{NAMES[a]} keeps driving', a, a)
        return True

    def _switching(self, s: ChannelSample):
        new, old = self.target, self.switch_from
        if not self.health.available(new):
            why = f'channel {NAMES[new]} failed during the switch: {self.health.why(new)}'
            self.latched[new] = self.latch_failed or self.latched[new]
            if self.ok(old) and self.health.available(old):
                self._start(old, why, commanded=False)
            else:
                self._safe(why)
            return
        waiting = self.waiting
        if waiting and self.matched(s):              # the valves open now, not at the cap
            (_, s1), (_, s2) = self.steps
            self.steps = [(self.t, s1), (self.t + self.valve_time + self.margin, s2)]
        self._apply_due()
        if waiting and not self.waiting:
            self.open_t = self.t
        if not self.steps:
            self.role_since = self.t
            state = ACTIVE if self.ok(1 - new) else DEGRADED
            self._transition(state, 'switch_done',
                             f'switch {NAMES[old]} -> {NAMES[new]} complete after '
                             f'{(self.t - self.switch_t0) * 1e3:.0f} ms (valves opened after '
                             f'{(self.open_t - self.switch_t0) * 1e3:.0f} ms)', old, new)

    # ------------------------------------------------------------------ commands
    def request(self, channel: int, reason: str = '') -> tuple[bool, str]:
        """Commanded switch (/eha/switch_channel); returns (accepted, message)."""
        reason = reason.strip() or 'commanded'
        if channel not in (0, 1):
            return False, f'channel {channel!r}: expected 0 (A) or 1 (B)'
        if self.state == SWITCHING:
            return self._refuse(channel, reason, f'a switch to {NAMES[self.target]} is in '
                                                 f'progress')
        if channel == self.active and self.state != FAILED_SAFE:
            return True, f'channel {NAMES[channel]} is already active ({self.name})'
        if not self.health.available(channel):
            return self._refuse(channel, reason, f'channel {NAMES[channel]} not available: '
                                                 f'{self.health.why(channel)}')
        self.latched[channel] = False
        self.health.rearm(channel)
        self._start(channel, f'commanded: {reason}', commanded=True)
        return True, (f'switching {NAMES[self.switch_from]} -> {NAMES[channel]} '
                      f'(switch {self.switch_count})')

    # ------------------------------------------------------------------ actions
    def _start(self, new: int, why: str, commanded: bool):
        old = self.active
        prespin = self.prespin if commanded else self.fault_prespin
        cur = self.select
        en = list(cur.drive_enable)
        en[new] = True
        if not commanded:
            en[old] = False                  # the faulty couple's drive goes off at once
            self.last_auto = self.t
            self.pressure_trip[old] = (self.health.pressure_residual(old)
                                       if self.health.failed(old) == ['pressure'] else math.nan)
            if self.latch_failed and old != new:
                self.latched[old] = True
        t0 = self.t
        s0 = Select(old, tuple(en), cur.valve_open, cur.bypass_open)
        s1 = Select(new, tuple(en), _pair(new), False)
        # pre-spin: s0 (the new drive on, its valves closed) until t0 + prespin, then s1 (the
        # valves change over); a commanded switch opens them sooner, once the speeds match
        self.steps = [(t0, s0), (t0 + prespin, s1),
                      (t0 + prespin + self.valve_time + self.margin, Select.only(new))]
        from_state = self.name
        self.target, self.switch_from, self.switch_t0 = new, old, t0
        self.open_t = t0 + prespin
        self.commanded = commanded
        self.switch_count += 1
        self.state = SWITCHING
        self._apply_due()
        self._event('switch_start', from_state, old, new, why)

    def _safe(self, why: str):
        from_state = self.name
        self.steps = []
        self._set(Select(self.active, (False, False), (False, False),
                         self.safe_mode == 'bypass'))
        self.state = FAILED_SAFE
        self._event('safe', from_state, self.active, self.active,
                    f'{why}; safe state {self.safe_mode}')

    def safe_state(self, why: str) -> bool:
        """The loop cannot be trusted (a position fault, core.loop.safe_state; the loop supervisor,
        core.loop.supervisor): the safe state, latched like both couples failed. Returns True when
        this call entered it."""
        if self.state == FAILED_SAFE:
            return False
        self._safe(why)
        return True

    def _refuse(self, channel: int, reason: str, why: str) -> tuple[bool, str]:
        self._event('refused', self.name, self.active, channel,
                    f'commanded switch to {NAMES[channel]} ({reason}) refused: {why}',
                    commanded=True, keep_reason=True)
        return False, why

    def _transition(self, state: str, kind: str, why: str, old: int, new: int):
        from_state = self.name
        self.state = state
        self._event(kind, from_state, old, new, why)

    def _apply_due(self):
        while self.steps and self.steps[0][0] <= self.t + 1e-9:
            self._set(self.steps.pop(0)[1])

    def _set(self, sel: Select):
        for c in range(2):
            if sel.drive_enable[c] != self.select.drive_enable[c]:
                self.enable_since[c] = self.t
                self.health.command_changed(c)
        self.select = sel

    def _why_not(self, c: int) -> str:
        if self.latched[c] and self.health.healthy(c):
            return 'latched failed (command a switch to it to retry)'
        return self.health.why(c)

    def _event(self, kind, from_state, old, new, why, commanded=None, keep_reason=False):
        if not keep_reason:
            self.reason = why
        ev = SwitchEvent(
            t=round(self.t, 9), seq=int(self.seq), kind=kind, from_state=from_state,
            to_state=self.name, from_channel=int(old), to_channel=int(new), reason=why,
            commanded=self.commanded if commanded is None else commanded,
            switch_count=self.switch_count,
            health={NAMES[c]: self.health.figures(c) for c in range(2)})
        self.events.append(ev)
