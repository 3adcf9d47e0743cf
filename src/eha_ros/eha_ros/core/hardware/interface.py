"""What a plant-side backend offers the loop owner (ros2_control's SystemInterface, reduced to
one actuator): configure/cleanup, ``write(speed)`` then ``read()`` once per tick, and the
device's own diagnostics. Failures of a transition are :class:`HardwareError` (the reason)."""
from __future__ import annotations

from dataclasses import dataclass, field


class HardwareError(Exception):
    """A transition the hardware cannot carry out; the message is the reason (one line)."""


@dataclass
class Reading:
    """One sample of the actuator, SI units (the fields of eha_msgs/ActuatorState)."""
    position: float = 0.0
    pressure_a: float = 0.0
    pressure_b: float = 0.0
    active_channel: int = 0
    bypass_open: bool = False
    valid: bool = True                  # a new, trustworthy sample (else: predict only)
    ticks: int = 1                      # loop periods Ts this reading stands for (device cycles)
    active_fault: bool = False          # the active couple's drive reports a fault
    motor_speed: list = field(default_factory=lambda: [0.0, 0.0])
    motor_current: list = field(default_factory=lambda: [0.0, 0.0])
    valve_open: list = field(default_factory=lambda: [False, False])
    drive_enabled: list = field(default_factory=lambda: [False, False])
    drive_fault: list = field(default_factory=lambda: [False, False])


class Hardware:
    """Base of the backends. ``kind``: 'sim', 'ads' or 'mock'."""

    kind = ''
    has_truth = False                   # serves eha/sim/truth (truth())
    retry_period = 0.5                  # s between autostart configure attempts
    lost = ''                           # why the link was declared lost ('' while up)

    # ---- lifecycle (executor thread; the loop does not run during configure/cleanup)
    def configure(self) -> str:
        """Connect and check the device; returns what was done, raises HardwareError."""
        return 'configured'

    def cleanup(self) -> None:
        """Release the device (the loop has stopped): zero speed written where possible."""

    # ---- the loop (one thread)
    @property
    def link_up(self) -> bool:
        return True

    def reconnect(self) -> bool:
        """While the link is down: one attempt when due (may sleep a little); True when up."""
        return True

    def fresh(self, now: float) -> bool:
        """The device's data is current (its cycle counter moved within the stale limit)."""
        return True

    def write(self, speed: float) -> None:
        """Apply the gated speed reference (rad/s) for the coming period."""
        raise NotImplementedError

    def read(self, now: float) -> Reading:
        """The sample after the last write (the first call: the device as it is)."""
        raise NotImplementedError

    def select(self, channel: int, drive_enable, valve_open, bypass_open: bool) -> None:
        """Redundancy command (eha/channel_select)."""
        raise NotImplementedError

    @property
    def last_error(self) -> str:
        return ''

    def values(self, now: float) -> dict:
        """Backend-specific diagnostics (added to the loop's common keys)."""
        return {}
