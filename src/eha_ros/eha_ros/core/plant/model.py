"""Nonlinear dual-redundant single-piston EHA plant (ch. 3, Fig. 3.12), one call per 1 ms tick.

The heavy lifting is in compiled kernels (:mod:`.integrator`, :mod:`.sensors`, one tick:
:func:`.stepper.step`); this class holds their arrays (one record, made once), the drive delay
FIFO, channel selection, faults and the API.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kernel_records import entry_point
from . import layout as L
from . import sensors as SN
from . import stepper as PS
from .accumulator import oil_volume
from .drive import SpeedDelay
from .faults import FaultSet
from .parameters import PlantParams, leakage_table, pack


@dataclass
class Measurement:
    """Measured state (what a real bench would see), SI units."""

    t: float
    position: float
    motor_speed: np.ndarray
    motor_current: np.ndarray
    pressure_a: float
    pressure_b: float
    active_channel: int
    valve_open: np.ndarray          # opening fractions 0..1
    drive_enabled: np.ndarray       # bool (2,)
    drive_fault: np.ndarray         # bool (2,)
    valid: bool


@dataclass
class Truth:
    """True plant state, SI units; pressures gauge."""

    t: float
    position: float
    velocity: float
    pressure_a: float
    pressure_b: float
    pressure_acc: float
    motor_speed: np.ndarray
    motor_current: np.ndarray
    friction_force: float
    load_force: float
    valve_fraction: np.ndarray
    bypass_fraction: float
    position_sensor_offset: float   # Gauss-Markov offset inside Measurement.position (S_GM)


def _aux_flag(index: int, doc: str) -> property:
    """A bool attribute kept in the plant's aux vector (1.0 / 0.0), where the compiled step
    reads and writes it."""
    def get(self) -> bool:
        return bool(self.arrays.aux[index] > 0.5)

    def put(self, value: bool) -> None:
        self.arrays.aux[index] = 1.0 if value else 0.0
    return property(get, put, doc=doc)


class EhaPlant:
    """EHA plant: ``step(omega_ref, load_force)`` advances one tick Ts.

    omega_ref (rad/s) goes, through the drive delay FIFO, to every enabled drive; load_force
    (N) follows eq. 3.23/3.32 (positive pushes towards negative x). Non-finite inputs raise
    ValueError and leave the state untouched.
    """

    def __init__(self, params: dict, seed: int = 0):
        self.p = PlantParams.from_dict(params)
        self.Ts = self.p.Ts
        self._nsub = self.p.substeps
        # the scalars the compiled step advances (stepper.A_*): time, noise row, flags, the
        # delay ring's head, the fault count; read through the properties below
        aux = np.zeros(PS.NAUX)
        self.faults = FaultSet(self.p.stroke, aux[PS.A_NFAULT:PS.A_NFAULT + 1])
        self._delay = SpeedDelay(self.p.delay_ticks, aux[PS.A_HEAD:PS.A_HEAD + 1])
        self._noise = SN.NoiseSource(seed, aux[PS.A_NOISE_K:PS.A_NOISE_K + 1])
        # the compiled step's arrays, made once: reset() and a new noise block write into them
        self.arrays = PS.Arrays(np.zeros(L.NSTATE), pack(self.p), np.zeros(L.NIN),
                                leakage_table(self.p), self._noise.block, np.zeros(L.NM), aux,
                                self._delay.ring, self.faults.table, np.zeros(L.NSTATE))
        # called per tick without typing the record again (kernel_records.entry_point)
        self._step = entry_point(PS.step, self.arrays, self._nsub, 0.0, 0.0)
        self.reset()

    # ------------------------------------------------------------------ set-up
    def reset(self, position: float = 0.0) -> None:
        """Rest state at ``position`` (m): pressures at the accumulator pressure, channel 0
        active (drive 0 enabled, valves 0 open), channel 1 standby; faults cleared."""
        if not math.isfinite(position) or abs(position) > self.p.x_stop:
            raise ValueError(f'reset position {position!r} m: expected within +-{self.p.x_stop}')
        p, a = self.p, self.arrays
        a.aux[:] = 0.0
        a.aux[PS.A_TS] = self.Ts
        S = a.S
        S[:] = 0.0
        S[L.S_X] = position
        S[L.S_PACC] = p.acc_p_init
        S[L.S_VOIL] = oil_volume(p.acc_p_init, p.acc_V_0, p.acc_P_0, p.p_atm)
        S[L.S_PA] = S[L.S_PB] = p.acc_p_init
        a.U[:] = 0.0
        a.U[L.U_LEAK0] = a.U[L.U_LEAK1] = 1.0
        self.select(0, (True, False), (True, False), False)
        S[L.S_CH + L.C_FV] = 1.0                # valves 0 already open at start
        self._delay.clear()
        a.aux[PS.A_NDELAY] = p.delay_ticks
        self._noise.restart()
        a.meas[:] = 0.0
        self._valid = True
        self.faults.clear()
        self._faulted = False
        self._sample()

    @property
    def S(self) -> np.ndarray:
        """State vector (layout.S_*)."""
        return self.arrays.S

    @property
    def U(self) -> np.ndarray:
        """Inputs of the tick and fault effects (layout.U_*)."""
        return self.arrays.U

    @property
    def t(self) -> float:
        """Plant time (s): ticks stepped times Ts."""
        return float(self.arrays.aux[PS.A_T])

    @t.setter
    def t(self, value: float) -> None:
        self.arrays.aux[PS.A_T] = value

    @property
    def active_channel(self) -> int:
        """Channel selected as active (:meth:`select`)."""
        return int(self.arrays.aux[PS.A_ACTIVE])

    _valid = _aux_flag(PS.A_VALID, 'Every tick so far finite (a non-finite one is undone and '
                                   'marks the state).')
    _faulted = _aux_flag(PS.A_FAULTED, 'Fault effects were written into U at the last tick (to '
                                       'be cleared once).')

    def select(self, channel: int, drive_enable=(True, False), valve_open=(True, False),
               bypass_open: bool = False) -> None:
        """Channel selection (/eha/channel_select): drive enables, on-off valve and bypass
        targets; valves move over their opening time."""
        if channel not in (0, 1):
            raise ValueError(f'channel {channel!r}: expected 0 or 1')
        self.arrays.aux[PS.A_ACTIVE] = channel
        for c in range(2):
            self.U[L.U_EN0 + c] = 1.0 if drive_enable[c] else 0.0
            self.U[L.U_VT0 + c] = 1.0 if valve_open[c] else 0.0
        self.U[L.U_BT] = 1.0 if bypass_open else 0.0

    def inject_fault(self, name: str, channel: int, magnitude: float, duration: float):
        """Inject a fault (see faults.FAULTS); returns (ok, message)."""
        return self.faults.inject(name, channel, magnitude, duration, self.t)

    # ------------------------------------------------------------------ run
    def step(self, omega_ref: float, load_force: float = 0.0) -> None:
        """Apply the speed reference and load force, advance one tick, sample the sensors."""
        omega_ref = float(omega_ref)
        load_force = float(load_force)
        if not (math.isfinite(omega_ref) and math.isfinite(load_force)):
            raise ValueError(f'non-finite plant input omega_ref={omega_ref!r}, '
                             f'load_force={load_force!r}: expected finite numbers')
        faults = self.faults
        if faults.active:
            faults.expire(self.t)
        self._noise.refill()
        # stepper.step: the drive delay, the fault effects, this tick's noise row, the tick
        # (a non-finite one is undone and marks the state not valid), t += Ts
        self._step(self.arrays, self._nsub, omega_ref, load_force)

    def run(self, omega_ref, load_force=None) -> np.ndarray:
        """Batch helper: step through arrays of inputs; returns the true positions."""
        omega_ref = np.asarray(omega_ref, float)
        load = np.zeros_like(omega_ref) if load_force is None else np.asarray(load_force, float)
        out = np.empty(len(omega_ref))
        for k in range(len(omega_ref)):
            self.step(omega_ref[k], load[k])
            out[k] = self.S[L.S_X]
        return out

    def _sample(self):
        a = self.arrays
        SN.sample(a.S, a.P, a.U, a.block[self._noise.next_index()], a.meas)

    # ------------------------------------------------------------------ outputs
    def measure(self) -> Measurement:
        a = self.arrays
        m, U = a.meas, a.U
        return Measurement(
            t=float(a.aux[PS.A_T]), position=float(m[L.M_X]),
            motor_speed=m[[L.M_W0, L.M_W1]].copy(),
            motor_current=m[[L.M_I0, L.M_I1]].copy(),
            pressure_a=float(m[L.M_PA]), pressure_b=float(m[L.M_PB]),
            active_channel=int(a.aux[PS.A_ACTIVE]),
            valve_open=self._channel(L.C_FV),
            drive_enabled=U[[L.U_EN0, L.U_EN1]] > 0.5,
            drive_fault=U[[L.U_FAIL0, L.U_FAIL1]] > 0.5, valid=self._valid)

    def read_into(self, r) -> None:
        """:meth:`measure` as the hardware interface reads it, written into ``r``
        (core.hardware.interface.Reading) in place: the real-time loop's per-tick read without
        a Measurement and its array copies (valves open above half open, as the bench's
        switches report them; the bypass from the true fraction, which the plant side reads)."""
        a = self.arrays
        m, U, S = a.meas, a.U, a.S
        r.position = float(m[L.M_X])
        r.pressure_a, r.pressure_b = float(m[L.M_PA]), float(m[L.M_PB])
        r.active_channel = active = int(a.aux[PS.A_ACTIVE])
        r.bypass_open = float(S[L.S_FB]) > 0.5
        r.valid = self._valid
        for i, (w, c, en, fail) in enumerate(((L.M_W0, L.M_I0, L.U_EN0, L.U_FAIL0),
                                              (L.M_W1, L.M_I1, L.U_EN1, L.U_FAIL1))):
            r.motor_speed[i] = float(m[w])
            r.motor_current[i] = float(m[c])
            r.valve_open[i] = bool(S[L.S_CH + i * L.NCH + L.C_FV] > 0.5)
            r.drive_enabled[i] = bool(U[en] > 0.5)
            r.drive_fault[i] = bool(U[fail] > 0.5)
        r.active_fault = r.drive_fault[active]

    def truth(self) -> Truth:
        a = self.arrays
        S = a.S
        return Truth(
            t=float(a.aux[PS.A_T]), position=float(S[L.S_X]), velocity=float(S[L.S_V]),
            pressure_a=float(S[L.S_PA]), pressure_b=float(S[L.S_PB]),
            pressure_acc=float(S[L.S_PACC]), motor_speed=self._channel(L.C_W),
            motor_current=self._channel(L.C_I), friction_force=float(S[L.S_FF]),
            load_force=float(a.U[L.U_FL]), valve_fraction=self._channel(L.C_FV),
            bypass_fraction=float(S[L.S_FB]), position_sensor_offset=float(S[L.S_GM]))

    def _channel(self, offset):
        S = self.arrays.S
        return np.array([S[L.S_CH + offset], S[L.S_CH + L.NCH + offset]])

    @property
    def position(self) -> float:
        """True piston position (m), cheap accessor for batch loops."""
        return float(self.S[L.S_X])
