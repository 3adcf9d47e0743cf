"""The position estimator the node wraps: one :meth:`Estimator.update` per measured state.

Per tick: validate the measurement (finite, position within stroke +- margin, pressures in
the sensor range, motor speed in range), predict one Ts with the active channel's motor speed
(eq. 4.1-4.2; mean of the previous and current sample held over the period), update with the
valid measurements (eq. 4.4-4.6, Joseph form), run the fault detector on the innovation.
A rejected position means predict only (``update_skipped``), and so does one held back as a
suspected jump's (the isolate stage); rejected pressures fall back to a position-only update;
a rejected motor speed holds the last good one. Each rejection is counted in ``counters`` by
reason.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kernel_records import entry_point
from ..plant.hydromech import circuit, hydromech
from ..plant.parameters import PlantParams
from ..stats import Counters
from . import adapt
from . import fault_detector as fd
from . import kernels
from . import noise_level
from . import sensor_band
from . import stepper
from .chamber_kf import ChamberKF
from .model_kf import ModelKF
from .params import adaptive_prior, drift_q, on
from .pva import PvaKF

# a motor-speed reading beyond this times the drive's speed reference limit
# (plant.drive.omega_max, 8000 rpm) is not physical: rejected, the last good one held
MOTOR_SPEED_MARGIN = 1.5
# a position reading beyond +-(stroke/2 + this) is not physical: rejected, predict only (a
# knob until issue 44's screen: 2.5 and 10 mm changed no campaign figure, random:50)
POSITION_MARGIN = 5.0e-3    # [m]


@dataclass
class EstimateResult:
    """One estimate (SI units); fields as eha_msgs/PositionEstimate."""

    position: float
    velocity: float
    pressure_diff: float
    position_variance: float
    innovation: float
    nis: float
    update_skipped: bool
    sensor_fault: int
    rejected: str = ''             # reasons, comma separated ('' when all was used)
    nis_dim: int = 0               # measurement dimension behind nis (0: no update)
    consistency: int = 0           # adapt.OK / MODEL / SENSOR / DISAGREE (adapt.VERDICTS)
    motor_speed: float = math.nan  # the model's input: the active motor's speed (rad/s)
    leak_flow: float = math.nan    # the flow the loaded chamber leaks (m^3/s, stepper.leak_flow)


def build_filter(p: dict):
    """The configured filter from parameters: the chamber-pressure model KF (chamber_kf), the
    model KF of eq. 4.35 (model_kf) or the PVA filter of eq. 4.30-4.34."""
    pp = PlantParams.from_dict(p)
    e = 'estimator.'
    s = 'plant.sensors.'                      # the sensor model: R and the offset state
    sig, gm_sig = p[s + 'position_sigma'], p[s + 'position_gm_sigma']
    if p[e + 'filter'] == 'pva':
        return PvaKF(pp.Ts, p[e + 'pva.W'], sig ** 2 + gm_sig ** 2, p[e + 'pva.p0'])
    gm = (gm_sig, p[s + 'position_gm_corner']) if on(p, 'sensor_offset') else None
    R_pos = sig ** 2 if gm else sig ** 2 + gm_sig ** 2
    with_p = p[e + 'measurements'] == 'position_pressure'
    if p[e + 'model.structure'] == 'chambers':
        q = list(p[e + 'model.q'][:2]) + [p[e + 'model.q_chamber']]
        m = e + 'model.'
        # the adaptive flow parameters need the measured pressures (the flow balance): none
        # with position-only measurements, where they are unobservable
        lam, dlt, kap, phi, eps = ((drift_q(p, k), *adaptive_prior(k))
                                   if on(p, 'adapt_' + k) and with_p else None
                                   for k in ('leakage', 'displacement', 'compliance', 'friction',
                                             'external_leakage'))
        fric = None
        if on(p, 'stribeck_friction'):     # the plant's curve; none without Coulomb part
            coulomb = pp.friction_model == 'stribeck'
            fric = (pp.F_c if coulomb else 0.0, pp.F_s if coulomb else 0.0, pp.v_s,
                    adapt.lowpass_alpha(p[m + 'friction_lowpass'], pp.Ts), p[m + 'rest_velocity'],
                    round(p[m + 'rest_time'] / pp.Ts), p[m + 'q_load_rest'])
        kf = ChamberKF(circuit(pp), pp.Ts, q, p[e + 'model.p0'], R_pos,
                       p[s + 'pressure_sigma'] ** 2 if with_p else None, gm,
                       F_s=pp.F_s, v_eps=p[e + 'model.v_eps'],
                       q_load=p[e + 'model.q_load'] if on(p, 'load_state') else None,
                       p0_load=p[e + 'model.p0_load'], leakage=lam, displacement=dlt,
                       compliance=kap, adapt_gate=p[m + 'adapt_gate'],
                       offset_bound=sensor_band.from_params(p).offset_bound if gm else 0.0,
                       friction=fric, friction_scale=phi, external=eps,
                       flow=on(p, 'flow_state') and with_p)
        kf.friction_uses_pressure = p[e + 'model.friction_pressure']
        if gm and with_p:       # a load step moves the piston, the sensor offset stays
            kf.set_moved_gate(kf.i_gm, p[m + 'load_jump_z'])
        return kf
    h = hydromech(pp, p[e + 'model.pd_leakage'])
    R_pd = 2.0 * p[s + 'pressure_sigma'] ** 2 if with_p else None
    kf = ModelKF(h, pp.Ts, p[e + 'model.q'], p[e + 'model.p0'], R_pos, R_pd, gm,
                 F_s=pp.F_s, v_eps=p[e + 'model.v_eps'],
                 q_leak=p[e + 'model.q_leak'] if on(p, 'leak_state') else None,
                 p0_leak=p[e + 'model.p0_leak'],
                 q_load=p[e + 'model.q_load'] if on(p, 'load_state') else None,
                 p0_load=p[e + 'model.p0_load'])
    kf.friction_uses_pressure = p[e + 'model.friction_pressure']
    return kf


class Estimator:
    """Position estimator of the SIL stack: ``Estimator(params)`` with the estimator schema's
    values (core.estimator.params.SCHEMA)."""

    def __init__(self, params: dict):
        kernels.warm_up()
        self.p = params
        pp = PlantParams.from_dict(params)
        e = 'estimator.'
        self.Ts = pp.Ts
        self.kf = build_filter(params)
        self.chambers = isinstance(self.kf, ChamberKF)
        self.is_model = self.chambers or isinstance(self.kf, ModelKF)
        self.x_max = 0.5 * pp.stroke + POSITION_MARGIN
        self.pressure_min = params[e + 'validity.pressure_min']
        self.pressure_max = params[e + 'validity.pressure_max']
        self.max_abs_motor_speed = MOTOR_SPEED_MARGIN * params['plant.drive.omega_max']
        self.isolate = on(params, 'isolate')
        self.alpha_pressure = adapt.lowpass_alpha(adapt.PRESSURE_LOWPASS, self.Ts)
        self.alpha_friction = adapt.lowpass_alpha(params[e + 'model.friction_lowpass'], self.Ts)
        self.detector = fd.FaultDetector.from_params(params, self.Ts)
        mk = np.zeros(adapt.NMK)                   # consistency monitor (adapt.monitor)
        mk[adapt.MK_ALPHA] = adapt.lowpass_alpha(params[e + 'monitor.lowpass'], self.Ts)
        mk[adapt.MK_BAND] = sensor_band.from_params(params).band
        mk[adapt.MK_N] = params[e + 'monitor.debounce']
        mk[adapt.MK_HOLD] = int(round(params[e + 'hold_time'] / self.Ts))
        self.monitor_k = mk
        m = e + 'model.'
        self.i_load = -1 if not self.is_model or self.kf.i_load is None else self.kf.i_load
        self.q_load, self.q_load_jump = params[m + 'q_load'], params[m + 'q_load_jump']
        self.load_jump_z = params[m + 'load_jump_z']
        self.q_x, self.q_x_disagree = params[m + 'q'][0], params[m + 'q_x_disagree']
        self.position_gm_sigma = params['plant.sensors.position_gm_sigma']
        self.q_flow, self.flow_gate = params[m + 'q_flow'], params[m + 'flow_gate']
        self.flow_ticks = round(params[m + 'flow_time'] / self.Ts)
        self.flow_share, self.flow_report = params[m + 'flow_share'], adapt.FLOW_REPORT
        self.flow_s = np.zeros(adapt.NFLOW)       # adapt.flow_noise's state
        self.q_x_offset = params[m + 'q_x_offset']
        self.hold_rate = (self.Ts / params[m + 'hold_blend_time'] if on(params, 'hold_blend')
                          else 0.0)
        self.alpha_load = (self.Ts / params[m + 'offset_load_mean'],
                           self.Ts / adapt.LOAD_VARIANCE_TIME)
        self.load_hold = round(adapt.LOAD_SWING_HOLD / self.Ts)
        self.load_s = np.zeros(adapt.NLV)         # adapt.load_variation's state
        self.monitor_s = np.zeros(adapt.NMS)
        self.noise_k = self._noise_constants(params, pp) if self.chambers else None
        self.noise_s = np.zeros(noise_level.NNS)
        self.noise_s[[noise_level.NS_SX, noise_level.NS_SP]] = 1.0   # datasheet's unless measured
        self.chinniah = None
        if on(params, 'chinniah'):
            from .chinniah import ChinniahEstimator
            self.chinniah = ChinniahEstimator(pp.m_p, pp.A_p, self.Ts)
        self.counters = Counters()
        self.max_gap_ticks = 1000       # a longer gap is predicted over at most 1 s
        # the compiled tick's constants, state and arrays (core.estimator.stepper): the state
        # arrays above become views into its state record, the scalars are read from it
        self.kernel = stepper.pack(self)
        self.E = E = self.kernel[1]
        self.i_gm = int(self.kernel[0]['i_gm'][0])
        self._leak_flow = entry_point(stepper.leak_flow, self.kernel[0], self.kf.x)
        self.detector.s, self.monitor_s = E['detector'][0], E['monitor'][0]
        self.noise_s, self.flow_s, self.load_s = E['noise'][0], E['flow'][0], E['load'][0]
        if self.chambers:
            self.kf.p_last, self.kf.clipped = E['p_last'][0], E['clipped'][0]
            self.kf.fs = E['friction'][0]
        # the kernels' compiled functions for these arrays, called per tick (the record is
        # not typed again on every call: kernel_records.entry_point)
        kn = self.kernel
        self._estimate = entry_point(stepper.estimate, *kn, 0.0, 0.0, 0.0, 0.0, 0.0)
        self._predict_tick = entry_point(stepper.predict_tick, *kn, 0.0, 0.0, 0.0)
        self._advance = entry_point(stepper.advance, *kn, 0.0, 0.0, 0.0)
        self._consistency = entry_point(stepper.consistency, *kn, 0.0)
        self.reset()

    def _noise_constants(self, p: dict, pp):
        """noise_level constants from the filter's sensor model, None when not adapting."""
        e, s, kf = 'estimator.noise.', 'plant.sensors.', self.kf
        if not on(p, 'noise_level'):
            return None
        sig, gm_sig = p[s + 'position_sigma'], p[s + 'position_gm_sigma']
        a = math.exp(-2.0 * math.pi * p[s + 'position_gm_corner'] * self.Ts)
        with_gm = kf.i_gm >= 0
        d_x = noise_level.second_difference_power(sig, gm_sig, a, pp.position_resolution)
        d_p = noise_level.second_difference_power(p[s + 'pressure_sigma'], 0.0, 0.0, 0.0)
        lo, hi = p[e + 'adapt_range'][:2]
        return noise_level.constants(
            self.Ts, noise_level.MEMORY, lo, hi, d_x, d_p, kf.R[0, 0],
            kf.R[1, 1] if kf.with_pressure else 0.0,
            kf.Q[kf.i_gm, kf.i_gm] if with_gm else 0.0, kf.i_gm,
            p[e + 'adapt_quiet_velocity'] * pp.A_p / pp.D_p)

    def _scalar(name):
        return property(lambda self: float(self.E[name][0]),
                        lambda self, v: self.E.__setitem__(name, v),
                        doc=f"stepper.STATE's {name}")

    omega_prev = _scalar('omega')
    w_fric, pd_meas, pd_filt = _scalar('w_fric'), _scalar('pd_meas'), _scalar('pd_filt')
    del _scalar

    @property
    def updates(self) -> int:
        """Measurement updates so far."""
        return int(self.E['updates'][0])

    def reset(self):
        self.started = False
        self._saved = None
        self.omega_prev = self.w_fric = self.pd_meas = self.pd_filt = 0.0
        self.E['updates'] = self.E['hold_weight'] = self.E['hold_v'] = self.E['hold_n'] = 0.0
        self.detector.reset()
        self.monitor_s[:] = 0.0
        self.flow_s[:] = 0.0
        self.load_s[:] = 0.0
        if self.noise_k is not None:
            noise_level.reset(self.noise_k, self.noise_s, self.kf.R, self.kf.R1, self.kf.Q)

    def stop_pressures(self) -> bool:
        """The chamber pressure sensors were blamed (/eha/redundancy pressure_sensors_failed):
        from here on the filter updates on the position alone (H1, R1), predicts with its own
        chamber pressures, and the fault detector goes without them (its jump veto asks the
        motor shaft), as with readings out of range. Returns True when this call turned them
        off."""
        on = self.use_pressure
        self.kernel[0]['use_pressure'] = 0.0
        return on

    @property
    def use_pressure(self) -> bool:
        """The filter updates on the chamber pressures: a model filter that measures them,
        until :meth:`stop_pressures`. Kept in one place, the compiled tick's constants."""
        return bool(self.kernel[0]['use_pressure'][0] > 0.5)

    # ------------------------------------------------------------------ checks
    def _position_ok(self, x) -> bool:
        return isinstance(x, (int, float)) and math.isfinite(x) and abs(x) <= self.x_max

    def _pressure_ok(self, pa, pb) -> bool:
        lo, hi = self.pressure_min, self.pressure_max
        return math.isfinite(pa) and math.isfinite(pb) and lo <= pa <= hi and lo <= pb <= hi

    def _speed(self, motor_speed, active_channel):
        """Active channel's speed if valid, else the last good one (counted)."""
        ch = int(active_channel) if active_channel in (0, 1) else -1
        if ch < 0:
            self.counters.bump('rejected_channel')
            return self.omega_prev, 'channel'
        w = float(motor_speed[ch])
        if not (math.isfinite(w) and abs(w) <= self.max_abs_motor_speed):
            self.counters.bump('rejected_motor_speed')
            return self.omega_prev, 'motor_speed'
        return w, ''

    # ------------------------------------------------------------------ tick
    def update(self, position: float, motor_speed, pressure_a: float, pressure_b: float,
               active_channel: int, ticks: int = 1, valid: bool = True,
               motor_current=None) -> EstimateResult:
        """One measured state -> one estimate. ``ticks``: periods Ts since the previous state
        (more than 1 after lost states; the missing ones are predicted with the held speed).
        ``motor_current``: both motors' measured currents (A; None: not known), the active one's
        for the fault detector's torque balance when a pressure reading is missing.
        Predict-only (stale) steps taken since the previous state are provisional: they are
        undone here and replaced by exactly ``ticks`` predictions. A state the plant side
        marked not ``valid`` (a repeated or stale device sample) is predicted over with the
        held speed, like a rejected one, and is no evidence for the fault detector."""
        if self._saved is not None:
            self.kf.x[:], self.kf.P[:], self.omega_prev, self.w_fric, p_last, fs = self._saved
            if p_last is not None:
                self.kf.p_last[:] = p_last
                self.kf.fs[:] = fs
            self._saved = None
        position = float(position)
        pressure_a, pressure_b = float(pressure_a), float(pressure_b)
        if valid:
            w, why_w = self._speed(motor_speed, active_channel)
            pos_ok = self._position_ok(position)
            pr_ok = self._pressure_ok(pressure_a, pressure_b)
            reasons = [] if pos_ok and (pr_ok or not self.use_pressure) and not why_w else \
                [r for r in (why_w, '' if pos_ok else 'position',
                             '' if pr_ok or not self.use_pressure else 'pressure') if r]
            if not pos_ok:
                self.counters.bump('rejected_position')
            if not pr_ok and self.use_pressure:
                self.counters.bump('rejected_pressure')
        else:
            self.counters.bump('invalid_states')
            w, pos_ok, pr_ok, reasons = self.omega_prev, False, False, ['invalid']
        if not valid:
            pressure_a = pressure_b = math.nan          # no evidence: p_D is not taken either
        if not self.started:
            if pr_ok:
                self.pd_meas = pressure_a - pressure_b
            if not pos_ok:
                self.counters.bump('skipped_updates')
                return self._result(0.0, 0.0, True, ','.join(reasons), 0)
            self.kf.reset(position, *((pressure_a, pressure_b) if pr_ok else ()))
            self.pd_filt = self.pd_meas
            self.omega_prev = self.w_fric = w
            self.started = True
            self.detector.start(position)
            return self._result(0.0, 0.0, False, ','.join(reasons), 0)
        if ticks > 1:
            noise_level.gap(self.noise_s)
            self.detector.forget_speed()
        for _ in range(min(max(int(ticks), 1), self.max_gap_ticks) - 1):
            self._predict_tick(*self.kernel, self.omega_prev, math.nan, math.nan)
        fault_before = self.detector.code
        if pos_ok and not (self.isolate and fault_before in (fd.JUMP, fd.STUCK)):
            i = math.nan
            if motor_current is not None and not why_w:         # (pos_ok: valid)
                i = float(motor_current[int(active_channel)])
            _, y, nis, m, _ = self._estimate(*self.kernel, position, w, i, pressure_a,
                                             pressure_b)
            if m == 0:                  # held back as a suspected jump's: predict only
                self.counters.bump('skipped_updates')
            if self.chinniah is not None and pr_ok:
                self.chinniah.step(position, self.kf.velocity, self.pd_meas)
            return self._result(y, nis, m == 0, ','.join(reasons), m)
        self._advance(*self.kernel, w, pressure_a, pressure_b)
        noise_level.gap(self.noise_s)
        self.counters.bump('skipped_updates')
        if not pos_ok:
            self.detector.tick_without_sample()
            return self._result(0.0, 0.0, True, ','.join(reasons), 0)
        # sensor reported faulty: predict only, but keep watching its innovation
        self.counters.bump('isolated_updates')
        reasons.append('sensor_fault')
        y, S = self.kf.innovation_only(position)
        if pr_ok and self.use_pressure:
            self.kf.update_pressures(pressure_a, pressure_b)   # the pressures still count
        self.detector.update(position, y, S)
        self._monitor(position)
        return self._result(y, y * y / S, True, ','.join(reasons), 0)

    def _monitor(self, position: float) -> int:
        """Consistency verdict of this sample (stepper.consistency)."""
        return self._consistency(*self.kernel, position)

    @property
    def flow_active(self) -> bool:
        """|v_f| was above flow_report at the last update (adapt.flow_noise): an unmodelled
        flow, reported as model_mismatch."""
        return bool(self.flow_s[adapt.FL_ACTIVE])

    @property
    def consistency(self) -> int:
        """Latest verdict: adapt.OK, MODEL, SENSOR or DISAGREE (names: adapt.VERDICTS)."""
        return int(self.monitor_s[adapt.MS_VERDICT])

    @property
    def noise_levels(self):
        """Measured noise level (x the datasheet's sigma) of the position and the pressure
        sensors and whether one sits on the top of its range (noise_level); None when not
        measured."""
        if self.noise_k is None:
            return None
        sx, sp = (float(self.noise_s[i]) for i in (noise_level.NS_SX, noise_level.NS_SP))
        return sx, sp, max(sx, sp) >= self.noise_k[noise_level.NK_HI]

    @property
    def safe_state_required(self) -> bool:
        """Filter and sensor disagree beyond the sensor's band, or the sensor is faulty: the
        nodes' cue for the safe state (adapt.monitor, adapt.safe_state)."""
        return adapt.safe_state(self.consistency)

    def predict_only(self) -> EstimateResult:
        """A tick without a state (stale): predict with the last good speed (provisional,
        see :meth:`update`)."""
        if self.started:
            if self._saved is None:
                p_last = getattr(self.kf, 'p_last', None)
                self._saved = (self.kf.x.copy(), self.kf.P.copy(), self.omega_prev,
                               self.w_fric, None if p_last is None else p_last.copy(),
                               None if p_last is None else self.kf.fs.copy())
            self._predict_tick(*self.kernel, self.omega_prev, math.nan, math.nan)
        noise_level.gap(self.noise_s)
        self.detector.tick_without_sample()
        return self._result(0.0, 0.0, True, 'stale', 0)

    def _result(self, innovation, nis, skipped, rejected, m) -> EstimateResult:
        kf = self.kf
        pd = kf.pressure_diff if self.is_model else self.pd_meas
        return EstimateResult(stepper.published(self.E, kf.x, self.i_gm),
                              kf.velocity, pd, kf.position_variance, innovation,
                              nis, skipped, self.detector.code, rejected, m, self.consistency,
                              self.omega_prev if self.started else math.nan,
                              self._leak_flow(self.kernel[0], kf.x))

    @property
    def friction_alphas(self):
        """(alpha_1, alpha_2, alpha_3) of the Chinniah pair, or None when disabled."""
        return None if self.chinniah is None else self.chinniah.alphas
