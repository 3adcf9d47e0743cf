"""Issue 44, named state: the compiled estimator's constants and state are records whose
fields carry the names of the parameters they come from (core.estimator.stepper.CONSTANTS),
so a parameter keeps one name from YAML to kernel."""
import numpy as np
import pytest

from eha_ros.core.estimator import stepper
from eha_ros.core.estimator.estimator import Estimator
from eha_ros.core.estimator.params import SCHEMA, adaptive_prior

ADAPTIVE = ('leakage', 'external_leakage', 'displacement', 'compliance', 'friction')
# constants that are not one parameter's value, and what they are computed from
DERIVED = {
    'x_max': 'plant stroke / 2 + estimator.POSITION_MARGIN',
    'use_pressure': 'measurements == position_pressure, for a model filter',
    'model_filter': 'filter', 'chambers': 'model.structure', 'n_lin': 'the filter',
    'alpha_pressure': 'adapt.PRESSURE_LOWPASS', 'alpha_friction': 'model.friction_lowpass',
    'A_p': 'plant', 'D_p': 'plant',
    'p_c': 'plant', 'C_x': 'plant', 'C_r': 'plant', 'p_acc': 'plant', 'c_Ts': 'plant, Ts',
    'i_leak': 'stages: leak_state', 'i_leakage': 'stages: adapt_leakage',
    'i_displacement': 'stages: adapt_displacement', 'i_compliance': 'stages: adapt_compliance',
    'i_friction': 'stages: adapt_friction', 'i_external_leakage': 'stages: '
    'adapt_external_leakage', 'i_frozen': 'the first adaptive state',
    'i_gm': 'stages: sensor_offset', 'i_load': 'stages: load_state', 'i_flow': 'stages: '
    'flow_state', 'i_moved': 'stages: sensor_offset', 'moved_gate': 'model.load_jump_z',
    'stribeck': 'stages: stribeck_friction', 'isolate': 'stages: isolate',
    'position_gm_sigma': 'plant.sensors.position_gm_sigma',
    'friction': 'model.friction_* and the plant (adapt.friction_input)', 'q_x': 'model.q[0]',
    'flow_ticks': 'model.flow_time / Ts', 'dp_friction': 'plant friction, friction_range',
    'alpha_load': 'model.offset_load_mean, adapt.LOAD_VARIANCE_TIME',
    'load_hold': 'adapt.LOAD_SWING_HOLD / Ts',
    'swing_band': 'adapt.LOAD_SWING_BAND x the pressure difference friction holds',
    'flow_report': 'adapt.FLOW_REPORT',
    'hold_rate': 'Ts / model.hold_blend_time (stages: hold_blend)',
    'noise_adapt': 'stages: noise_level',
    'noise': 'noise.*, plant.sensors.* (noise_level.constants)', 'monitor': 'monitor.*',
    'detector': 'fault.* (fault_detector)',
    'max_abs_motor_speed': 'plant.drive.omega_max x estimator.MOTOR_SPEED_MARGIN',
    'offset_bound': 'plant.sensors.* (sensor_band)', 'F_s': 'plant.friction.F_s',
    **{f'{name}_range': 'TUNED (adaptive_prior: derived from the family by tune_estimator)'
       for name in ADAPTIVE},
}


def leaf_params():
    """{leaf name: full key} of the numeric estimator.* parameters, where the leaf is unique."""
    leaves = {}
    for p in SCHEMA.params:
        if p.name.startswith('estimator.') and p.type in ('float', 'int', 'bool', 'float[]'):
            leaves.setdefault(p.name.rsplit('.', 1)[1], []).append(p.name)
    return {k: v[0] for k, v in leaves.items() if len(v) == 1}


def test_every_constant_is_a_parameter_or_declared_derived(params):
    est = Estimator(params)
    K = est.kernel[0]
    leaves = leaf_params()
    named = [f for f in K.dtype.names if f not in DERIVED]
    assert len(named) >= 10, named            # many constants are a parameter's own value
    for f in named:
        assert f in leaves, f'{f}: neither a parameter name nor in DERIVED'
        value, want = np.atleast_1d(K[f][0]), np.atleast_1d(params[leaves[f]])
        if f.endswith('_range') and K['i_' + f[:-len('_range')]][0] < 0:
            continue                          # that adaptive state is off: the range unused
        np.testing.assert_array_equal(value, np.asarray(want[:len(value)], float), err_msg=f)
    assert not set(DERIVED) - set(K.dtype.names), 'DERIVED names a constant that is gone'
    for name in ADAPTIVE:                     # the adaptive states' ranges: the TUNED table's
        if K[f'i_{name}'][0] >= 0:
            np.testing.assert_array_equal(K[f'{name}_range'][0], adaptive_prior(name)[1:])


def test_one_name_from_yaml_to_kernel(params):
    """The issue's example: estimator.model.flow_gate is flow_gate on the Estimator, in the
    constants record and in adapt.flow_noise's signature."""
    import inspect
    from eha_ros.core.estimator import adapt
    p = dict(params, **{'estimator.model.flow_gate': 3.25})
    est = Estimator(p)
    assert est.flow_gate == 3.25 and est.kernel[0]['flow_gate'][0] == 3.25
    assert 'flow_gate' in inspect.signature(adapt.flow_noise).parameters


@pytest.mark.parametrize('dtype', [stepper.CONSTANTS, stepper.STATE])
def test_records_are_plain_float64(dtype):
    """The closed loop copies and rolls back the state record whole: float64 fields only,
    no padding."""
    assert dtype.itemsize % 8 == 0 and all(
        dtype.fields[f][0].base == np.float64 for f in dtype.names)
    assert dtype.itemsize == 8 * sum(int(np.prod(dtype.fields[f][0].shape) or 1)
                                     for f in dtype.names)
