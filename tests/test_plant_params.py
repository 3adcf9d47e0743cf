"""config/plant.yaml against PLANT_SCHEMA: complete, loadable, validated."""
import os

import pytest
import yaml

from eha_ros.core.config.params import ParamError, flatten, load
from eha_ros.core.plant import PLANT_SCHEMA, EhaPlant, PlantParams

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
YAML = os.path.join(ROOT, 'config', 'plant.yaml')


def test_yaml_keys_are_schema_keys_with_a_comment_and_load():
    with open(YAML) as fh:
        text = fh.read()
    keys = set(flatten(yaml.safe_load(text)['/**']['ros__parameters']))
    # the file lists what differs from the schema defaults (tests/test_config_home.py)
    assert keys <= set(PLANT_SCHEMA.by_name)
    values = load(PLANT_SCHEMA, [YAML])
    assert values['plant.pump.D_p'] == pytest.approx(6.684e-7)
    for line in text.splitlines():
        if ':' in line and not line.strip().startswith('#') and not line.rstrip().endswith(':') \
                and not line.strip()[0].isdigit():
            assert '#' in line or line.strip().startswith('eta_v'), line
    EhaPlant(values)


def test_table_3_8_values_and_decided_choices():
    p = PlantParams.from_dict(load(PLANT_SCHEMA, [YAML]))
    assert p.C_eq == pytest.approx(3.8e-12)
    assert p.beta == 1.379e9 and p.b_eq == 4.26e-3 and p.k_E == 0.53
    assert p.lambda_m * 1.5 * p.n_p == pytest.approx(p.k_T)


@pytest.mark.parametrize('key,value', [('plant.pump.D_p', -1.0), ('plant.motor.model', 'ac'),
                                       ('plant.sim.substeps', 10), ('plant.pump.eta_v', [0.5] * 3),
                                       ('plant.friction.F_s', 100.0), ('plant.nope', 1.0)])
def test_bad_values_stop_with_one_clear_line(key, value):
    with pytest.raises(ParamError) as err:
        EhaPlant(load(PLANT_SCHEMA, [YAML], {key: value}))
    assert '\n' not in str(err.value) and key.split('.')[-1] in str(err.value)
