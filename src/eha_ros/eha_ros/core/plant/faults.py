"""Fault injection: sensor and actuator faults, timed (duration 0 = permanent)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..jit_cache import drop_stale
from . import layout as L

drop_stale(__file__)

FAULTS = {
    'msp_noise': 'extra white noise on the position sensor, magnitude = sigma (m)',
    'msp_stuck': 'position output frozen at its last value (magnitude ignored)',
    'msp_bias': 'position bias jump, magnitude (m)',
    'msp_drift': 'position bias growing at magnitude (m/s) from injection',
    'motor_fail': "channel's motor gives no torque, its drive reports a fault, current 0",
    'pump_leakage': "channel's pump leakage coefficients C_p, C_r times magnitude (>= 0)",
    'pressure_sensor': 'bias magnitude (Pa) on both pressure readings; NaN = both stuck',
    'pressure_sensor_a': "bias magnitude (Pa) on chamber A's pressure reading only; NaN = stuck",
    'pressure_sensor_b': "bias magnitude (Pa) on chamber B's pressure reading only; NaN = stuck",
}
PRESSURE_FAULTS = ('pressure_sensor', 'pressure_sensor_a', 'pressure_sensor_b')
CLEAR = 'clear'         # not a fault: removes every active fault (channel, magnitude ignored)
# numeric codes of the compiled path: the position in FAULTS
FAULT_CODES = {name: i for i, name in enumerate(FAULTS)}
(FC_MSP_NOISE, FC_MSP_STUCK, FC_MSP_BIAS, FC_MSP_DRIFT, FC_MOTOR_FAIL, FC_PUMP_LEAKAGE,
 FC_PRESSURE_SENSOR, FC_PRESSURE_A, FC_PRESSURE_B) = (FAULT_CODES[n] for n in (
    'msp_noise', 'msp_stuck', 'msp_bias', 'msp_drift', 'motor_fail', 'pump_leakage',
    *PRESSURE_FAULTS))
# fault table rows: code, channel, magnitude, t_start, t_end; one per (name, channel) at most
F_CODE, F_CH, F_MAG, F_T0, F_T1 = range(5)
MAX_FAULTS = 2 * len(FAULTS)


@njit(cache=True)
def expiring(table, n, t) -> bool:
    """One of the first n faults of the table ends at or before t."""
    for i in range(n):
        if table[i, F_T1] <= t + 1e-12:
            return True
    return False


@njit(cache=True)
def apply_faults(t, U, table, n) -> None:
    """The effects of the first n rows of the fault table into the input vector U, in order."""
    U[L.U_FAIL0] = 0.0
    U[L.U_FAIL1] = 0.0
    U[L.U_LEAK0] = 1.0
    U[L.U_LEAK1] = 1.0
    for j in range(L.U_FX_SIGMA, L.U_FPB_STUCK + 1):
        U[j] = 0.0
    for i in range(n):
        code = int(table[i, F_CODE])
        ch = int(table[i, F_CH])
        mag = table[i, F_MAG]
        if code == FC_MOTOR_FAIL:
            U[L.U_FAIL0 + ch] = 1.0
        elif code == FC_PUMP_LEAKAGE:
            U[L.U_LEAK0 + ch] = mag
        elif code == FC_MSP_NOISE:
            U[L.U_FX_SIGMA] = mag
        elif code == FC_MSP_BIAS:
            U[L.U_FX_BIAS] += mag
        elif code == FC_MSP_DRIFT:
            U[L.U_FX_BIAS] += mag * (t - table[i, F_T0])
        elif code == FC_MSP_STUCK:
            U[L.U_FX_STUCK] = 1.0
        elif code == FC_PRESSURE_SENSOR or code == FC_PRESSURE_A or code == FC_PRESSURE_B:
            for side in range(2):       # 0: chamber A, 1: chamber B
                if code == FC_PRESSURE_SENSOR or code == FC_PRESSURE_A + side:
                    if math.isnan(mag):
                        U[L.U_FPA_STUCK + 2 * side] = 1.0
                    else:
                        U[L.U_FPA_BIAS + 2 * side] += mag


@dataclass
class Fault:
    name: str
    channel: int
    magnitude: float
    t_start: float
    t_end: float        # inf = permanent


class FaultSet:
    """Active faults, kept as the table (rows F_*, the first ``n`` in use, in the order of
    ``active``) that :func:`apply_faults` reads in the plant's compiled step."""

    def __init__(self, position_range: float = math.inf, count=None):
        """position_range (m): the position sensor's measuring range (the stroke), the largest
        |magnitude| of msp_bias, msp_noise and msp_drift (per second). count: a one-element
        array that holds ``n`` (the plant's aux vector, where the compiled step reads it)."""
        self.active: dict[tuple[str, int], Fault] = {}
        self.table = np.zeros((MAX_FAULTS, 5))
        self._count = count if count is not None else np.zeros(1)
        expiring(self.table, 0, 0.0)    # compiled (or loaded) now, not at a fault mid-run
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
        if not math.isfinite(magnitude) and not (name in PRESSURE_FAULTS
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
        if name.startswith('msp') or name in PRESSURE_FAULTS:
            channel = 0        # one position sensor and one pair of pressure sensors
        t_end = math.inf if duration == 0 else t + duration
        self.active[(name, channel)] = Fault(name, channel, magnitude, t, t_end)
        self._tabulate()
        span = 'permanent' if duration == 0 else f'for {duration:g} s'
        return True, f'fault {name} on channel {channel} magnitude {magnitude:g} {span}'

    def clear(self):
        self.active.clear()
        self._tabulate()

    def _tabulate(self):
        for i, f in enumerate(self.active.values()):
            self.table[i] = (FAULT_CODES[f.name], f.channel, f.magnitude, f.t_start, f.t_end)
        self._count[0] = len(self.active)

    @property
    def n(self) -> int:
        """Rows of the table in use (the active faults)."""
        return int(self._count[0])

    def due(self, t) -> bool:
        """A fault ends at or before t (apply deletes it)."""
        return expiring(self.table, self.n, float(t))

    def expire(self, t) -> None:
        """Delete the faults ending at or before t."""
        if self.due(t):
            for key in [k for k, f in self.active.items() if f.t_end <= t + 1e-12]:
                del self.active[key]
            self._tabulate()
