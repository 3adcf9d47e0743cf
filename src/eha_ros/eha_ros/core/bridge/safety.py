"""Bridge safety logic (no I/O, time passed in): arming, command limits, watchdog, staleness,
link-loss latch. The drive only ever sees :meth:`Safety.speed_output`.

- Unarmed (the start state), stale data, a tripped watchdog or a latched link fault: the
  speed reference is 0 at once (a stop is never rate limited; the drive ramps it).
- Armed: the latest good command, saturated at ``max_speed`` and rate limited at
  ``max_rate`` (rad/s^2), starting from 0 on arming.
- Arming needs: link up, no latched link fault, fresh data, no drive fault on the active
  couple, and |latest command| <= ``arm_max_command`` (no jump on arming).
- Link loss disarms and latches; :meth:`reset` clears the latch once the link is back and the
  data fresh. Arming again is a separate, explicit step.
"""
from __future__ import annotations

import math

from ..stats import Counters


class Safety:
    """Speed command gate between the controller and the PLC."""

    def __init__(self, max_speed: float, max_rate: float, watchdog_time: float,
                 arm_max_command: float, counters: Counters | None = None):
        self.max_speed = max_speed
        self.max_rate = max_rate
        self.watchdog_time = watchdog_time
        self.arm_max_command = arm_max_command
        self.c = counters if counters is not None else Counters()
        self.armed = False
        self.link_up = False
        self.link_fault = False          # latched on link loss until reset()
        self.link_fault_reason = ''
        self.fresh = False
        self.drive_fault = False         # the active couple's drive reports a fault
        self.command = 0.0               # latest good command, saturated (rad/s)
        self.command_time = None         # when it arrived (s, caller's clock)
        self.watchdog_tripped = False
        self.out = 0.0                   # last speed reference sent (rad/s)

    # ------------------------------------------------------------ inputs
    def set_command(self, value: float, now: float) -> bool:
        """A command from the controller; non-finite ones are rejected (last good kept)."""
        if not math.isfinite(value):
            self.c.bump('rejected_commands')
            return False
        if abs(value) > self.max_speed:
            self.c.bump('saturated_commands')
            value = math.copysign(self.max_speed, value)
        self.command, self.command_time = float(value), now
        return True

    def set_link(self, up: bool, reason: str = ''):
        """Link state from the I/O thread; a loss disarms and latches a fault."""
        if self.link_up and not up:
            self.link_fault = True
            self.link_fault_reason = reason or 'link lost'
            self.c.bump('link_losses')
            self.disarm('link lost')
        self.link_up = up
        if not up:
            self.fresh = False

    def set_data(self, fresh: bool, drive_fault: bool = False):
        self.fresh = fresh
        self.drive_fault = drive_fault

    # ------------------------------------------------------------ operator
    def arm_refusal(self) -> str:
        """Why arming is refused now ('' = allowed)."""
        if self.link_fault:
            return f'link fault latched ({self.link_fault_reason}): reset first'
        if not self.link_up:
            return 'no ADS link to the PLC'
        if not self.fresh:
            return 'PLC data is stale'
        if self.drive_fault:
            return 'the active drive reports a fault'
        if abs(self.command) > self.arm_max_command:
            return (f'latest command {self.command:.1f} rad/s exceeds '
                    f'{self.arm_max_command:g} rad/s: bring the controller to rest first')
        return ''

    def arm(self) -> tuple[bool, str]:
        if self.armed:
            return True, 'already armed'
        why = self.arm_refusal()
        if why:
            self.c.bump('arm_refused')
            return False, f'arming refused: {why}'
        self.armed = True
        self.out = 0.0
        self.c.bump('arms')
        return True, 'armed'

    def disarm(self, reason: str = 'requested') -> tuple[bool, str]:
        was = self.armed
        self.armed = False
        self.out = 0.0
        if was:
            self.c.bump('disarms')
        return True, f'disarmed ({reason})' if was else 'already disarmed'

    def reset(self) -> tuple[bool, str]:
        """Clear a latched link fault once the link is back with fresh data."""
        if not self.link_fault:
            return True, 'no latched fault'
        if not self.link_up:
            return False, 'reset refused: the ADS link is still down'
        if not self.fresh:
            return False, 'reset refused: PLC data is stale'
        self.link_fault = False
        self.link_fault_reason = ''
        self.c.bump('resets')
        return True, 'link fault reset; arm again to move'

    # ------------------------------------------------------------ output
    def watchdog(self, now: float) -> bool:
        """True while commands have stopped for longer than watchdog_time."""
        t = self.command_time
        tripped = t is not None and now - t > self.watchdog_time
        if tripped and not self.watchdog_tripped:
            self.c.bump('watchdog_trips')
        self.watchdog_tripped = tripped
        return tripped

    def speed_output(self, now: float, dt: float) -> float:
        """Speed reference to write this cycle (rad/s)."""
        stop = (not self.armed or self.link_fault or not self.link_up or not self.fresh or
                self.watchdog(now) or self.command_time is None)
        if stop:
            self.out = 0.0
            return 0.0
        step = self.max_rate * max(dt, 0.0)
        delta = self.command - self.out
        if abs(delta) > step:
            self.c.bump('rate_limited_cycles')
            delta = math.copysign(step, delta)
        self.out += delta
        return self.out


class Staleness:
    """Age of the PLC data from its cycle counter: fresh while the counter moved within
    ``limit`` seconds and the last read succeeded."""

    def __init__(self, limit: float):
        self.limit = limit
        self.cycle = None
        self.changed_at = None

    def update(self, plc_cycle: int, now: float) -> bool:
        if plc_cycle != self.cycle:
            self.cycle, self.changed_at = plc_cycle, now
        return self.fresh(now)

    def fresh(self, now: float) -> bool:
        return self.changed_at is not None and now - self.changed_at <= self.limit

    def age(self, now: float) -> float:
        return math.inf if self.changed_at is None else now - self.changed_at
