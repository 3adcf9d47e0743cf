"""plant_sim node: the nonlinear EHA model (core.plant.EhaPlant) on the ROS graph at 1 kHz.

The plant-side program (nodes.plant_side) with the ``sim`` backend (core.hardware.sim):
publishes eha/state and eha/sim/truth each tick, applies eha/command through the command gate,
takes eha/sim/load_force and eha/channel_select, serves eha/inject_fault, reports on
/diagnostics; a managed node (lifecycle), ACTIVE at start-up by default (sim_node.autostart).
"""
from __future__ import annotations

import sys

from ..core.config.registry import LOOP_PREFIX
from ..core.hardware.sim import SimHardware
from ..core.hardware.sim_params import SCHEMA
from .common import run
from .plant_side import Program, make_node as make_plant_side


def hardware(p: dict, counters):
    return SimHardware(p, counters, seed=p['sim_node.seed'],
                       initial_position=p['sim_node.initial_position'],
                       max_load=p['sim_node.max_abs_load'])


PROGRAM = Program('plant_sim', SCHEMA, LOOP_PREFIX['plant_sim'], hardware)


def make_node(params: dict, transport=None):
    return make_plant_side(params, PROGRAM, transport)


def main(argv=None) -> int:
    return run('plant_sim', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
