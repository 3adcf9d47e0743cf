"""Plant parameter schema (Tables 3.7, 3.8, 4.5, appendix D.1) and the frozen parameter set.

Every ``plant.*`` parameter is declared here with type, SI unit, physical range and default
(the actuator's identity -- A_p, V_d, m_p, stroke, D_p, k_T, beta -- has none: a plant file
must state it);
``config/plant.yaml`` repeats them with their thesis source. :class:`PlantParams` is the
validated, typed view that the model and the linear models use, and :func:`pack` turns it into
the flat float64 vector the compiled kernels read (indices in :mod:`.layout`, each one's
attribute in :data:`PACKED`).

Decided choices (thesis inconsistencies, see DESIGN.md):
- beta = 1.379e9 Pa (Table 3.8; Table 4.5's 1.379e7 is a typo, D.1 uses 1.355e9).
- b_eq = 4.26e-3 Nm/(rad/s) (appendix D.1; Table 3.8's "100" is a typo).
- V_d = 4.01e-4 m^3 (Table 3.8; D.1 computes A_p*0.12*1.3 = 4.01e-4 too).
- C_eq = C_p + C_c + C_r/2 = 3.8e-12 m^3/(s Pa) (eq. 3.22 and Table 3.8), split as
  C_p = 1.5e-12, C_c = 0.5e-12, C_r = 3.6e-12 (the split is not given in the thesis).
- k_E = 0.53 V/(rad/s) (Table 4.5 / D.1).
"""
from __future__ import annotations

import math
from dataclasses import make_dataclass

import numpy as np

from ..config.params import Param, ParamError, Schema
from . import layout as L

RPM = 2.0 * math.pi / 60.0
BAR = 1.0e5


def _synthetic_eta_table():
    """Synthetic volumetric-efficiency map eta_v(omega, p_D) (eq. 3.31), NOT measured data.

    Built from a total leakage coefficient that rises linearly from 0.8 to 1.2 times
    C_p + C_r = 5.1e-12 m^3/(s Pa) between 0 and 250 bar, so its average over 50-250 bar is
    close to the linearisation used by the linear models; clipped to [0.05, 1].
    """
    omegas = [50.0, 100.0, 200.0, 400.0, 600.0, 838.0]
    pds = [0.0, 50 * BAR, 100 * BAR, 150 * BAR, 200 * BAR, 250 * BAR]
    d_p, c_tot = 6.684e-7, 5.1e-12
    table = []
    for w in omegas:
        for p in pds:
            c = c_tot * (0.8 + 0.4 * p / (250 * BAR))
            table.append(round(min(1.0, max(0.05, 1.0 - c * p / (d_p * w))), 5))
    return omegas, pds, table


_ETA_W, _ETA_P, _ETA = _synthetic_eta_table()

P = 'plant.'


def check(v: dict) -> None:
    """Ts / drive.period an integer that divides sim.substeps; len(pump.eta_v) =
    len(eta_v_omega) len(eta_v_pd), both grids strictly increasing; friction.F_s >= F_c
    (eq. 3.33); drive.delay a whole number of ticks; accumulator.p_init above P_0."""
    ts, period, substeps = v[P + 'sim.Ts'], v[P + 'drive.period'], v[P + 'sim.substeps']
    ratio = ts / period
    if abs(ratio - round(ratio)) > 1e-9 or substeps % int(round(ratio)):
        raise ParamError(f'plant.sim.substeps = {substeps} with plant.drive.period = '
                         f'{period:g}: expected Ts/period an integer that divides substeps',
                         P + 'sim.substeps')
    n_w, n_p, n = (len(v[P + 'pump.eta_v_omega']), len(v[P + 'pump.eta_v_pd']),
                   len(v[P + 'pump.eta_v']))
    if n != n_w * n_p:
        raise ParamError(f'plant.pump.eta_v has {n} values: expected '
                         f'len(eta_v_omega)*len(eta_v_pd) = {n_w * n_p}', P + 'pump.eta_v')
    for key in ('pump.eta_v_omega', 'pump.eta_v_pd'):
        arr = list(v[P + key])
        if any(b <= a for a, b in zip(arr, arr[1:])):
            raise ParamError(f'plant.{key} = {arr}: expected strictly increasing values', P + key)
    f_s, f_c = v[P + 'friction.F_s'], v[P + 'friction.F_c']
    if f_s < f_c:
        raise ParamError(f'plant.friction.F_s = {f_s}: expected >= plant.friction.F_c = {f_c} '
                         f'(static friction at least the Coulomb level, eq. 3.33)',
                         P + 'friction.F_s')
    delay = v[P + 'drive.delay']
    if abs(delay / ts - round(delay / ts)) > 1e-6:
        raise ParamError(f'plant.drive.delay = {delay}: expected a whole number of ticks of '
                         f'{ts} s', P + 'drive.delay')
    p_init, p_0 = v[P + 'accumulator.p_init'], v[P + 'accumulator.P_0']
    if p_init <= p_0:
        raise ParamError(f'plant.accumulator.p_init = {p_init}: expected above the pre-charge '
                         f'plant.accumulator.P_0 = {p_0}', P + 'accumulator.p_init')


PLANT_SCHEMA = Schema('plant_sim', [
    # numerics
    Param(P + 'sim.Ts', 'float', 's', 1.0e-3, 1.0e-4, 1.0e-2,
          doc='tick (sample) period of the SIL stack (1 kHz, DESIGN.md)'),
    Param(P + 'sim.substeps', 'int', '', 16, 1, 4096,
          doc='integration sub-steps per tick (16: h = 62.5 us); a multiple of Ts/drive.period '
              '(choice)'),
    Param(P + 'sim.theta', 'float', '', 0.5, 0.5, 1.0,
          doc='theta-method weight of the linear hydro-mechanical terms (0.5 trapezoidal; '
              'choice)'),
    Param(P + 'sim.theta_stiff', 'float', '', 1.0, 0.5, 1.0,
          doc='theta-method weight of friction and end-stop forces (1 = backward Euler; '
              '0.5..1, choice)'),
    Param(P + 'sim.newton_max_iter', 'int', '', 8, 1, 50,
          doc='cap of the Newton iterations per sub-step (choice)'),
    Param(P + 'sim.newton_tol', 'float', '', 1.0e-5, 1.0e-16, 1.0e-3,
          doc='Newton stop: scaled last step (p/1e7 Pa, v/0.1 m/s); quadratic convergence '
              'leaves an error ~tol^2 (choice)'),
    # fluid and cylinder
    Param(P + 'fluid.beta', 'float', 'Pa', min=1.0e8, max=5.0e9, doc='Table 3.8'),
    Param(P + 'cylinder.A_p', 'float', 'm^2', min=1e-5, max=1e-1, doc='Table 3.8'),
    Param(P + 'cylinder.V_d', 'float', 'm^3', min=1e-6, max=1e-1, doc='Table 3.8'),
    Param(P + 'cylinder.m_p', 'float', 'kg', min=0.01, max=1000.0, doc='Table 3.8'),
    Param(P + 'cylinder.C_c', 'float', 'm^3/(s Pa)', 0.5e-12, 0.0, 1e-9,
          doc='cross-piston leakage; share of C_eq = C_p + C_c + C_r/2 = 3.8e-12 (eq. 3.22, '
              'Table 3.8; the split is a choice)'),
    Param(P + 'cylinder.stroke', 'float', 'm', min=1e-3, max=2.0, doc='Table 3.1'),
    Param(P + 'cylinder.stop_k', 'float', 'N/m', 1.0e8, 1e4, 1e11,
          doc='end-stop stiffness (choice, not in the thesis)'),
    Param(P + 'cylinder.stop_c', 'float', 'N/(m/s)', 2.0e4, 0.0, 1e8,
          doc='end-stop damping (choice, not in the thesis)'),
    # friction, Table 3.7, eq. 3.33
    Param(P + 'friction.model', 'str', '', 'stribeck', choices=('stribeck', 'viscous', 'none'),
          field='friction_model',
          doc='stribeck = eq. 3.33; viscous = mu v only (the linear b of eq. 3.23); none'),
    Param(P + 'friction.F_c', 'float', 'N', 450.0, 0.0, 1e5, doc='Coulomb friction, Table 3.7'),
    Param(P + 'friction.F_s', 'float', 'N', 800.0, 0.0, 1e5, doc='static friction, Table 3.7'),
    Param(P + 'friction.v_s', 'float', 'm/s', 0.03, 1e-5, 10.0,
          doc='Stribeck velocity, Table 3.7'),
    Param(P + 'friction.mu', 'float', 'N/(m/s)', 1120.0, 0.0, 1e6,
          doc='viscous friction, Table 3.7 (= b of Table 3.8)'),
    # pump, eq. 3.15/3.31
    Param(P + 'pump.D_p', 'float', 'm^3/rad', min=1e-9, max=1e-4, doc='Table 3.8'),
    Param(P + 'pump.C_p', 'float', 'm^3/(s Pa)', 1.5e-12, 0.0, 1e-9,
          doc='cross-port leakage, eq. 3.15; share of C_eq (choice)'),
    Param(P + 'pump.C_r', 'float', 'm^3/(s Pa)', 3.6e-12, 0.0, 1e-9,
          doc='per-port external leakage to the accumulator circuit, eq. 3.15; share of C_eq '
              '(choice)'),
    Param(P + 'pump.leakage_model', 'str', '', 'linear', choices=('linear', 'table'),
          doc='linear = eq. 3.15; table = volumetric-efficiency map eta_v(omega, p_D), '
              'eq. 3.31'),
    Param(P + 'pump.eta_v_omega', 'float[]', 'rad/s', _ETA_W, 0.0, 1e4, min_len=2,
          doc='map grid of |omega|'),
    Param(P + 'pump.eta_v_pd', 'float[]', 'Pa', _ETA_P, 0.0, 1e9, min_len=2,
          doc='map grid of |p_D|'),
    Param(P + 'pump.eta_v', 'float[]', '', _ETA, 0.0, 1.0, min_len=4,
          doc='row-major [omega][p_D] volumetric efficiency; default SYNTHETIC (leakage '
              '0.8..1.2 x (C_p + C_r) over 0..250 bar), not the Fig. 3.39 data'),
    # motor, eq. 3.10-3.14
    Param(P + 'motor.model', 'str', '', 'dc', choices=('dc', 'dq'), field='motor_model',
          doc='dc = eqs. 3.13-3.14; dq = eqs. 3.10-3.12 with i_d controlled to 0'),
    Param(P + 'motor.R', 'float', 'ohm', 0.45, 1e-4, 100.0,
          doc='armature resistance, Table 3.8'),
    Param(P + 'motor.L', 'float', 'H', 2.1e-3, 1e-6, 1.0, doc='inductance, Table 3.8'),
    Param(P + 'motor.k_T', 'float', 'Nm/A', min=1e-3, max=100.0),
    Param(P + 'motor.k_E', 'float', 'V/(rad/s)', 0.53, 1e-3, 100.0,
          doc='back-EMF constant, Table 4.5 / appendix D.1'),
    Param(P + 'motor.J_eq', 'float', 'kg m^2', 5.93e-4, 1e-7, 10.0,
          doc='motor-pump inertia, Table 3.8'),
    Param(P + 'motor.b_eq', 'float', 'Nm/(rad/s)', 4.26e-3, 0.0, 10.0,
          doc='motor-pump viscous damping, appendix D.1 (Table 3.8\'s "100" is a typo)'),
    Param(P + 'motor.n_p', 'int', '', 5, 1, 64,
          doc='pole pairs (dq model only; choice); lambda_m = k_T/(1.5 n_p)'),
    Param(P + 'motor.L_d', 'float', 'H', 2.1e-3, 1e-6, 1.0,
          doc='d inductance, dq model (choice: = L)'),
    Param(P + 'motor.L_q', 'float', 'H', 2.1e-3, 1e-6, 1.0,
          doc='q inductance, dq model (choice: = L)'),
    # drive, eq. 3.34, 4.65, 4.71
    Param(P + 'drive.period', 'float', 's', 62.5e-6, 1e-6, 1e-3,
          doc='current/speed loop period (16 kHz, choice)', field='drive_period'),
    Param(P + 'drive.Kp_i', 'float', 'V/A', 11.3, 0.0, 1e4,
          doc='current loop P gain, Table 3.8, eq. 3.34'),
    Param(P + 'drive.Ki_i', 'float', 'V/(A s)', 14125.0, 0.0, 1e8,
          doc='current loop I gain, Table 3.8 (= 11.3/0.8 ms, D.1)'),
    Param(P + 'drive.Kp_w', 'float', 'Nm/(rad/s)', 0.45, 0.0, 1e3),
    Param(P + 'drive.Ki_w', 'float', 'Nm/rad', 56.0, 0.0, 1e6),
    Param(P + 'drive.lowpass_w', 'float', 'rad/s', 2555.0, 1.0, 1e6),
    Param(P + 'drive.V_max', 'float', 'V', 480.0, 1.0, 1e4,
          doc='voltage limit, sec. 3.4 (+-480 V)'),
    Param(P + 'drive.I_max', 'float', 'A', 36.0, 0.1, 1e4,
          doc='current reference limit (choice; AX5118: 18 A nominal, 2x peak)'),
    Param(P + 'drive.omega_max', 'float', 'rad/s', 8000 * RPM, 1.0, 1e5),
    Param(P + 'drive.delay', 'float', 's', 1.0e-3, 0.0, 0.1,
          doc='drive delay on the speed reference, whole ticks (sec. 3.6.4 mentions driver '
              'delay)'),
    # accumulator, eq. 3.18
    Param(P + 'accumulator.V_0', 'float', 'm^3', 6.0e-3, 1e-5, 1.0, field='acc_V_0',
          doc='accumulator volume, Table 3.2 (6 L)'),
    Param(P + 'accumulator.P_0', 'float', 'Pa', 8.0e5, 0.0, 1e8,
          doc='gas pre-charge, gauge (choice)', field='acc_P_0'),
    Param(P + 'accumulator.p_init', 'float', 'Pa', 10.0e5, 0.0, 1e8,
          doc='initial (idle/boost) pressure, gauge (choice, ~10 bar)', field='acc_p_init'),
    Param(P + 'accumulator.p_atm', 'float', 'Pa', 101325.0, 0.0, 2e5,
          doc='atmosphere, for the absolute gas law of eq. 3.18'),
    # valves
    Param(P + 'valves.check_K', 'float', 'm^3/(s Pa)', 1.0e-9, 1e-14, 1e-5,
          doc='check valve conductance accumulator -> chamber (choice)'),
    Param(P + 'valves.check_crack', 'float', 'Pa', 0.3e5, 0.0, 1e7,
          doc='check valve cracking pressure (choice)'),
    Param(P + 'valves.relief_crack', 'float', 'Pa', 255e5, 1e5, 1e9,
          doc='relief cracking pressure above the low-pressure circuit, Table 3.2'),
    Param(P + 'valves.relief_K', 'float', 'm^3/(s Pa)', 5.0e-10, 1e-14, 1e-5,
          doc='relief valve opening gain (choice)'),
    Param(P + 'valves.band', 'float', 'Pa', 0.05e5, 1.0, 1e6,
          doc='width of the smooth (C1) opening of check and relief valves: lets Newton '
              'converge (choice)'),
    Param(P + 'valves.onoff_time', 'float', 's', 0.02, 0.0, 10.0,
          doc='on-off valve opening/closing time, Fig. 3.12 (choice)'),
    Param(P + 'valves.bypass_time', 'float', 's', 0.02, 0.0, 10.0,
          doc='A-B bypass valve opening time (choice)'),
    Param(P + 'valves.bypass_K', 'float', 'm^3/(s Pa)', 1.0e-9, 0.0, 1e-5,
          doc='A-B bypass conductance when open (choice)'),
    # sensors (thesis 4.1.2, Fig 4.6)
    Param(P + 'sensors.noise', 'bool', '', True, field='sensor_noise',
          doc='false: noise-free sensors (faults still act)'),
    Param(P + 'sensors.position_sigma', 'float', 'm', 10e-6, 0.0, 1e-2,
          doc='MSP white noise sigma (choice, cf. Fig. 4.6)'),
    Param(P + 'sensors.position_gm_sigma', 'float', 'm', 20e-6, 0.0, 1e-2,
          doc='MSP low-frequency Gauss-Markov sigma (choice, cf. Fig. 4.6)'),
    Param(P + 'sensors.position_gm_corner', 'float', 'Hz', 1.0, 1e-3, 1e3,
          doc='Gauss-Markov corner frequency (choice)'),
    Param(P + 'sensors.position_resolution', 'float', 'm', 1e-6, 0.0, 1e-2,
          doc='MSP resolution (choice)'),
    Param(P + 'sensors.speed_sigma', 'float', 'rad/s', 0.1, 0.0, 100.0,
          doc='encoder speed noise (choice, small)'),
    Param(P + 'sensors.current_sigma', 'float', 'A', 0.02, 0.0, 10.0,
          doc='current measurement noise (choice, small)'),
    Param(P + 'sensors.pressure_sigma', 'float', 'Pa', 0.316 * BAR, 0.0, 1e7,
          doc='pressure sensor noise, sec. 4.1.2 (0.316 bar)'),
], check=check)


_PYTYPE = {'float': float, 'int': int, 'bool': bool, 'str': str, 'float[]': tuple}
# one attribute per plant.* Param, named by its field (the declaration above is the only one)
_Fields = make_dataclass('_Fields', [(p.attr, _PYTYPE[p.type]) for p in PLANT_SCHEMA.params],
                         frozen=True)


class PlantParams(_Fields):
    """Typed, validated plant parameters (SI units), one attribute per ``plant.*`` Param of
    PLANT_SCHEMA (its ``attr``); build with :meth:`from_dict`."""

    @property
    def C_eq(self) -> float:
        """Total leakage coefficient of eq. 3.22: C_p + C_c + C_r/2."""
        return self.C_p + self.C_c + 0.5 * self.C_r

    @property
    def lambda_m(self) -> float:
        """PM flux linkage consistent with k_T = 1.5 n_p lambda_m (eq. 3.12 vs 3.13)."""
        return self.k_T / (1.5 * self.n_p)

    @property
    def b(self) -> float:
        """Linear viscous piston damping of eq. 3.23 (= mu of eq. 3.33, 1120 in Table 3.8)."""
        return self.mu

    @property
    def x_stop(self) -> float:
        """End-stop position (half stroke, x = 0 mid-stroke)."""
        return 0.5 * self.stroke

    @property
    def drive_ratio(self) -> int:
        """Drive samples per tick."""
        return int(round(self.Ts / self.drive_period))

    @property
    def delay_ticks(self) -> int:
        return int(round(self.delay / self.Ts))

    @property
    def h(self) -> float:
        """Integration sub-step (s)."""
        return self.Ts / self.substeps

    @property
    def drive_every(self) -> int:
        """Sub-steps per drive sample."""
        return self.substeps // self.drive_ratio

    @property
    def friction_code(self) -> int:
        """friction_model as friction.friction's ``model``: 0 none, 1 viscous, 2 Stribeck."""
        return {'none': 0, 'viscous': 1, 'stribeck': 2}[self.friction_model]

    @property
    def leakage_tabulated(self) -> bool:
        """Pump leakage from the eta_v map (:func:`leakage_table`), not C_p and C_r."""
        return self.leakage_model == 'table'

    @property
    def dq(self) -> bool:
        """d-q motor model (eq. 3.10-3.12), not the DC one."""
        return self.motor_model == 'dq'

    @property
    def current_pole(self) -> float:
        """exp(-R h / L): the motor current's decay over a sub-step."""
        return math.exp(-self.R * self.h / self.L)

    @property
    def lowpass_pole(self) -> float:
        """exp(-lowpass_w drive_period): the speed loop's low-pass over a drive sample."""
        return math.exp(-self.lowpass_w * self.drive_period)

    @property
    def onoff_rate(self) -> float:
        """On-off valve opening fraction per sub-step (1: at once)."""
        return self.h / self.onoff_time if self.onoff_time > 0 else 1.0

    @property
    def bypass_rate(self) -> float:
        """Bypass valve opening fraction per sub-step (1: at once)."""
        return self.h / self.bypass_time if self.bypass_time > 0 else 1.0

    @property
    def position_gm_pole(self) -> float:
        """exp(-2 pi f_c Ts): the position sensor's Gauss-Markov pole per tick."""
        return math.exp(-2.0 * math.pi * self.position_gm_corner * self.Ts)

    @classmethod
    def from_dict(cls, values: dict) -> 'PlantParams':
        """Build from ``load(PLANT_SCHEMA, files)``: validated again (defaults filled, the
        cross-key checks of :func:`check`, one line for a missing identity parameter)."""
        v = PLANT_SCHEMA.validate({k: x for k, x in values.items() if k.startswith(P)},
                                  context='plant parameters')
        return cls(**{spec.attr: tuple(v[spec.name]) if isinstance(v[spec.name], list)
                      else v[spec.name] for spec in PLANT_SCHEMA.params})


# the parameter vector the compiled kernels read: each layout.P_* index and the PlantParams
# attribute that gives its value, in index order
PACKED = {
    L.P_H: 'h', L.P_THETA: 'theta', L.P_NEWTON_N: 'newton_max_iter',
    L.P_NEWTON_TOL: 'newton_tol', L.P_DRIVE_EVERY: 'drive_every',
    L.P_BETA: 'beta', L.P_AP: 'A_p', L.P_VD: 'V_d', L.P_MP: 'm_p', L.P_CC: 'C_c',
    L.P_XSTOP: 'x_stop', L.P_KSTOP: 'stop_k', L.P_CSTOP: 'stop_c',
    L.P_FRIC: 'friction_code', L.P_FC: 'F_c', L.P_FS: 'F_s', L.P_VS: 'v_s', L.P_MU: 'mu',
    L.P_DP: 'D_p', L.P_CP: 'C_p', L.P_CR: 'C_r', L.P_LEAK_TABLE: 'leakage_tabulated',
    L.P_DQ: 'dq', L.P_R: 'R', L.P_L: 'L', L.P_KT: 'k_T', L.P_KE: 'k_E', L.P_J: 'J_eq',
    L.P_BEQ: 'b_eq', L.P_NP: 'n_p', L.P_LD: 'L_d', L.P_LQ: 'L_q', L.P_LAMBDA: 'lambda_m',
    L.P_TD: 'drive_period', L.P_KPI: 'Kp_i', L.P_KII: 'Ki_i', L.P_KPW: 'Kp_w',
    L.P_KIW: 'Ki_w', L.P_LPW: 'lowpass_w', L.P_VMAX: 'V_max', L.P_IMAX: 'I_max',
    L.P_WMAX: 'omega_max', L.P_EXP_RL: 'current_pole', L.P_EXP_LP: 'lowpass_pole',
    L.P_ACC_V0: 'acc_V_0', L.P_ACC_P0: 'acc_P_0', L.P_PATM: 'p_atm',
    L.P_CHECK_K: 'check_K', L.P_CHECK_CRACK: 'check_crack',
    L.P_RELIEF_CRACK: 'relief_crack', L.P_RELIEF_K: 'relief_K',
    L.P_ONOFF_RATE: 'onoff_rate', L.P_BYPASS_RATE: 'bypass_rate', L.P_BYPASS_K: 'bypass_K',
    L.P_X_SIGMA: 'position_sigma', L.P_GM_SIGMA: 'position_gm_sigma',
    L.P_GM_A: 'position_gm_pole', L.P_X_RES: 'position_resolution',
    L.P_W_SIGMA: 'speed_sigma', L.P_I_SIGMA: 'current_sigma', L.P_PR_SIGMA: 'pressure_sigma',
    L.P_NOISE_ON: 'sensor_noise', L.P_THETA_STIFF: 'theta_stiff', L.P_VALVE_BAND: 'band',
}
assert sorted(PACKED) == list(range(L.NPAR)), 'PACKED: one entry per layout.P_* index'


def pack(p: PlantParams) -> np.ndarray:
    """Flat float64 parameter vector for the compiled kernels (:data:`PACKED`)."""
    return np.array([float(getattr(p, PACKED[i])) for i in range(L.NPAR)])


def leakage_table(p: PlantParams) -> np.ndarray:
    """Total pump leakage coefficient map C(|omega|, |p_D|) from eta_v (eq. 3.31).

    C = D_p |omega| (1 - eta_v) / p_D; at p_D = 0 the coefficient of the next pressure column
    is used (the flow there is zero anyway). Returned as one array T of shape (n_w+1, n_p+1):
    T[0, 1:] = p_D grid, T[1:, 0] = omega grid, T[1:, 1:] = C.
    """
    w = np.asarray(p.eta_v_omega, float)
    pd = np.asarray(p.eta_v_pd, float)
    eta = np.asarray(p.eta_v, float).reshape(len(w), len(pd))
    c = np.zeros_like(eta)
    for j, pj in enumerate(pd):
        if pj > 0:
            c[:, j] = p.D_p * w * (1.0 - eta[:, j]) / pj
    for j, pj in enumerate(pd):
        if pj <= 0:
            c[:, j] = c[:, j + 1] if j + 1 < len(pd) else 0.0
    table = np.zeros((len(w) + 1, len(pd) + 1))
    table[0, 1:] = pd
    table[1:, 0] = w
    table[1:, 1:] = c
    return table


def plant_file() -> str:
    """The shipped plant parameter file, config/plant.yaml (or $EHA_CONFIG_DIR/plant.yaml)."""
    import os
    from ..config.params import default_config_dir
    return os.path.join(default_config_dir(), 'plant.yaml')


def nominal_plant(overrides: dict | None = None) -> dict:
    """Loaded and validated plant parameters from :func:`plant_file` plus overrides."""
    from ..config.params import load
    return load(PLANT_SCHEMA, [plant_file()], overrides or {})
