"""The plant side's command gate (no I/O, time passed in): arming, the one saturation, rate
limit, command timeout, link-loss latch. A backend only ever sees :meth:`CommandGate.speed_output`.

- Unarmed (the start state: the node not ACTIVE), stale device data, commands stopped for
  ``timeout`` or a latched link fault: the speed reference is 0 at once (a stop is never rate
  limited; the drive ramps it).
- Armed: the latest good command, saturated at ``max_speed`` (plant.drive.omega_max) and rate
  limited at ``max_rate`` (rad/s^2), starting from 0 on arming.
- Arming (the lifecycle's activate) needs: link up, no latched link fault, fresh data, no
  drive fault on the active couple, and |latest command| <= ``arm_max_command`` (no jump).
- Link loss disarms and latches; :meth:`reset` clears the latch once the link is back and the
  data fresh. Arming again is a separate, explicit step.
"""
from __future__ import annotations

import math

from ..stats import Counters


class CommandGate:
    """Speed command gate between the controller and the hardware (every backend)."""

    def __init__(self, max_speed: float, max_rate: float, timeout: float,
                 arm_max_command: float, counters: Counters | None = None):
        self.max_speed = max_speed
        self.max_rate = max_rate
        self.timeout = timeout
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
        self.command_seq = None          # its seq (the state it answers)
        self.stale = False               # commands stopped for longer than timeout
        self.disarm_reason = ''          # why the last arming ended
        self.out = 0.0                   # last speed reference sent (rad/s)

    # ------------------------------------------------------------ inputs
    def set_command(self, value: float, now: float, seq: int | None = None) -> bool:
        """A command from the controller; non-finite ones are rejected (last good kept)."""
        if not math.isfinite(value):
            self.c.bump('rejected_commands')
            return False
        if abs(value) > self.max_speed:
            self.c.bump('saturated_commands')
            value = math.copysign(self.max_speed, value)
        self.command, self.command_time, self.command_seq = float(value), now, seq
        return True

    def set_link(self, up: bool, reason: str = ''):
        """Link state from the loop; a loss disarms and latches a fault."""
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
            return 'no link to the drive'
        if not self.fresh:
            return 'the drive\'s data is stale'
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
            self.disarm_reason = reason
        return True, f'disarmed ({reason})' if was else 'already disarmed'

    def reset(self) -> tuple[bool, str]:
        """Clear a latched link fault once the link is back with fresh data."""
        if not self.link_fault:
            return True, 'no latched fault'
        if not self.link_up:
            return False, 'reset refused: the link is still down'
        if not self.fresh:
            return False, 'reset refused: the drive\'s data is stale'
        self.link_fault = False
        self.link_fault_reason = ''
        self.c.bump('resets')
        return True, 'link fault reset; activate (arm) again to move'

    # ------------------------------------------------------------ output
    def commands_stale(self, now: float) -> bool:
        """True while commands have stopped for longer than ``timeout`` (counted per event)."""
        t = self.command_time
        stale = t is not None and now - t > self.timeout
        if stale and not self.stale:
            self.c.bump('command_timeouts')
        self.stale = stale
        return stale

    def speed_output(self, now: float, dt: float) -> float:
        """Speed reference to write this tick (rad/s)."""
        stop = (not self.armed or self.link_fault or not self.link_up or not self.fresh or
                self.commands_stale(now) or self.command_time is None)
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
