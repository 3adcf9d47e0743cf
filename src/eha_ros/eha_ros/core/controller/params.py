"""Parameters of the controller node: transfer functions from design_qft (config/controller.yaml),
loop settings (config/controller_node.yaml) and the shared plant.* set (config/plant.yaml)."""
from __future__ import annotations

from ..config.params import Param, ParamError, Schema
from ..hardware.params import AUTOSTART
from ..plant.parameters import PLANT_SCHEMA

TF = [Param(f'{name}.{part}', 'float[]', unit, doc=doc)
      for name, unit, doc in (
          ('position_controller', '(rad/s)/m', 'G(s), eq. 4.74, continuous, descending powers'),
          ('prefilter', 'm/m', 'F(s), eq. 4.77'),
          ('velocity_controller', 'A/(rad/s)', 'G_v(s), eq. 4.65 incl. 1/k_T (drive)'))
      for part in ('num', 'den')] + [
    Param(f'antiwindup.poles_{part}', 'float[]', 'rad/s',
          doc=f'{part} parts of the poles of G while the speed clamp is active (observer-form '
              'anti-windup, core.controller.antiwindup; conjugates listed both; design_qft)')
    for part in ('real', 'imag')]

NODE = Schema('controller', TF + [
    Param('control.stroke_margin', 'float', 'm', 0.005, 0.0, 0.05,
          doc='references are clamped to +-(stroke/2 - margin) (+-(60 - 5) mm)'),
    Param('control.rate_limit', 'float', 'm/s', 0.19, 1e-3, 10.0,
          doc='reference rate limit (Table 3.1: 190 mm/s)'),
    Param('control.accel_limit', 'float', 'm/s^2', 6.0, 0.0, 1000.0,
          doc='acceleration of the move to a jumped reference (0: rate limit only). The '
              'drive\'s current limit bounds the piston acceleration at k_T I_max D_p / (J_eq '
              'A_p): 7.4 m/s^2 on the weakest plant of Table 4.5 (k_T, D_p x0.8). With the '
              'observer-form anti-windup a 5 mm step stays within the spec without this limit '
              'too (0.14 %; tests/test_controller_core.py); references that move at most '
              '190 mm/s per tick (sines, ramps) pass unchanged'),
    Param('control.antiwindup', 'bool', '', True,
          doc='observer-form anti-windup with antiwindup.poles_* of controller.yaml '
              '(core.controller.antiwindup; false: none, L = 0)'),
    Param('control.drive_limit_antiwindup', 'bool', '', True,
          doc='the anti-windup also bounds its actuator by the drive\'s reach beyond the '
              'measured motor speed of /eha/estimate (k_T I_max/Kp_w + k_T I_max/J_eq (Ts + '
              'drive delay), from plant.*: 133.5 rad/s with config/plant.yaml; '
              'core.controller.antiwindup.drive_reach): a held '
              'piston or a motor starting from rest does not wind G up; false: the speed clamp '
              'only'),
    Param('control.leakage_compensation', 'float', '', 0.5, 0.0, 2.0,
          doc='leakage compensation: the speed command adds alpha q_L / D_p, the pump speed '
              'that supplies the fraction alpha of the flow the loaded chamber leaks, q_L of '
              '/eha/estimate leak_flow (core.estimator.adapt.leak_flow: the chamber filter\'s '
              'pressures and adapted leakage), so the pump feeds the leak before the position '
              'error shows it: dynamic stiffness under load (issue 42; 0.5: the decided '
              'stiffness limits on every held-out run of Table 4.5, docs/measurements.md). 0: '
              'off, the thesis\' controller; NaN leak flow (a filter without chamber '
              'pressures): nothing added'),
    Param('control.prewarp_hz', 'float', 'Hz', 0.0, 0.0, 200.0,
          doc='Tustin prewarp frequency; 0 = plain Tustin'),
    Param('control.watchdog_ticks', 'int', '', 5, 1, 1000,
          doc='no (or stale) estimate for more ticks: zero speed, reported'),
    Param('control.reference_wait', 'float', 's', 1.0, 0.001, 60.0,
          doc='lock-step only: how long (wall time) an estimate waits for the reference of '
              'its tick from a tick-locked source (the sweep) before it goes on with the '
              'last one (counted as reference_wait_timeouts, WARN once); a starved process '
              'is late by tens of ms on a loaded machine, a dead one never answers'),
    Param('control.switch_hold', 'float', 's', 0.0, 0.0, 1.0,
          doc='state of G frozen this long after the active channel changes (0: none; stack '
              'controller, Table 3.4 switch: 20 ms measured 0.013 mm extra deviation against '
              'the twin run vs 0.010 mm without)'),
    Param('control.drive_check_tolerance', 'float', '', 0.01, 0.0, 1.0,
          doc='relative mismatch between velocity_controller and plant.drive gains to report'),
    Param('control.autostart', 'str', '', 'active', choices=AUTOSTART,
          doc='lifecycle state to reach by itself at start-up: unconfigured (wait for a '
              'manager, e.g. run_stack), inactive (zero output) or active (controls while the '
              'plant side is active)'),
    Param('control.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0,
          doc='/diagnostics period'),
])


def check(p: dict) -> None:
    """What the node refuses when it builds its PositionController, one line each: a transfer
    function without a non-zero coefficient or improper (num of higher degree than den), then
    anything the build itself rejects (prefilter DC gain, anti-windup poles vs G's order)."""
    import numpy as np
    for name in ('position_controller', 'prefilter', 'velocity_controller'):
        num = np.trim_zeros(np.asarray(p[f'{name}.num'], float), 'f')
        den = np.trim_zeros(np.asarray(p[f'{name}.den'], float), 'f')
        for part, poly in (('num', num), ('den', den)):
            if poly.size == 0:
                raise ParamError(f'{name}.{part} = {p[f"{name}.{part}"]}: expected a polynomial '
                                 f'with a non-zero coefficient (descending powers of s)')
        if num.size > den.size:
            raise ParamError(f'{name}: num of degree {num.size - 1} over den of degree '
                             f'{den.size - 1}: expected a proper transfer function')
    from .position import PositionController
    try:
        PositionController.from_params(p)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as err:
        raise ParamError(f'controller: {err}') from None


SCHEMA = PLANT_SCHEMA + Schema('controller', NODE.params, check)
