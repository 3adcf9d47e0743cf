"""One home per value (issue 44, point 5): config/*.yaml restates no schema default, the tuned
estimator numbers live in one table written by tune_estimator, and every range pair and
dependent pair of a schema is a cross-key check refusing with one line naming both keys."""
import glob
import os

import pytest
import yaml

from eha_ros.core.config.params import ParamError, flatten, load
from eha_ros.core.config.registry import schema_for
from eha_ros.core.plant.parameters import PLANT_SCHEMA
from eha_ros.core.qft.spec import QFT_SPEC_SCHEMA

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, 'config')

# (file, key): a value kept visible although it equals the default, because it is what a user
# of a bench is expected to edit (the PLC's address) or to pick (which run).
ALLOWLIST = {
    ('hardware_bridge.yaml', 'ads.ams_net_id'),     # the bench PLC's AMS net id
    ('hardware_bridge.yaml', 'ads.host'),           # the bench PLC's IP address
    ('live.yaml', 'live.host'),                     # bind address: 0.0.0.0 to watch remotely
    ('sweep.yaml', 'sweep.mode'),                   # which test the sweep node runs
    ('experiment.yaml', 'experiment.kind'),         # which identification experiment runs
}


def _schema(section: str):
    """The schema a params-file section is checked against."""
    name = section.strip('/')
    if name == '**':
        return PLANT_SCHEMA
    if name == 'design_qft':
        return QFT_SPEC_SCHEMA
    return schema_for(name)


def _norm(v):
    return [_norm(x) for x in v] if isinstance(v, (list, tuple)) else v


def _params_files():
    out = []
    for path in sorted(glob.glob(os.path.join(CONFIG, '*.yaml'))):
        with open(path, encoding='utf-8') as fh:
            doc = yaml.safe_load(fh)
        if doc and 'symbols' not in doc:            # ads_symbols.yaml is no params file
            out.append((os.path.basename(path), doc))
    return out


@pytest.mark.parametrize('name, doc', _params_files(), ids=lambda x: x if isinstance(x, str)
                         else '')
def test_no_yaml_leaf_restates_its_schema_default(name, doc):
    """A key in config/*.yaml differs from its schema default (or is allowlisted above)."""
    restated = []
    for section, body in doc.items():
        schema = _schema(str(section))
        for key, value in flatten(body['ros__parameters'] or {}).items():
            spec = schema.by_name[key]
            if spec.required or (name, key) in ALLOWLIST:
                continue
            if _norm(spec.check(value)) == _norm(spec.default):
                restated.append(f'{key} = {value!r}')
    assert not restated, f'config/{name} restates the default of: {", ".join(restated)}'


def test_allowlist_names_existing_keys():
    keys = {(n, k) for n, doc in _params_files() for body in doc.values()
            for k in flatten(body['ros__parameters'] or {})}
    assert ALLOWLIST <= keys


def test_tuned_table_is_what_tune_estimator_writes(tmp_path):
    """core/estimator/params.py's TUNED table is the one home of the tuned numbers:
    tune_estimator --write leaves the file as it is (and no YAML file restates them)."""
    from eha_ros.core.estimator import params as P
    from eha_ros.tools import tune_estimator as T
    with open(P.__file__, encoding='utf-8') as fh:
        text = fh.read()
    out = tmp_path / 'params.py'
    out.write_text(text)
    assert T.main(['--out', str(out), '--write']) == 0
    assert out.read_text() == text
    loaded = load(schema_for('estimator'), [os.path.join(CONFIG, 'plant.yaml'),
                                            os.path.join(CONFIG, 'estimator.yaml')])
    assert not any('estimator.' + key in loaded for key in P.TUNED)     # no parameters
    for name in ('leakage', 'external_leakage', 'displacement', 'compliance', 'friction'):
        p0, lo, hi = P.adaptive_prior(name)
        assert p0 > 0 and lo < 0 < hi, name


E, H = 'estimator:estimator.', 'switch_manager:switch.health.'
# a 2 ms tick (Nyquist 250 Hz) that the plant's own checks accept
TS2 = {'/**:plant.sim.Ts': 0.002, '/**:plant.sim.substeps': 32, '/**:plant.drive.delay': 0.002}
# check -> (node, overrides that violate it, words of the one-line error: both keys, values)
CASES = {
    'estimator noise.adapt_range lo > hi': ('estimator', {f'{E}noise.adapt_range': [0.5, 0.1]},
                                            ['estimator.noise.adapt_range = [0.5, 0.1]',
                                             'lo <= hi']),
    'estimator range of 3 values': ('estimator', {f'{E}noise.adapt_range': [0.5, 1.0, 2.0]},
                                    ['estimator.noise.adapt_range = [0.5, 1.0, 2.0]']),
    'estimator pressure_min > pressure_max': (
        'estimator', {f'{E}validity.pressure_min': 2.0e6, f'{E}validity.pressure_max': 1.0e6},
        ['estimator.validity.pressure_min = 2000000.0', 'estimator.validity.pressure_max '
         '(1000000.0)']),
    **{f'estimator {k} above Nyquist': ('estimator', {f'{E}{k}': 400.0, **TS2},
                                        [f'estimator.{k} = 400.0', 'plant.sim.Ts = 0.002'])
       for k in ('model.friction_lowpass', 'monitor.lowpass')},
    'estimator unknown stage': ('estimator', {f'{E}stages': ['load_state', 'kalman_magic']},
                                ["estimator.stages: unknown stage 'kalman_magic'",
                                 'sensor_offset']),
    'estimator noise-free sensor model': (
        'estimator', {'/**:plant.sensors.position_sigma': 0.0},
        ['plant.sensors.position_sigma = 0.0', 'plant.sensors.noise = false']),
    'switch_manager drive clear > trip': (
        'switch_manager', {f'{H}drive.trip': 0.3, f'{H}drive.clear': 0.6},
        ['switch.health.drive.clear = 0.6', 'switch.health.drive.trip (0.3)']),
    **{f'switch_manager {m}.lowpass above Nyquist': (
        'switch_manager', {f'{H}{m}.lowpass': 400.0, **TS2},
        [f'switch.health.{m}.lowpass = 400.0', 'plant.sim.Ts = 0.002'])
       for m in ('speed', 'pressure', 'estimator')},
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_cross_key_check_refuses_with_one_line(case):
    node, overrides, words = CASES[case]
    over = {}
    for key, value in overrides.items():      # '/**:key' = a wildcard (plain -p) assignment
        over[key.partition(':')[2] if key.startswith('/**:') else key] = value
    files = [os.path.join(CONFIG, f) for f in ('plant.yaml', f'{node}.yaml')]
    with pytest.raises(ParamError) as err:
        load(schema_for(node), files, over, node=node)
    text = str(err.value)
    assert '\n' not in text and text.startswith('command line: '), text
    for w in words:
        assert w in text, text


def test_shipped_files_pass_every_check():
    for node in ('estimator', 'switch_manager'):
        load(schema_for(node), [os.path.join(CONFIG, f) for f in ('plant.yaml', f'{node}.yaml')],
             node=node)


QFT_CASES = {
    'family range': ({'family.beta_range': [1.4, 0.7]},
                     ['family.beta_range = [1.4, 0.7]', 'min <= max']),
    'K_min >= K_max': ({'velocity.K_min': [0.01, 3000.0, 100.0]},
                       ['velocity.K_min/velocity.K_max = [0.01, 3000.0, 100.0]/']),
    'zp_min >= zp_max': ({'position.zp_min': 1500.0},
                         ['position.zp_min = 1500.0', 'position.zp_max (1500.0)']),
    'zp_max above pi/(2 Ts)': ({'digital.Ts': 0.002},
                               ['position.zp_max = 1500.0', 'pi/(2 digital.Ts)']),
    'zeta_min >= zeta_max': ({'position.zeta_min': 1.0},
                             ['position.zeta_min = 1.0', 'position.zeta_max (1.0)']),
    'corner_min >= corner_max': ({'prefilter.corner_min': 3000.0},
                                 ['prefilter.corner_min = 3000.0',
                                  'prefilter.corner_max (2000.0)']),
    'w_min >= w_max': ({'verify.w_min': 5000.0},
                       ['verify.w_min = 5000.0', 'verify.w_max (3000.0)']),
}


@pytest.mark.parametrize('case', sorted(QFT_CASES))
def test_qft_spec_cross_key_check_refuses_with_one_line(case):
    """The QFT spec's range pairs are checks of its schema (load_spec, check_config alike)."""
    overrides, words = QFT_CASES[case]
    with pytest.raises(ParamError) as err:
        load(QFT_SPEC_SCHEMA, [os.path.join(CONFIG, 'qft_spec.yaml')], overrides)
    text = str(err.value)
    assert '\n' not in text, text
    for w in words:
        assert w in text, text
