"""Discrete PID with filtered derivative, output clamp and anti-windup (Table 3.8 position PID).

u = Kp e + Ki int(e) + Kd d/dt(e) filtered by 1/(tau_d s + 1); the integral is forward Euler
with conditional integration (frozen while the output is clamped and the error pushes further
into the clamp); the filtered derivative uses the exact discretisation of the filter for a
sampled error (backward difference of the error, pole exp(-Ts/tau_d)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

RPM = 2.0 * math.pi / 60.0

# Table 3.8 position loop gains, converted to SI (rad/s of motor speed reference per m).
KP_TABLE_3_8 = 900.0 * RPM / 1e-3          # 900 rpm/mm       -> 94247.8 (rad/s)/m
KI_TABLE_3_8 = 105.88 * RPM / 1e-3         # 105.88 rpm/(mm s) -> 11087.7 (rad/s)/(m s)
KD_TABLE_3_8 = 0.9 * RPM / 1e-3            # 0.9 rpm s/mm     -> 94.25 (rad/s) s/m


@dataclass
class PID:
    """Discrete PID at sample time Ts (s); SI units of the loop (here m -> rad/s)."""

    Ts: float
    kp: float
    ki: float = 0.0
    kd: float = 0.0
    tau_d: float = 2e-3
    u_min: float = -math.inf
    u_max: float = math.inf

    def __post_init__(self):
        if not (self.Ts > 0 and self.tau_d > 0 and self.u_min < self.u_max):
            raise ValueError('PID: expected Ts > 0, tau_d > 0 and u_min < u_max')
        self._a = math.exp(-self.Ts / self.tau_d)
        self.reset()

    @classmethod
    def table_3_8(cls, Ts: float = 1e-3, omega_max: float = 8000 * RPM, tau_d: float = 2e-3):
        """The thesis position PID (Table 3.8) with the 8000 rpm speed clamp."""
        return cls(Ts, KP_TABLE_3_8, KI_TABLE_3_8, KD_TABLE_3_8, tau_d, -omega_max, omega_max)

    def reset(self, integral: float = 0.0) -> None:
        self.integral = integral
        self.d_state = 0.0
        self._e_prev = None

    def update(self, error: float) -> float:
        """One sample: returns the clamped output for the error e = reference - measurement."""
        e_prev = error if self._e_prev is None else self._e_prev
        self._e_prev = error
        # filtered derivative: D(z) = Kd (1 - a)/Ts * (1 - z^-1) / (1 - a z^-1)
        self.d_state = self._a * self.d_state + (1.0 - self._a) * (error - e_prev) / self.Ts
        u = self.kp * error + self.ki * self.integral + self.kd * self.d_state
        clamped = min(max(u, self.u_min), self.u_max)
        if not ((u > self.u_max and error > 0) or (u < self.u_min and error < 0)):
            self.integral += self.Ts * error
        return clamped


class PIDLoop:
    """A :class:`PID` on the position error behind the position controller's interface
    (request / update / start / hold_integrator), so the one closed-loop harness
    (core.sim.batch.BatchLoop) runs the thesis' Table 3.8 loop as it runs the stack's."""

    class Output(NamedTuple):
        speed_ref: float     # rad/s

    started = True           # no start-up: the PID acts from the first tick

    def __init__(self, pid: PID):
        self.pid = pid
        self.reference = 0.0

    def request(self, reference: float) -> None:
        self.reference = reference

    def update(self, position: float, motor_speed: float = 0.0,
               leak_flow: float = 0.0) -> 'PIDLoop.Output':
        """One sample on the error reference - position (the motor speed and the leak flow
        are not used)."""
        return self.Output(self.pid.update(self.reference - position))

    def start(self, position: float) -> None:
        """Back from a hold (the stack's safe state): integral and derivative from zero."""
        self.pid.reset()

    def hold_integrator(self, ticks: int) -> None:
        """A channel switch: the Table 3.8 loop has no hold; nothing to do."""
