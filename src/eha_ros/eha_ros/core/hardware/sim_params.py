"""Parameters of the plant_sim node: the plant model's plant.* set plus the node's sim_node.*."""
from __future__ import annotations

from ..config.registry import LOOP_PREFIX
from .params import loop_params
from ..config.params import Param, Schema
from ..plant.parameters import PLANT_SCHEMA

NODE = Schema('plant_sim', [
    Param('sim_node.seed', 'int', '', 0, 0, 2**31 - 1, doc='noise generator seed'),
    *loop_params(LOOP_PREFIX['plant_sim'], command_timeout=0.05, autostart='active',
                 max_speed_rate=1.0e9, arm_max_command=1.0e5),
    Param('sim_node.initial_position', 'float', 'm', 0.0, -0.06, 0.06,
          doc='piston position at start (0 = mid-stroke)'),
    Param('sim_node.max_abs_load', 'float', 'N', 2.0e5, 0.0, 1.0e7,
          doc='load forces beyond this magnitude are saturated and counted'),
])

SCHEMA = PLANT_SCHEMA + NODE


def plant_file(path: str, config_dir: str | None = None) -> dict:
    """The plant parameters a params file sets for plant_sim, {key: value}: an identified
    plant (scripts/identify's identified.yaml) for run_stack, campaign and design_qft
    (--plant-params). Only plant.* keys (the model, not the node's settings); checked with
    config/'s plant_sim files under them, so an unknown key or a value out of range is a
    ParamError (one line)."""
    import os

    from ..config.params import ParamError, default_config_dir, load, read_params_file
    from ..config.registry import NODE_FILES
    values = read_params_file(path, 'plant_sim')
    if not values:
        raise ParamError(f'{path}: sets no parameter of plant_sim: expected a params file with '
                         f'plant.* keys (in a plant_sim: or /** section)')
    other = sorted(k for k in values if not k.startswith('plant.'))
    if other:
        raise ParamError(f'{path}: {other[0]} is not a plant parameter: expected plant.* keys '
                         f'only (the plant\'s model, not plant_sim\'s node settings)')
    files = [os.path.join(config_dir or default_config_dir(), f) for f in NODE_FILES['plant_sim']]
    checked = load(SCHEMA, files + [path], node='plant_sim')
    return {k: checked[k] for k in values}
