"""QFT position controller at Ts: prefilter F(s) and G(s) (eqs. 4.74, 4.76, 4.77) discretised by
Tustin, motor-speed clamp with observer-form anti-windup (core.controller.antiwindup), bumpless
(re)starts.

One call per estimate::

    r_req -> ReferenceShaper (NaN reject, clamp, 190 mm/s, acceleration) -> F -> r_f
    e = r_f - x_hat -> G (state x, observer-form anti-windup) -> u -> u_s = clip(u, +-omega_max)
    motor speed omega_m -> the drive's reach (antiwindup.drive_reach) bounds the anti-windup's
    actuator u_a = clip(u_s, omega_m -+ reach)
    estimated leak flow q_L -> leakage compensation (alpha 0.5 by default): u += alpha q_L / D_p
    before the clamp

G is realised as one state space (a cascade of real first- and second-order sections,
controller.lti) of any proper G(s); nothing assumes its structure. The per-tick arithmetic is
controller.stepper.control, the same compiled function the closed-loop kernels run.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal

from ..kernel_records import entry_point
from .lti import from_num_den
from ..stats import Counters
from . import stepper as S
from .antiwindup import drive_reach, observer_gain, poles_from_params
from .discrete import DiscreteSS, tustin
from .reference import ReferenceShaper


def tf_to_ss(num, den):
    """Balanced (A, B, C, D) of a proper SISO num/den (descending powers of s)."""
    num = np.trim_zeros(np.asarray(num, float), 'f')
    den = np.trim_zeros(np.asarray(den, float), 'f')
    if len(num) > len(den):
        raise ValueError('improper transfer function')
    A, B, C, D = signal.tf2ss(num, den)
    if A.size:
        _, (scale, _) = linalg.matrix_balance(A, permute=False, separate=True)
        T, Ti = np.diag(scale), np.diag(1.0 / scale)
        A, B, C = Ti @ A @ T, Ti @ B, C @ T
    return A, B, C, D


def drive_reach_of(p: dict) -> float:
    """antiwindup.drive_reach from the plant.* parameters: measurement to application is one
    tick plus the drive's delay."""
    return drive_reach(p['plant.motor.k_T'], p['plant.drive.I_max'], p['plant.motor.J_eq'],
                       p['plant.drive.Kp_w'], p['plant.sim.Ts'] + p['plant.drive.delay'])


@dataclass
class ControlOutput:
    speed_ref: float          # saturated motor-speed reference [rad/s]
    saturated: bool
    reference: float          # rate-limited reference after the prefilter [m]
    error: float              # r_f - x_hat [m]
    unsaturated: float        # controller output before the clamp [rad/s]


class PositionController:
    """The controller core the node wraps; SI units (m in, rad/s out).

    aw_poles: continuous-time poles (rad/s, one per state of G, conjugate pairs) of the
    controller while clamped (antiwindup.observer_gain); None or antiwindup False: L = 0.
    drive_reach: how far (rad/s) the reference may lead the motor speed given to
    :meth:`update` (antiwindup.drive_reach); 0: the clamp is the only actuator limit.
    leakage_gain: alpha / D_p (rad/s per m^3/s), the motor speed added per m^3/s of the leak
    flow given to :meth:`update` (stepper.control); 0: off."""

    def __init__(self, G, F, Ts: float, omega_max: float, stroke: float, margin: float,
                 rate_limit: float, antiwindup: bool = True, aw_poles=None,
                 prewarp_w: float | None = None, counters: Counters | None = None,
                 accel_limit: float = 0.0, drive_reach: float = 0.0,
                 leakage_gain: float = 0.0):
        self.Ts = Ts
        self.omega_max = omega_max
        self.c = counters if counters is not None else Counters()
        self.ref = ReferenceShaper(stroke, margin, rate_limit, Ts, self.c, accel_limit)
        self.k, self.s = self.ref.k, self.ref.s           # the stepper's constants and state
        self.F = DiscreteSS(*tustin(*tf_to_ss(*F), Ts, prewarp_w))
        if abs(self.F.dc_gain() - 1.0) > 1e-6:
            raise ValueError(f'prefilter DC gain {self.F.dc_gain():.6g}: expected 1')
        self.G = DiscreteSS(*tustin(*from_num_den(*G).ss(), Ts, prewarp_w))
        self.antiwindup = bool(antiwindup)
        if self.antiwindup:
            if aw_poles is None or len(aw_poles) == 0:
                raise ValueError('anti-windup on but no antiwindup.poles_real/poles_imag for G: '
                                 'run scripts/design_qft --antiwindup <controller.yaml>')
            self.L = observer_gain(self.G.Ad, self.G.Cd, aw_poles, Ts)
        else:
            self.L = np.zeros(self.G.n)
        if not (drive_reach >= 0.0 and math.isfinite(drive_reach)):
            raise ValueError(f'drive reach {drive_reach}: expected a finite value >= 0 rad/s')
        self.k[S.K_WMAX], self.k[S.K_FDD], self.k[S.K_GDD] = omega_max, self.F._dd, self.G._dd
        self.k[S.K_REACH] = drive_reach if self.antiwindup else 0.0
        if not (leakage_gain >= 0.0 and math.isfinite(leakage_gain)):
            raise ValueError(f'leakage compensation gain {leakage_gain}: expected a finite '
                             f'value >= 0 (rad/s)/(m^3/s)')
        self.k[S.K_LEAK] = leakage_gain
        self._arrays = S.pack(self)[2]     # F, G and L arrays: changed in place, never replaced
        self._control = entry_point(S.control, self.k, self.s, self._arrays, 0.0, 0.0,
                                    0.0)   # per tick

    @classmethod
    def from_params(cls, p: dict, counters: Counters | None = None) -> 'PositionController':
        """From the controller node's parameters (core.controller.params.SCHEMA)."""
        prewarp = 2 * math.pi * p['control.prewarp_hz'] or None
        poles = poles_from_params(p['antiwindup.poles_real'], p['antiwindup.poles_imag'])
        reach = drive_reach_of(p) if p['control.drive_limit_antiwindup'] else 0.0
        return cls((p['position_controller.num'], p['position_controller.den']),
                   (p['prefilter.num'], p['prefilter.den']), p['plant.sim.Ts'],
                   p['plant.drive.omega_max'], p['plant.cylinder.stroke'],
                   p['control.stroke_margin'], p['control.rate_limit'], p['control.antiwindup'],
                   aw_poles=poles, prewarp_w=prewarp, counters=counters,
                   accel_limit=p['control.accel_limit'], drive_reach=reach,
                   leakage_gain=p['control.leakage_compensation'] / p['plant.pump.D_p'])

    def request(self, position: float) -> bool:
        return self.ref.request(position)

    def start(self, position: float):
        """(Re)start bumplessly at the piston position: zero output, reference from there."""
        self.ref.start_from(position)
        self.F.steady_state(position)
        self.G.reset()
        self.s[S.C_CLAMPED] = 0.0

    @property
    def started(self) -> bool:
        return self.ref.value is not None

    @property
    def clamped(self) -> int:
        """Sign of the clamp at the last tick (0: none)."""
        return int(self.s[S.C_CLAMPED])

    @property
    def hold(self) -> int:
        """Ticks left with G's state frozen."""
        return int(self.s[S.C_HOLD])

    @property
    def compensating(self) -> bool:
        """The leakage compensation is on (control.leakage_compensation > 0, not stopped)."""
        return bool(self.k[S.K_LEAK] > 0.0)

    def stop_leakage_compensation(self) -> bool:
        """The chamber pressure sensors were blamed (/eha/redundancy pressure_sensors_failed):
        the leak flow the estimator reports comes from a wrong p_D, so the compensation stays
        off from here on. Returns True when this call turned it off."""
        on = self.compensating
        self.k[S.K_LEAK] = 0.0
        return on

    def hold_integrator(self, ticks: int):
        """Channel switch: the output stays continuous; G's state is frozen while valves change
        over."""
        self.s[S.C_HOLD] = max(self.s[S.C_HOLD], ticks)

    def update(self, position_estimate: float, motor_speed: float = math.nan,
               leak_flow: float = math.nan) -> ControlOutput:
        """One tick: the position estimate (m), the active motor's measured speed (rad/s;
        NaN when unknown: the clamp is the only actuator limit) and the estimated leak flow
        (m^3/s; NaN: no leakage compensation this tick)."""
        if not self.started:
            self.start(position_estimate)
        u_sat = self._control(self.k, self.s, self._arrays, float(position_estimate),
                              float(motor_speed), float(leak_flow))
        S.unpack(self, self.s)
        s = self.s
        return ControlOutput(float(u_sat), bool(s[S.C_CLAMPED]), float(s[S.C_R]),
                             float(s[S.C_E]), float(s[S.C_U]))
