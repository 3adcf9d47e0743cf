"""Parameters of the plant_sim node: the plant model's plant.* set plus the node's sim_node.*."""
from __future__ import annotations

from ..config.registry import LOOP_PREFIX
from ..hardware.params import loop_params
from ..config.params import Param, Schema
from .parameters import PLANT_SCHEMA

NODE = Schema('plant_sim', [
    Param('sim_node.seed', 'int', '', 0, 0, 2**31 - 1, doc='noise generator seed'),
    *loop_params(LOOP_PREFIX['plant_sim'], command_timeout=0.05, autostart='active',
                 max_speed_rate=1.0e9, arm_max_command=1.0e5),
    Param('sim_node.initial_position', 'float', 'm', 0.0, -0.06, 0.06),
    Param('sim_node.max_abs_load', 'float', 'N', 2.0e5, 0.0, 1.0e7,
          doc='load forces beyond this magnitude are saturated and counted'),
])

SCHEMA = PLANT_SCHEMA + NODE
