"""QFT position controller at Ts: prefilter F(s) and G(s) (eqs. 4.74, 4.76, 4.77) discretised by
Tustin, motor-speed saturation with observer-form anti-windup, bumpless (re)starts.

One call per estimate::

    r_req -> ReferenceShaper (NaN reject, clamp, 190 mm/s) -> F -> r_f
    e = r_f - x_hat -> G (state x) -> u -> u_sat = clip(u, +-omega_max)

G(s) = K_dc (1/s) R(s), R(0) = 1, is split at its pole at s = 0: a Tustin integrator feeds
the biproper lead/lag R(s) (Tustin, same warping), so unsaturated the controller is exactly
Tustin(G). Anti-windup (the thesis names it as missing, ch. 5) is conditional integration:
while the output is clamped and the error pushes further into the clamp, the integrator
holds. Measured alternatives: back-calculation must be scaled by R's feed-through (1e4 and
more for these leads) and then barely acts on slow components; the observer form (Astrom &
Wittenmark) turns the output around when the lead's large feed-through D e shrinks.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal

from ..stats import Counters
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


def split_integrator(num, den):
    """G = K_dc (1/s) R(s) with R(0) = 1: (K_dc, R_num, R_den), or None without a pole at 0."""
    num = np.trim_zeros(np.asarray(num, float), 'f')
    den = np.trim_zeros(np.asarray(den, float), 'f')
    if den[-1] != 0.0:
        return None
    rden = den[:-1]
    k_dc = num[-1] / rden[-1]
    if not math.isfinite(k_dc) or k_dc == 0.0:
        return None
    return k_dc, num / k_dc, rden


@dataclass
class ControlOutput:
    speed_ref: float          # saturated motor-speed reference [rad/s]
    saturated: bool
    reference: float          # rate-limited reference after the prefilter [m]
    error: float              # r_f - x_hat [m]
    unsaturated: float        # controller output before the clamp [rad/s]


class PositionController:
    """The controller core the node wraps; SI units (m in, rad/s out)."""

    def __init__(self, G, F, Ts: float, omega_max: float, stroke: float, margin: float,
                 rate_limit: float, antiwindup: bool = True, tracking_time: float = 0.01,
                 prewarp_w: float | None = None, counters: Counters | None = None,
                 accel_limit: float = 0.0):
        self.Ts = Ts
        self.omega_max = omega_max
        self.c = counters if counters is not None else Counters()
        self.ref = ReferenceShaper(stroke, margin, rate_limit, Ts, self.c, accel_limit)
        self.F = DiscreteSS(*tustin(*tf_to_ss(*F), Ts, prewarp_w))
        if abs(self.F.dc_gain() - 1.0) > 1e-6:
            raise ValueError(f'prefilter DC gain {self.F.dc_gain():.6g}: expected 1')
        parts = split_integrator(*G)
        if parts is None:
            raise ValueError('position controller G(s) has no integrator (pole at s = 0): '
                             'expected the K/s structure of eq. 4.74')
        self.k_dc, rnum, rden = parts
        self.R = DiscreteSS(*tustin(*tf_to_ss(rnum, rden), Ts, prewarp_w))
        # Tustin integrator with the same warping: v_out = v + T/2 w, v += T w
        self.T = Ts if not prewarp_w else 2.0 * math.tan(prewarp_w * Ts / 2.0) / prewarp_w
        self.antiwindup = antiwindup
        self.v = 0.0
        self.clamped = 0              # sign of the clamp at the previous tick (0: none)
        self.hold = 0                 # ticks left with the integrator held

    @classmethod
    def from_params(cls, p: dict, counters: Counters | None = None) -> 'PositionController':
        """From the controller node's parameters (core.controller.params.SCHEMA)."""
        prewarp = 2 * math.pi * p['control.prewarp_hz'] or None
        return cls((p['position_controller.num'], p['position_controller.den']),
                   (p['prefilter.num'], p['prefilter.den']), p['plant.sim.Ts'],
                   p['plant.drive.omega_max'], p['plant.cylinder.stroke'],
                   p['control.stroke_margin'], p['control.rate_limit'], p['control.antiwindup'],
                   prewarp_w=prewarp, counters=counters, accel_limit=p['control.accel_limit'])

    def request(self, position: float) -> bool:
        return self.ref.request(position)

    def start(self, position: float):
        """(Re)start bumplessly at the piston position: zero output, reference from there."""
        self.ref.start_from(position)
        self.F.steady_state(position)
        self.R.reset()
        self.v = 0.0
        self.clamped = 0

    @property
    def started(self) -> bool:
        return self.ref.value is not None

    def hold_integrator(self, ticks: int):
        """Channel switch: the output stays continuous; no integration while valves change over."""
        self.hold = max(self.hold, ticks)

    def update(self, position_estimate: float) -> ControlOutput:
        if not self.started:
            self.start(position_estimate)
        r = self.F.update(self.ref.next())
        e = r - position_estimate
        w = self.k_dc * e
        if self.hold > 0:
            self.hold -= 1
            w = 0.0
        elif self.antiwindup and self.clamped * w > 0:
            w = 0.0                   # clamped and the error pushes further into the clamp
        v_out = self.v + 0.5 * self.T * w
        self.v += self.T * w
        u = self.R.update(v_out)
        u_sat = max(-self.omega_max, min(self.omega_max, u))
        self.clamped = int(u > u_sat) - int(u < u_sat)
        if self.clamped:
            self.c.bump('saturated_ticks')
        return ControlOutput(u_sat, bool(self.clamped), r, e, u)
