"""The nodes of the stack, written once: executable, params files, schema, place in the loop.

setup.py (console scripts), eha_ros.stack and scripts/run_stack (the commands they start),
eha_loop (what it may host), the launch file (through run_stack), check_config and the
parameter reference (the schemas) and the batch code (the files a node reads) all read this
table. Standard library only: setup.py loads this file before the package is installed.
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module

PLANT, LOOP, GUEST, TOOL, CONTAINER = 'plant', 'loop', 'guest', 'tool', 'container'


@dataclass(frozen=True)
class NodeInfo:
    """One executable: ``eha_ros.nodes.<name>:main``, its files in config/ (later ones
    override earlier ones) and its parameter schema (module, attribute; imported lazily).

    role: ``plant`` a plant side of the 1 kHz loop (one of them runs; it owns the tick),
    ``loop`` a loop node eha_loop composes with it, ``guest`` a node that may join the loop's
    process, ``tool`` a node of its own process, ``container`` eha_loop itself.
    ``loop_prefix``: the parameter group of a plant side's loop settings (lockstep, autostart).
    ``joins_loop``: a tool that eha_loop hosts in real time with the loop nodes' parameters
    (plant.yaml's /** included): it answers the loop's ticks, which from a process of its own
    come too late for a 1 ms tick.
    ``guest``: a tool that may also join the loop's process as a guest (its own params
    sections only), taking the loop topics in-process (the recorder, in a composed run).
    """

    name: str
    role: str
    files: tuple = ()
    schema: tuple | None = None
    loop_prefix: str | None = None
    joins_loop: bool = False
    guest: bool = False

    @property
    def executable(self) -> str:
        return self.name

    @property
    def entry_point(self) -> str:
        return f'{self.name} = eha_ros.nodes.{self.name}:main'


_NODES = (
    NodeInfo('plant_sim', PLANT, ('plant.yaml', 'plant_sim.yaml'),
             ('eha_ros.core.hardware.sim_params', 'SCHEMA'), loop_prefix='sim_node'),
    NodeInfo('hardware_bridge', PLANT, ('plant.yaml', 'hardware_bridge.yaml'),
             ('eha_ros.core.hardware.bridge_params', 'SCHEMA'), loop_prefix='bridge'),
    NodeInfo('estimator', LOOP, ('plant.yaml', 'estimator.yaml'),
             ('eha_ros.core.estimator.params', 'SCHEMA')),
    NodeInfo('controller', LOOP, ('plant.yaml', 'controller.yaml', 'controller_node.yaml'),
             ('eha_ros.core.controller.params', 'SCHEMA')),
    NodeInfo('switch_manager', LOOP, ('plant.yaml', 'switch_manager.yaml'),
             ('eha_ros.core.redundancy.params', 'SCHEMA')),
    NodeInfo('live', GUEST, ('live.yaml',), ('eha_ros.core.io.live_params', 'SCHEMA')),
    NodeInfo('sweep', TOOL, ('plant.yaml', 'sweep.yaml'), ('eha_ros.core.sweep.params', 'SCHEMA')),
    NodeInfo('experiment', TOOL, ('plant.yaml', 'experiment.yaml'),
             ('eha_ros.core.ident.params', 'SCHEMA'), joins_loop=True),
    NodeInfo('recorder', TOOL, ('recorder.yaml',), ('eha_ros.core.io.recorder_params', 'SCHEMA'),
             guest=True),
    NodeInfo('eha_loop', CONTAINER),
)
NODES = {n.name: n for n in _NODES}

PLANT_NODES = tuple(n.name for n in _NODES if n.role == PLANT)
LOOP_NODES = tuple(n.name for n in _NODES if n.role == LOOP)
GUESTS = tuple(n.name for n in _NODES if n.role == GUEST or n.guest)
LOOP_TOOLS = tuple(n.name for n in _NODES if n.joins_loop)
# a node name -> its files in config/
NODE_FILES = {n.name: list(n.files) for n in _NODES if n.files}
LOOP_PREFIX = {n.name: n.loop_prefix for n in _NODES if n.loop_prefix}


def entry_points() -> list[str]:
    """console_scripts of setup.py: one executable per node."""
    return [n.entry_point for n in _NODES]


def node_names() -> list[str]:
    """Nodes with a parameter schema (check_config --node, the parameter reference)."""
    return sorted(n.name for n in _NODES if n.schema)


def schema_for(node: str):
    """The node's full Schema; an unknown name is a ParamError (one line)."""
    from .params import ParamError
    info = NODES.get(node)
    if info is None or info.schema is None:
        raise ParamError(f'unknown node {node!r}: expected one of {", ".join(node_names())}')
    module, attr = info.schema
    return getattr(import_module(module), attr)
