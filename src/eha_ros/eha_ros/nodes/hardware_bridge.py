"""hardware_bridge node: the drive and PLC (Beckhoff AX5118 + C6015, TwinCAT) over ADS in place
of plant_sim, with plant_sim's topics (minus truth and sim-only inputs).

The plant-side program (nodes.plant_side) with the ``ads`` backend (core.hardware.ads), or
``mock`` (bridge.backend: commands echoed into states, no PLC, for tests without physics).
A managed node: configured (link up, symbol table checked) and INACTIVE at start-up by
default; activate (lifecycle ~/change_state, or the alias eha/bridge/arm) arms it under the
arming conditions, deactivate disarms. eha/bridge/reset (Trigger) clears a latched link
fault. Refuses to start while another node publishes eha/state.
"""
from __future__ import annotations

import sys

from ..core.hardware.bridge_params import SCHEMA
from ..core.config.registry import LOOP_PREFIX
from .common import run
from .plant_side import Program, make_node as make_plant_side


def hardware(p: dict, counters):
    if p['bridge.backend'] == 'mock':
        from ..core.hardware.mock import MockHardware
        return MockHardware(p, counters, p['bridge.stale_limit'], seed=p['bridge.mock_seed'])
    from ..core.hardware.ads import AdsHardware
    return AdsHardware(p, counters, p['bridge.stale_limit'])


PROGRAM = Program('hardware_bridge', SCHEMA, LOOP_PREFIX['hardware_bridge'], hardware,
                  bridge_services=True, exclusive=True)


def make_node(params: dict, transport=None):
    return make_plant_side(params, PROGRAM, transport)


def main(argv=None) -> int:
    return run('hardware_bridge', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
