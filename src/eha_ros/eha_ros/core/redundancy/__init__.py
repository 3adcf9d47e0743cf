"""Redundancy switch manager core (thesis 3.4, Fig. 3.12): per-channel health monitors,
the switch state machine with the on-off valve sequence, and the switch-event log.
Pure Python, no rclpy: the switch_manager node and the batch tests wrap the same objects."""
from .health import ChannelSample, HealthMonitor, Hysteresis
from .state_machine import (ACTIVE, DEGRADED, FAILED_SAFE, SWITCHING, Select, SwitchManager,
                            state_name)
from .events import EventLog, SwitchEvent

__all__ = ['ChannelSample', 'HealthMonitor', 'Hysteresis', 'Select', 'SwitchManager',
           'ACTIVE', 'SWITCHING', 'DEGRADED', 'FAILED_SAFE', 'state_name', 'EventLog',
           'SwitchEvent']
