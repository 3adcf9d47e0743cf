"""Fault injection: sensor and actuator faults, timed (duration 0 = permanent)."""
from __future__ import annotations

import math
from dataclasses import dataclass

from . import layout as L

FAULTS = {
    'msp_noise': 'extra white noise on the position sensor, magnitude = sigma (m)',
    'msp_stuck': 'position output frozen at its last value (magnitude ignored)',
    'msp_bias': 'position bias jump, magnitude (m)',
    'msp_drift': 'position bias growing at magnitude (m/s) from injection',
    'motor_fail': "channel's motor gives no torque, its drive reports a fault, current 0",
    'pump_leakage': "channel's pump leakage coefficients C_p, C_r times magnitude (>= 0)",
    'pressure_sensor': 'bias magnitude (Pa) on both pressure readings; NaN = both stuck',
}
CLEAR = 'clear'         # not a fault: removes every active fault (channel, magnitude ignored)


@dataclass
class Fault:
    name: str
    channel: int
    magnitude: float
    t_start: float
    t_end: float        # inf = permanent


class FaultSet:
    """Active faults; writes their effect into the input vector U and sensor fault vector."""

    def __init__(self, position_range: float = math.inf):
        """position_range (m): the position sensor's measuring range (the stroke), the largest
        |magnitude| of msp_bias, msp_noise and msp_drift (per second)."""
        self.active: dict[tuple[str, int], Fault] = {}
        self.limits = dict.fromkeys(('msp_bias', 'msp_noise', 'msp_drift'), position_range)

    def inject(self, name, channel, magnitude, duration, t) -> tuple[bool, str]:
        if name == CLEAR:
            n = len(self.active)
            self.clear()
            return True, f'cleared {n} active fault(s)'
        if name not in FAULTS:
            return False, (f'unknown fault {name!r}: expected one of '
                           f'{", ".join(sorted(FAULTS) + [CLEAR])}')
        try:
            channel = int(channel)
            magnitude = float(magnitude)
            duration = float(duration)
        except (TypeError, ValueError):
            return False, f'fault {name}: channel, magnitude and duration must be numbers'
        if channel not in (0, 1):
            return False, f'fault {name}: channel = {channel}: expected 0 or 1'
        if not math.isfinite(duration) or duration < 0:
            return False, f'fault {name}: duration = {duration}: expected finite >= 0 s'
        if not math.isfinite(magnitude) and not (name == 'pressure_sensor'
                                                 and math.isnan(magnitude)):
            return False, f'fault {name}: magnitude = {magnitude}: expected a finite number'
        if name == 'pump_leakage' and magnitude < 0:
            return False, f'fault pump_leakage: magnitude = {magnitude}: expected >= 0'
        if name == 'msp_noise' and magnitude < 0:
            return False, f'fault msp_noise: magnitude = {magnitude}: expected sigma >= 0 m'
        limit = self.limits.get(name, math.inf)
        if abs(magnitude) > limit:
            return False, (f'fault {name}: magnitude = {magnitude:g}: beyond the sensor range '
                           f'(|magnitude| <= {limit:g})')
        if name.startswith('msp') or name == 'pressure_sensor':
            channel = 0        # one position sensor and one pair of pressure sensors
        t_end = math.inf if duration == 0 else t + duration
        self.active[(name, channel)] = Fault(name, channel, magnitude, t, t_end)
        span = 'permanent' if duration == 0 else f'for {duration:g} s'
        return True, f'fault {name} on channel {channel} magnitude {magnitude:g} {span}'

    def clear(self):
        self.active.clear()

    def apply(self, t, U) -> None:
        """Expire faults ending at or before t; write the remaining ones' effects into U."""
        for key in [k for k, f in self.active.items() if f.t_end <= t + 1e-12]:
            del self.active[key]
        U[L.U_FAIL0] = U[L.U_FAIL1] = 0.0
        U[L.U_LEAK0] = U[L.U_LEAK1] = 1.0
        U[L.U_FX_SIGMA:L.U_FP_STUCK + 1] = 0.0
        for f in self.active.values():
            if f.name == 'motor_fail':
                U[L.U_FAIL0 + f.channel] = 1.0
            elif f.name == 'pump_leakage':
                U[L.U_LEAK0 + f.channel] = f.magnitude
            elif f.name == 'msp_noise':
                U[L.U_FX_SIGMA] = f.magnitude
            elif f.name == 'msp_bias':
                U[L.U_FX_BIAS] += f.magnitude
            elif f.name == 'msp_drift':
                U[L.U_FX_BIAS] += f.magnitude * (t - f.t_start)
            elif f.name == 'msp_stuck':
                U[L.U_FX_STUCK] = 1.0
            elif f.name == 'pressure_sensor':
                if math.isnan(f.magnitude):
                    U[L.U_FP_STUCK] = 1.0
                else:
                    U[L.U_FP_BIAS] = f.magnitude
