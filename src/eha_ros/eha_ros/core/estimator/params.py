"""Parameters of the estimator (node and batch): estimator.* below plus the plant.* set of
config/plant.yaml (the model of eq. 4.35 is built from the same plant parameters)."""
from __future__ import annotations

from dataclasses import dataclass

from ..config.params import Param, ParamError, Schema, _chain
from ..plant.parameters import PLANT_SCHEMA

BAR = 1.0e5
E = 'estimator.'


# The numbers tools/tune_estimator derives from the Table 4.5 family and the robustness box
# (core.estimator.tuning): their one home, rewritten by tune_estimator --write. (The sensor's
# bands follow from plant.sensors at run time: core.estimator.sensor_band.)
# BEGIN tune_estimator
TUNED = {
    'model.p0_leakage': 6.236,
    'model.leakage_range': [-0.99, 30.41],
    'model.p0_external_leakage': 6.236,
    'model.external_leakage_range': [-0.99, 36.5],
    'model.p0_displacement': 0.003331,
    'model.displacement_range': [-0.325, 0.125],
    'model.p0_compliance': 0.04218,
    'model.compliance_range': [-0.5833, 0.9167],
    'model.p0_friction': 0.1818,
    'model.friction_range': [-0.875, 1.375],
}
# END tune_estimator


# the adaptive states whose parameters drift in service (viscosity, air, temperature move both
# leakage paths and the bulk modulus): a random walk of model.drift_time; the displacement is
# geometry and the friction Table 3.7's, constant for a plant (no random walk)
DRIFTING = ('leakage', 'external_leakage', 'compliance')


def adaptive_prior(name: str) -> tuple[float, float, float]:
    """(p0, lo, hi) of the adaptive model state of stage adapt_<name> (core.estimator.adapt):
    its initial variance (its spread over the family) and projection range, from TUNED. Not
    parameters: they follow from the family (config/qft_spec.yaml family.*, the random box);
    a changed family is taken in with scripts/tune_estimator --write."""
    lo, hi = TUNED[f'model.{name}_range']
    return TUNED[f'model.p0_{name}'], lo, hi


def drift_q(p: dict, name: str) -> float:
    """Per-step random-walk variance of adaptive state ``name``: p0_<name> Ts / drift_time for
    a DRIFTING one (its family sigma in drift_time), 0 for the others."""
    if name not in DRIFTING:
        return 0.0
    return adaptive_prior(name)[0] * p['plant.sim.Ts'] / p[E + 'model.drift_time']


@dataclass(frozen=True)
class Stage:
    """A stage the estimator adds to the Kalman filter of eq. 4.35: what it adds, the filter
    structure it belongs to (None: any model structure) and whether it runs by default."""

    doc: str
    structure: str | None = None
    default: bool = True


# The stages, in the order they run (docs/nodes/estimator.md); estimator.stages lists the ones
# that run (the default ones unless set).
STAGES = {
    'sensor_offset': Stage("the position sensor's low-frequency (Gauss-Markov) offset b as a "
                           "state (coloured noise, Fig. 4.6)"),
    'load_state': Stage('an external-force state (random walk): a static load balances the '
                        'measured pressures instead of biasing x (23 kN: 26 um vs 251 um '
                        'without)'),
    'leak_state': Stage('a leakage-coefficient correction state (1e-12 m^3/(s Pa) units): the '
                        'boost check valves make C_eff != C_eq', 'eq4_35'),
    'adapt_leakage': Stage('relative leakage correction lambda as a state (C_p + C_c x (1+'
                           'lambda); every leakage without adapt_external_leakage)', 'chambers'),
    'adapt_external_leakage': Stage('relative correction epsilon of the per-port leakage C_r '
                                    'as a state (C_r x (1+epsilon)); lambda then scales the '
                                    'cross-port C_p + C_c only', 'chambers'),
    'adapt_displacement': Stage('relative displacement correction delta as a state (D_p x '
                                '(1+delta))', 'chambers'),
    'adapt_compliance': Stage('relative compliance correction kappa as a state (V_d/beta x '
                              '(1+kappa))', 'chambers'),
    'adapt_friction': Stage('with stribeck_friction: relative friction correction phi as a '
                            'state (F_c, F_s x (1+phi))', 'chambers'),
    'flow_state': Stage('with stribeck_friction: an unmodelled flow v_f (velocity units, A_p '
                        'v_f into A, out of B) as a state, opened at rest while the sensor '
                        'offset is implausible, bounded by the leakage of the pressure '
                        'difference beyond friction (adapt.flow_noise): a persistent velocity '
                        'bias at rest is not a sensor offset (issue 15)', 'chambers'),
    'stribeck_friction': Stage('the piston friction of the model is the plant curve of eq. '
                               '3.33 (plant.friction F_c, F_s, v_s; Table 3.7) at the '
                               'pump-flow velocity, low-passed at friction_lowpass '
                               '(adapt.friction_input); without it (and in the eq4_35 '
                               'structure) eq. 4.36: -sign(xdot) min(|p_D A_p|, F_s) with '
                               'the plant\'s static friction plant.friction.F_s (thesis: '
                               '800 N, Table 3.7) and v_eps', 'chambers'),
    'noise_level': Stage("measure the position and pressure sensors' noise level online and "
                         "scale R (and the Gauss-Markov state's q) by it (second differences "
                         "of its readings; core.estimator.noise_level, issue 15)", 'chambers'),
    'hold_blend': Stage('while the piston rests under a held load, publish the sensor reading '
                        'without its white noise, x_hat + b (model.hold_blend_time)'),
    'isolate': Stage('skip the position update (predict only, adapted model) while a sensor '
                     'fault (jump or stuck) is reported, and undo it on the samples of a '
                     'suspected jump (fault_detector.suspect) until its debounce decides'),
    'chinniah': Stage('run the Chinniah 3-state and 4-state friction estimators (eqs. '
                      '4.15-4.29) on the estimate (analysis; not in the default list)',
                      default=False),
}
DEFAULT_STAGES = [k for k, v in STAGES.items() if v.default]


def on(p: dict, stage: str) -> bool:
    """Whether ``stage`` (a key of :data:`STAGES`) runs with parameters ``p``."""
    return stage in p[E + 'stages']


def without(p: dict, *stages: str) -> dict:
    """A copy of the parameters ``p`` with ``stages`` switched off."""
    left = [s for s in p[E + 'stages'] if s not in stages]
    return {**p, E + 'stages': left or ['']}


ESTIMATOR = Schema('estimator', [
    Param(E + 'filter', 'str', '', 'model', choices=('model', 'pva'),
          doc='model = eq. 4.35 model-based KF; pva = position-velocity-acceleration KF '
              '(eqs. 4.30-4.34)'),
    Param(E + 'stages', 'str[]', '', DEFAULT_STAGES, min_len=1,
          doc='the stages that run beyond the Kalman filter of eq. 4.35, any of: ' + '; '.join(
              f'{k} = {v.structure + " structure only: " if v.structure else ""}{v.doc}'
              for k, v in STAGES.items()) + ". [''] = none: the filter alone"),
    Param(E + 'hold_time', 'float', 's', 0.5, 0.0, 100.0,
          doc='a consistency verdict (monitor) or a detected sensor fault (fault) stays '
              'reported this long after its condition clears'),
    Param(E + 'measurements', 'str', '', 'position_pressure',
          choices=('position', 'position_pressure'),
          doc='model KF measurement set: position, or position and the pressures (p_A, p_B '
              'for chambers, p_D = p_A - p_B for eq4_35)'),
    # model of eq. 4.35
    Param(E + 'model.structure', 'str', '', 'chambers', choices=('chambers', 'eq4_35'),
          doc='chambers = states x, xdot, p_A, p_B with the boost check valves (chamber_kf); '
              'eq4_35 = states x, xdot, p_D of eq. 4.35 (model_kf)'),
    Param(E + 'model.pd_leakage', 'str', '', 'eq3_22', choices=('boost', 'eq3_22', 'eq4_35'),
          doc='eq4_35 structure only: p_D leakage: boost = 2 (C_p+C_c+C_r) beta/V_d, '
              'eq3_22 = 2 C_eq beta/V_d (as the plant), eq4_35 = C_eq beta/V_d (as printed)'),
    Param(E + 'model.rest_velocity', 'float', 'm/s', 3e-3, 0.0, 1.0,
          doc='stribeck_friction: the piston is at rest while the pump-flow velocity stays '
              'below this for rest_time (stiction: the friction is whatever holds it)'),
    Param(E + 'model.rest_time', 'float', 's', 0.1, 0.0, 100.0,
          doc='stribeck_friction: how long the pump-flow velocity stays below rest_velocity '
              'before the piston counts as at rest (stiction)'),
    Param(E + 'model.q_load_rest', 'float', 'N^2', 1000.0, 0.0, 1e12,
          doc='stribeck_friction: per-step variance added to the force state\'s random walk '
              'while the piston is at rest (stiction: the holding force is whatever holds it; '
              'the friction input is held). Campaigns over the family tried 1e2, 1e3, 3e3, '
              '1e4: above 1e3 a 1 mm sensor bias at rest is no longer told from motion'),
    Param(E + 'model.v_eps', 'float', 'm/s', 1.0e-2, 1.0e-6, 0.1,
          doc='pump-flow velocity D_p w/A_p over which eq. 4.36 friction reaches full sign '
              '(choice)'),
    Param(E + 'model.friction_pressure', 'bool', '', False,
          doc='use the measured p_D in min(|p_D A_p|, F_s) of eq. 4.36 (injects the 0.45 bar '
              'p_D noise as force noise)'),
    Param(E + 'model.friction_lowpass', 'float', 'Hz', 50.0, 0.0, 500.0,
          doc='low-pass of the motor speed that gives eq. 4.36 its sign of xdot (0 = none): '
              'command chatter above it must not flip the modelled friction'),
    Param(E + 'model.q', 'float[]', 'm^2, (m/s)^2, Pa^2', [1e-16, 1e-10, 1e6], 0.0, 1e20,
          min_len=3, doc='per-step process noise variances of x, xdot, p_D (p_D: eq4_35 only; '
                         'tuned, SIL)'),
    Param(E + 'model.q_chamber', 'float', 'Pa^2', 1.0e4, 0.0, 1e20,
          doc='per-step process noise variance of each chamber pressure (chambers structure; '
              'tuned, SIL)'),
    Param(E + 'model.p0', 'float[]', 'm^2, (m/s)^2, Pa^2', [1e-8, 1e-4, 1e10], 0.0, 1e20,
          min_len=3, doc='initial variances of x, xdot, p_D'),
    Param(E + 'model.q_leak', 'float', '(1e-12 m^3/(s Pa))^2', 1e-8, 0.0, 1e6,
          doc='per-step random-walk variance of the leakage correction'),
    Param(E + 'model.p0_leak', 'float', '(1e-12 m^3/(s Pa))^2', 4.0, 0.0, 1e6,
          doc='initial variance of the leakage correction (2e-12 m^3/(s Pa) sigma)'),
    Param(E + 'model.q_load', 'float', 'N^2', 1e-4, 0.0, 1e12,
          doc='per-step random-walk variance of the external force (stribeck_friction: the '
              'load; eq. 4.36: the load and every friction error); 1e-4: 0.01 N per tick'),
    Param(E + 'model.q_load_jump', 'float', 'N^2', 1e8, 0.0, 1e14,
          doc='per-step variance of the external force after a sample whose pressure '
              'innovation exceeds load_jump_z (a load step; adjustable-level process noise)'),
    Param(E + 'model.load_jump_z', 'float', '', 5.0, 0.0, 1e300,
          doc='normalised pressure innovation above which the force state takes q_load_jump'),
    Param(E + 'model.p0_load', 'float', 'N^2', 1e8, 0.0, 1e14,
          doc='initial variance of the external force (1e8: 10 kN sigma)'),
    # adaptive model states (chambers structure; core.estimator.adapt, issue 15): relative
    # corrections of the uncertain flow parameters of Table 4.5 as random-walk states projected
    # onto their ranges; p0 and ranges are no parameters (adaptive_prior: TUNED, DERIVED by
    # tools/tune_estimator from the Table 4.5 family + box); the drifting ones random-walk by
    # drift_q.
    Param(E + 'model.drift_time', 'float', 's', 1.0e6, 1.0, 1e15,
          doc='a drifting adaptive state (leakage, external_leakage, compliance: viscosity, '
              'entrained air and temperature move them in service) may random-walk by its '
              'family sigma sqrt(p0_<name>) in this time: q = p0_<name> Ts / drift_time per '
              'step (10 % of the spread in the 1e4 s of an oil warm-up; nominal 1 Hz sine, '
              'seeds 1-4, goal 0.25: worst RMSE ratio 0.249 at 1e6 s, 0.255 at 1e5 s, 0.27 at '
              '1e4 s)'),
    Param(E + 'model.q_flow', 'float', '(m/s)^2', 1e-9, 0.0, 1.0,
          doc='per-step random walk of v_f while open (closed: 0)'),
    Param(E + 'model.flow_gate', 'float', '', 2.0, 0.0, 1e6,
          doc='v_f opens while at rest, the load not varying (adapt.load_varying), |b| exceeds '
              'this many of its stationary sigma (at the measured noise level) ...'),
    Param(E + 'model.flow_time', 'float', 's', 0.1, 0.0, 100.0,
          doc='... for this long in a row, the pressure difference held within F_s (1 + '
              'phi_max) / A_p of its value at the start (a held load, not a sinusoidal one)'),
    Param(E + 'model.flow_share', 'float', '', 1.0, 0.0, 100.0,
          doc='bound of |v_f|: this x (C_x + C_r) (|p_A - p_B| - F_s (1 + phi_max) / A_p) / A_p, '
              'the nominal leakage of the pressure difference that friction cannot hold'),
    Param(E + 'model.offset_load_mean', 'float', 's', 0.25, 0.001, 100.0,
          doc='time constant of the pressure difference\'s mean (adapt.load_variation: is the '
              'load varying? q_x_offset and the flow state ask; its variance about that mean '
              'over adapt.LOAD_VARIANCE_TIME, 2 s: a load step adds at most offset_load_mean/'
              '(2 x 2 s) of its square, a held load is not varying)'),
    Param(E + 'model.q_x_offset', 'float', 'm^2', 3e-10, 0.0, 1.0,
          doc='per-step position noise under a varying load (the pressure difference varying by '
              'more than F_s (1 + phi_max) / A_p rms about its mean: leakage and compressibility '
              'flows the adaptive states get wrong integrate into a position error at low '
              'frequency, which the sensor-offset state would otherwise take): the estimate '
              'follows the sensor at low frequency (issue 42: stiffness at C_eq x10)'),
    Param(E + 'model.hold_blend_time', 'float', 's', 0.2, 1e-3, 100.0,
          doc='stage hold_blend: while the piston rests (the pump-flow velocity averaged over '
              'rest_time below rest_velocity for rest_time) under a held load (the pressure '
              'difference beyond F_s (1 + phi_max) / A_p and not varying) the published '
              'position is the sensor\'s reading without its white noise, x_hat + b: nothing '
              'observes b then, so the loop holds what the sensor reads (issue 42, decision '
              '2); b is blended in and out over this time, out once the load lets go or that '
              'velocity stays beyond rest_velocity for rest_time'),
    Param(E + 'model.adapt_gate', 'float', '', 4.0, 0.0, 1e6,
          doc='no update of the adaptive states from a sample whose |position innovation| / '
              'sqrt(S) exceeds this (0: always): a fast transient the model cannot explain '
              '(an unknown load step) must not be taken for a parameter change'),
    Param(E + 'model.q_x_disagree', 'float', 'm^2', 1e-8, 0.0, 1.0,
          doc='per-step position process noise while filter and sensor disagree beyond the '
              'DISAGREE band (core.estimator.sensor_band): the estimate is pulled back to the '
              'measurement'),
    # consistency monitor (core.estimator.adapt.monitor), verdict: ok | model_mismatch |
    # sensor_fault | filter_sensor_disagree
    Param(E + 'monitor.lowpass', 'float', 'Hz', 5.0, 0.01, 500.0,
          doc='low-pass of the measurement-minus-estimate disagreement z - x_hat (its DISAGREE '
              'band follows from plant.sensors: core.estimator.sensor_band)'),
    Param(E + 'monitor.debounce', 'int', 'samples', 10, 1, 100000),
    Param(E + 'noise.adapt_range', 'float[]', '', [0.5, 3.0], 0.01, 100.0, min_len=2,
          doc='range of the measured noise level, relative to the sigmas of plant.sensors [lo, '
              'hi] (the random box reaches x2)'),
    Param(E + 'noise.adapt_quiet_velocity', 'float', 'm/s', 0.02, 0.0, 10.0,
          doc='the level is measured only while the pump-flow velocity D_p |omega| / A_p is '
              'below this (faster, the loop carries motion the filter does not follow: a 3 Hz '
              '3 mm sine chatters above ~35 mm/s)'),
    # PVA filter, eq. 4.30-4.34
    Param(E + 'pva.W', 'float', 'm^2/s^5', 100.0, 1e-12, 1e12,
          doc='jerk noise intensity W, eq. 4.32, appendix C.4 (R, eq. 4.33: the position '
              'sensor\'s variance, plant.sensors position_sigma^2 + position_gm_sigma^2; the '
              'thesis prints 2.5e-8 for the bench MSP)'),
    Param(E + 'pva.p0', 'float[]', 'm^2, (m/s)^2, (m/s^2)^2', [1e-6, 1e-2, 1e2], 0.0, 1e20,
          min_len=3, doc='initial variances, eq. 4.34 (which prints 100, 10, 100)'),
    # measurement validity
    Param(E + 'validity.pressure_min', 'float', 'Pa', 0.0, -1e6, 1e7,
          doc='pressure sensor range, gauge: lowest accepted reading (0 bar)'),
    Param(E + 'validity.pressure_max', 'float', 'Pa', 400.0 * BAR, 1e5, 1e9,
          doc='highest accepted pressure reading (400 bar)'),
    # position-sensor fault detector
    Param(E + 'fault.jump_debounce', 'int', 'samples', 3, 1, 10000),
    Param(E + 'fault.jump_pressure_veto', 'float', '', 8.0, 0.0, 1e300,
          doc='no jump when a pressure innovation of a debounce sample is above this '
              '(normalised): the piston moved by compressing the oil, the sensor did not jump'),
    Param(E + 'fault.stuck_samples', 'int', 'samples', 10, 2, 1000000,
          doc='identical consecutive readings of the noisy sensor that mean stuck (10 um '
              'noise, 1 um steps: 2.8 % per pair, 1e-14 for 10; was 25: 24 ms of a stuck '
              'reading pulled the estimate 0.2 mm before isolation)'),
    Param(E + 'fault.drift_h', 'float', '', 300.0, 1.0, 1e9,
          doc='CUSUM alarm level (a 60 s nominal 1 Hz sine peaks near 10; 150 -> 300, issue '
              '15: the adaptive model converging after a 10 kN step reached 167; a sensor '
              'drift is reported by monitor DISAGREE, 1 mm/s in 0.28 s)'),
    # node
    Param(E + 'node.stale_time', 'float', 's', 0.005, 1e-4, 10.0,
          doc='no state for longer than this: publish predict-only estimates marked stale'),
    Param(E + 'node.timer_period', 'float', 's', 0.001, 1e-4, 1.0,
          doc='stale check period'),
    Param(E + 'node.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0,
          doc='/diagnostics period'),
])

RANGES = ('noise.adapt_range',)
LOWPASS = ('model.friction_lowpass', 'monitor.lowpass')


def check_ranges(p: dict) -> None:
    """Each [lo, hi] range (noise.adapt_range) has two values with lo <= hi;
    validity.pressure_min <= validity.pressure_max."""
    for key in RANGES:
        v = p[E + key]
        if len(v) != 2 or v[0] > v[1]:
            raise ParamError(f'{E}{key} = {v!r}: expected [lo, hi] with lo <= hi', E + key)
    lo, hi = p[E + 'validity.pressure_min'], p[E + 'validity.pressure_max']
    if lo > hi:
        raise ParamError(f'{E}validity.pressure_min = {lo!r}: expected <= '
                         f'{E}validity.pressure_max ({hi!r})', E + 'validity.pressure_min')


def check_sensor_model(p: dict) -> None:
    """The sensor model the filter's R comes from (plant.sensors position_sigma, pressure_sigma;
    the PVA filter: position only) has noise: a zero sigma would make R singular."""
    keys = (('position_sigma', 1e-9),) + ((('pressure_sigma', 1.0),)
                                          if p[E + 'filter'] == 'model' else ())
    for key, least in keys:
        v = p['plant.sensors.' + key]
        if v < least:
            raise ParamError(f'plant.sensors.{key} = {v!r}: the estimator takes its R from it; '
                             f'expected >= {least:g} (a noise-free simulated sensor: '
                             f'plant.sensors.noise = false)', 'plant.sensors.' + key)


def check_stages(p: dict) -> None:
    """estimator.stages names stages of STAGES only ('' alone: none)."""
    bad = [v for v in p[E + 'stages'] if v not in STAGES and v != '']
    if bad:
        raise ParamError(f'{E}stages: unknown stage {bad[0]!r}: expected any of '
                         f'{", ".join(STAGES)} ([\'\'] for none)', E + 'stages')


def check_corners(p: dict) -> None:
    """Each low-pass corner of the estimator at most the Nyquist frequency 1/(2 plant.sim.Ts)
    of its sample period."""
    ts = p['plant.sim.Ts']
    for key in LOWPASS:
        f = p[E + key]
        if f > 0.5 / ts:
            raise ParamError(f'{E}{key} = {f!r}: expected <= the Nyquist frequency 1/(2 '
                             f'plant.sim.Ts) = {0.5 / ts:g} Hz (plant.sim.Ts = {ts!r})', E + key)


SCHEMA = PLANT_SCHEMA + Schema('estimator', ESTIMATOR.params, _chain(check_stages, check_ranges,
                                                                 check_corners, check_sensor_model))
