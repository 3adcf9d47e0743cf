"""Parameters of the estimator (node and batch): estimator.* below plus the plant.* set of
config/plant.yaml (the model of eq. 4.35 is built from the same plant parameters)."""
from __future__ import annotations

from ..config.params import Param, Schema
from ..plant.parameters import PLANT_SCHEMA

BAR = 1.0e5
E = 'estimator.'



def _adaptive(name, symbol, adapt_doc, q, q_max, p0, p0_max, rng, lo, hi) -> list:
    """The four parameters of one adaptive model state (core.estimator.adapt): its switch
    adapt_<name>, random walk q_<name>, initial variance p0_<name> and projection range."""
    m = E + 'model.'
    return [Param(m + f'adapt_{name}', 'bool', '', True, doc=adapt_doc),
            Param(m + f'q_{name}', 'float', '', q, 0.0, q_max,
                  doc=f'per-step random-walk variance of {symbol}'),
            Param(m + f'p0_{name}', 'float', '', p0, 0.0, p0_max,
                  doc=f'initial variance of {symbol}'),
            Param(m + f'{name}_range', 'float[]', '', rng, lo, hi, min_len=2,
                  doc=f'projection range of {symbol} [lo, hi]')]


ESTIMATOR = Schema('estimator', [
    Param(E + 'filter', 'str', '', 'model', choices=('model', 'pva'),
          doc='model = eq. 4.35 model-based KF; pva = position-velocity-acceleration KF '
              '(eqs. 4.30-4.34)'),
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
              'eq3_22 = 2 C_eq beta/V_d, eq4_35 = C_eq beta/V_d'),
    Param(E + 'model.friction', 'str', '', 'stribeck', choices=('stribeck', 'eq4_36'),
          doc='chambers: piston friction of the model: stribeck = the plant curve of eq. 3.33 '
              '(plant.friction F_c, F_s, v_s; Table 3.7) at the pump-flow velocity, low-passed '
              'at friction_lowpass (adapt.friction_input); eq4_36 = -sign(xdot) min(|p_D A_p|, '
              'F_s) with F_s, v_eps below (eq4_35 structure: always)'),
    Param(E + 'model.rest_velocity', 'float', 'm/s', 3e-3, 0.0, 1.0,
          doc='stribeck: the piston is at rest while the pump-flow velocity stays below this '
              'for rest_time (stiction: the friction is whatever holds it)'),
    Param(E + 'model.rest_time', 'float', 's', 0.1, 0.0, 100.0),
    Param(E + 'model.q_load_rest', 'float', 'N^2', 1000.0, 0.0, 1e12,
          doc='stribeck: per-step variance added to the force state\'s random walk while the '
              'piston is at rest (stiction: the holding force is whatever holds it; the friction '
              'input is held)'),
    Param(E + 'model.F_s', 'float', 'N', 800.0, 0.0, 1.0e5,
          doc='friction bound of eq. 4.36'),
    Param(E + 'model.v_eps', 'float', 'm/s', 1.0e-2, 1.0e-6, 0.1,
          doc='pump-flow velocity over which eq. 4.36 friction reaches full sign'),
    Param(E + 'model.friction_pressure', 'bool', '', False,
          doc='use the measured p_D in min(|p_D A_p|, F_s) of eq. 4.36 (adds pressure noise)'),
    Param(E + 'model.friction_lowpass', 'float', 'Hz', 50.0, 0.0, 500.0,
          doc='low-pass of the motor speed that gives eq. 4.36 its sign of xdot (0 = none): '
              'command chatter above it must not flip the modelled friction'),
    Param(E + 'model.pressure_lowpass', 'float', 'Hz', 30.0, 0.1, 500.0,
          doc='low-pass of the measured p_D used as a model input (friction, leakage column)'),
    Param(E + 'model.sensor_gm', 'bool', '', True,
          doc='add the position sensor Gauss-Markov offset as a state (coloured noise)'),
    Param(E + 'model.leak_state', 'bool', '', True,
          doc='eq4_35 structure only: add a leakage-coefficient correction state '
              '(1e-12 m^3/(s Pa) units)'),
    Param(E + 'model.q', 'float[]', 'm^2, (m/s)^2, Pa^2', [1e-16, 1e-10, 1e6], 0.0, 1e20,
          min_len=3, doc='per-step process noise variances of x, xdot, p_D (p_D: eq4_35 only)'),
    Param(E + 'model.q_chamber', 'float', 'Pa^2', 1.0e4, 0.0, 1e20,
          doc='per-step process noise variance of each chamber pressure (chambers structure)'),
    Param(E + 'model.p0', 'float[]', 'm^2, (m/s)^2, Pa^2', [1e-8, 1e-4, 1e10], 0.0, 1e20,
          min_len=3, doc='initial variances of x, xdot, p_D'),
    Param(E + 'model.q_leak', 'float', '(1e-12 m^3/(s Pa))^2', 1e-8, 0.0, 1e6,
          doc='per-step random-walk variance of the leakage correction'),
    Param(E + 'model.p0_leak', 'float', '(1e-12 m^3/(s Pa))^2', 4.0, 0.0, 1e6),
    Param(E + 'model.load_state', 'bool', '', True,
          doc='add an external-force state (random walk) so a static load does not bias x'),
    Param(E + 'model.q_load', 'float', 'N^2', 1e-4, 0.0, 1e12,
          doc='per-step random-walk variance of the external force (stribeck friction: the '
              'load; eq4_36: the load and every friction error)'),
    Param(E + 'model.q_load_jump', 'float', 'N^2', 1e8, 0.0, 1e14,
          doc='per-step variance of the external force after a sample whose pressure '
              'innovation exceeds load_jump_z (a load step; adjustable-level process noise)'),
    Param(E + 'model.load_jump_z', 'float', '', 5.0, 0.0, 1e300,
          doc='normalised pressure innovation above which the force state takes q_load_jump'),
    Param(E + 'model.p0_load', 'float', 'N^2', 1e8, 0.0, 1e14,
          doc='initial variance of the external force'),
    # adaptive model states and projection (chambers structure; core.estimator.adapt).
    # Defaults = config/estimator.yaml = scripts/tune_estimator's values (Table 4.5 + box,
    # sensor model).
    *_adaptive('leakage', 'lambda', 'chambers: relative leakage correction lambda as a state '
               '(C_p + C_c x (1+lambda); every leakage without adapt_external_leakage)',
               6.2362e-09, 1e6, 6.236, 1e6, [-0.99, 30.41], -1.0, 1e3),
    Param(E + 'model.leakage_excitation', 'float', 'Pa', 0.0, 0.0, 1e8,
          doc='lambda is updated only while |p_A - p_B| exceeds this (dead zone)'),
    *_adaptive('external_leakage', 'epsilon', 'chambers: relative correction epsilon of the '
               'per-port leakage C_r as a state (C_r x (1+epsilon)); lambda then scales the '
               'cross-port C_p + C_c only', 6.2362e-09, 1e6, 6.236, 1e6, [-0.99, 36.5], -1.0, 1e3),
    *_adaptive('displacement', 'delta', 'chambers: relative displacement correction delta as a '
               'state (D_p x (1+delta))', 0, 1.0, 0.003331, 1.0, [-0.325, 0.125], -0.9, 1.0),
    *_adaptive('compliance', 'kappa', 'chambers: relative compliance correction kappa as a state '
               '(V_d/beta x (1+kappa))', 4.2185e-11, 1.0, 0.04218, 10.0, [-0.5833, 0.9167],
               -0.9, 10.0),
    *_adaptive('friction', 'phi', 'chambers with stribeck friction: relative friction correction '
               'phi as a state (F_c, F_s x (1+phi))', 0.0, 1.0, 0.1818, 10.0, [-0.875, 1.375],
               -0.99, 10.0),
    Param(E + 'model.flow_state', 'bool', '', True,
          doc='chambers with stribeck friction: an unmodelled flow v_f (velocity units, A_p v_f '
              'into A, out of B) as a state, opened at rest while the sensor offset is '
              'implausible, bounded by the leakage of the pressure difference beyond friction '
              '(adapt.flow_noise)'),
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
    Param(E + 'model.flow_report', 'float', 'm/s', 2e-5, 0.0, 1.0,
          doc='|v_f| above this is reported as model_mismatch (a sensor drift under load looks '
              'like a leak): the load-step spec\'s steady error (20 um) per second'),
    Param(E + 'model.offset_gate', 'float', '', 2.0, 0.0, 1e6,
          doc='chambers: while the sensor-offset estimate b has a mean square (over offset_time) '
              'above this^2 x its stationary sigma^2 (at the measured noise level) under a '
              'varying load, b is the model\'s error: reported as model_mismatch '
              '(adapt.offset_noise; 0: off)'),
    Param(E + 'model.offset_time', 'float', 's', 0.5, 0.001, 100.0,
          doc='time constant of b\'s mean square'),
    Param(E + 'model.offset_load_mean', 'float', 's', 0.25, 0.001, 100.0,
          doc='time constant of the pressure difference\'s mean ...'),
    Param(E + 'model.offset_load_time', 'float', 's', 2.0, 0.001, 100.0,
          doc='... and of its variance about that mean (a load step adds at most '
              'offset_load_mean/(2 offset_load_time) of its square: a held load is not varying)'),
    Param(E + 'model.q_x_offset', 'float', 'm^2', 3e-10, 0.0, 1.0,
          doc='per-step position noise under a varying load (the pressure difference varying by '
              'more than F_s (1 + phi_max) / A_p rms about its mean: leakage and compressibility '
              'flows the adaptive states get wrong integrate into a position error at low '
              'frequency, which the sensor-offset state would otherwise take): the estimate '
              'follows the sensor at low frequency (issue 42: stiffness at C_eq x10)'),
    Param(E + 'model.hold_blend_time', 'float', 's', 0.2, 0.0, 100.0,
          doc='while the piston rests (rest_velocity, rest_time) under a held load (the '
              'pressure difference beyond F_s (1 + phi_max) / A_p and not varying) the published '
              'position is the sensor\'s reading without its white noise, x_hat + b: nothing '
              'observes b then, so the loop holds what the sensor reads (issue 42, decision 2); '
              'b is blended in and out over this time (0: off, x_hat always)'),
    Param(E + 'model.adapt_gate', 'float', '', 4.0, 0.0, 1e6,
          doc='no update of the adaptive states from a sample whose |position innovation| / '
              'sqrt(S) exceeds this (0: always): a fast transient the model cannot explain '
              '(an unknown load step) must not be taken for a parameter change'),
    Param(E + 'model.compliance_lowpass', 'float', 'Hz', 0.0, 0.0, 1e4,
          doc='low-pass of the pressure increments that carry the compliance flow (0: none)'),
    Param(E + 'model.q_x_disagree', 'float', 'm^2', 1e-8, 0.0, 1.0,
          doc='per-step position process noise while filter and sensor disagree beyond the '
              'band (monitor.band): the estimate is pulled back to the measurement'),
    Param(E + 'model.offset_bound', 'float', 'm', 2.5320e-04, 0.0, 0.01,
          doc='projection bound of the sensor Gauss-Markov offset state |b| (0: none): the '
              'estimate stays within it of the measurement'),
    # consistency monitor (core.estimator.adapt.monitor)
    Param(E + 'monitor.lowpass', 'float', 'Hz', 5, 0.01, 500.0,
          doc='low-pass of the measurement-minus-estimate disagreement'),
    Param(E + 'monitor.band', 'float', 'm', 2.1362e-04, 1e-7, 0.1,
          doc='sensor error band: a larger low-passed disagreement is DISAGREE'),
    Param(E + 'monitor.debounce', 'int', 'samples', 10, 1, 100000),
    Param(E + 'monitor.hold_time', 'float', 's', 0.5, 0.0, 100.0,
          doc='a verdict stays reported this long after its condition clears'),
    # sensor noise model (the filter's R)
    Param(E + 'noise.position_sigma', 'float', 'm', 1.0e-5, 1e-9, 1e-2,
          doc='white position noise sigma (R of the position)'),
    Param(E + 'noise.position_gm_sigma', 'float', 'm', 2.0e-5, 0.0, 1e-2,
          doc='low-frequency (Gauss-Markov) position noise sigma, Fig. 4.6'),
    Param(E + 'noise.position_gm_corner', 'float', 'Hz', 1.0, 1e-3, 100.0),
    Param(E + 'noise.pressure_sigma', 'float', 'Pa', 0.316 * BAR, 1.0, 1e7,
          doc='one pressure sensor sigma; p_D gets twice its variance'),
    Param(E + 'noise.adapt', 'bool', '', True,
          doc='chambers: measure the position and pressure sensors\' noise level online and '
              'scale R (and the Gauss-Markov state\'s q) by it (core.estimator.noise_level)'),
    Param(E + 'noise.adapt_time', 'float', 's', 5.0, 0.01, 1e6,
          doc='memory of the noise-level measurement'),
    Param(E + 'noise.adapt_range', 'float[]', '', [0.5, 3.0], 0.01, 100.0, min_len=2,
          doc='range of the measured noise level, relative to the sigmas above [lo, hi]'),
    Param(E + 'noise.adapt_quiet_velocity', 'float', 'm/s', 0.02, 0.0, 10.0,
          doc='the level is measured only while the pump-flow velocity D_p |omega| / A_p is '
              'below this (faster, the loop carries motion the filter does not follow)'),
    # PVA filter, eq. 4.30-4.34
    Param(E + 'pva.W', 'float', 'm^2/s^5', 100.0, 1e-12, 1e12,
          doc='jerk noise intensity W, eq. 4.32'),
    Param(E + 'pva.R', 'float', 'm^2', 5.0e-10, 1e-16, 1.0,
          doc='position noise variance, eq. 4.33'),
    Param(E + 'pva.p0', 'float[]', 'm^2, (m/s)^2, (m/s^2)^2', [1e-6, 1e-2, 1e2], 0.0, 1e20,
          min_len=3, doc='initial variances, eq. 4.34'),
    # measurement validity
    Param(E + 'validity.position_margin', 'float', 'm', 5.0e-3, 0.0, 0.1,
          doc='accepted position: within +-(stroke/2 + margin)'),
    Param(E + 'validity.pressure_min', 'float', 'Pa', 0.0, -1e6, 1e7),
    Param(E + 'validity.pressure_max', 'float', 'Pa', 400.0 * BAR, 1e5, 1e9),
    Param(E + 'validity.max_abs_motor_speed', 'float', 'rad/s', 1257.0, 1.0, 1e5,
          doc='motor speeds beyond this are rejected (last good speed held)'),
    # position-sensor fault detector
    Param(E + 'fault.jump_threshold', 'float', '', 8.0, 1.0, 1e6,
          doc='|innovation| / sqrt(S) above this counts towards a jump'),
    Param(E + 'fault.jump_debounce', 'int', 'samples', 3, 1, 10000),
    Param(E + 'fault.jump_step', 'float', 'm', 1.4142e-04, 0.0, 0.1,
          doc='a jump must begin with an innovation step of at least this within one sample '
              '(0: any); a smooth large innovation is a model mismatch, not a sensor jump'),
    Param(E + 'fault.jump_pressure_veto', 'float', '', 8.0, 0.0, 1e300,
          doc='no jump when a pressure innovation of a debounce sample is above this '
              '(normalised): the piston moved by compressing the oil, the sensor did not jump'),
    Param(E + 'fault.stuck_samples', 'int', 'samples', 10, 2, 1000000,
          doc='identical consecutive readings of the noisy sensor that mean stuck'),
    Param(E + 'fault.stuck_tolerance', 'float', 'm', 0.0, 0.0, 1e-3,
          doc='readings closer than this count as identical'),
    Param(E + 'fault.drift_k', 'float', '', 0.5, 0.0, 100.0,
          doc='CUSUM allowance on the normalised innovation'),
    Param(E + 'fault.drift_h', 'float', '', 300.0, 1.0, 1e9, doc='CUSUM alarm level'),
    Param(E + 'fault.drift_debounce', 'int', 'samples', 5, 1, 10000),
    Param(E + 'fault.hold_time', 'float', 's', 0.5, 0.0, 100.0,
          doc='a detected fault stays reported this long after its condition clears'),
    Param(E + 'fault.isolate', 'bool', '', True,
          doc='skip the position update while a sensor fault (jump or stuck) is reported'),
    # Chinniah friction estimator (sec. 4.1.2) on the running estimate
    Param(E + 'chinniah.enabled', 'bool', '', False,
          doc='run the 3-state/4-state friction estimators (eqs. 4.15-4.29) on the estimate'),
    # node
    Param(E + 'node.stale_time', 'float', 's', 0.005, 1e-4, 10.0,
          doc='no state for longer than this: publish predict-only estimates marked stale'),
    Param(E + 'node.timer_period', 'float', 's', 0.001, 1e-4, 1.0),
    Param(E + 'node.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0),
])

SCHEMA = PLANT_SCHEMA + ESTIMATOR
