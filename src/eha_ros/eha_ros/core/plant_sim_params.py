"""Parameters of the plant_sim node: the plant model's plant.* set plus the node's sim_node.*."""
from __future__ import annotations

from .params import Param, Schema
from .plant.parameters import PLANT_SCHEMA



def lockstep_params(prefix: str) -> list:
    """The lock-step switches of a plant-side node (plant_sim: sim_node, hardware_bridge:
    bridge): it publishes /clock and steps per command; nodes.common.StartGate holds tick 0."""
    return [
        Param(f'{prefix}.lockstep', 'bool', '', False,
              doc='step only when the command of the previous state arrived; publish /clock'),
        Param(f'{prefix}.lockstep_timeout', 'float', 's', 1.0, 1e-3, 60.0,
              doc='lock-step: re-publish state(k) after this wall time without command(k)'),
        Param(f'{prefix}.start_after', 'str[]', '', [''], min_len=1,
              doc='hold tick 0 (real time: the loop\'s start) until these nodes subscribe to '
                  'every /eha topic with a publisher (run_stack --record adds the recorder); '
                  'empty string = none'),
        Param(f'{prefix}.start_timeout', 'float', 's', 30.0, 0.0, 600.0,
              doc='start anyway (with a warning) after this wall time at tick 0'),
    ]


NODE = Schema('plant_sim', [
    Param('sim_node.seed', 'int', '', 0, 0, 2**31 - 1, doc='noise generator seed'),
    *lockstep_params('sim_node'),
    Param('sim_node.initial_position', 'float', 'm', 0.0, -0.06, 0.06),
    Param('sim_node.command_timeout', 'float', 's', 0.05, 1e-3, 10.0,
          doc='no command for this long: speed reference goes to zero and is reported'),
    Param('sim_node.max_abs_speed_ref', 'float', 'rad/s', 838.0, 1.0, 5000.0,
          doc='commands beyond this magnitude are saturated and counted'),
    Param('sim_node.max_abs_load', 'float', 'N', 2.0e5, 0.0, 1.0e7,
          doc='load forces beyond this magnitude are saturated and counted'),
    Param('sim_node.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0),
])

SCHEMA = PLANT_SCHEMA + NODE
