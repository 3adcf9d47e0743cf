"""eha_loop: the 1 kHz loop nodes composed in one process (see eha_ros.nodes.compose).

Usage: eha_loop [--plant sim|bridge] [--nodes a,b,...] --ros-args --params-file F ...

Each node is the same class as its standalone executable, with its own name, parameters
(its sections of the params files), services and /diagnostics; the topics between them are
delivered in-process, in the plant's (or bridge's) loop thread, so state(k) -> estimate(k)
-> command(k) completes within the tick. Everything else on the graph (sweep, recorder,
monitors, tests) sees the usual topics over DDS. ``--nodes ...,live`` adds the live view as a
guest: it takes the loop topics in-process and only its own params sections (no /**);
``--nodes ...,recorder`` the recorder likewise (what run_stack --record does in real time): the
loop's topics are then recorded without a DDS publish.
``--nodes ...,experiment`` hosts the experiment node (core.config.registry LOOP_TOOLS: it
answers the loop's ticks) with the loop nodes' parameters; when it ends itself, the process
ends (the plant side writes zero speed as it stops).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ..core.config.cli import UsageError, guarded
from ..core.config.params import load, parse_ros_args
from ..core.config.registry import GUESTS, LOOP_NODES, LOOP_TOOLS
from . import common

COMPOSED_STALE_CHECK = 0.005   # s: estimator.node.timer_period in eha_loop unless given
# GUESTS may join the loop's process: the live view then takes the loop topics in-process (the
# message object, serialized only for a subscribed viewer) instead of a second DDS delivery
PLANTS = {'sim': 'plant_sim', 'bridge': 'hardware_bridge'}
# s: Python's default. Shorter (0.2 ms tried) lets a 1 kHz executor timer preempt the loop
# thread mid-tick, only to block on the callback lock: two thread switches per timer tick.
GIL_SWITCH_INTERVAL = 5e-3


def parse(argv):
    ours, ros = argv, []
    if '--ros-args' in argv:
        i = argv.index('--ros-args')
        ours, ros = argv[:i], argv[i:]
    ap = argparse.ArgumentParser(prog='eha_loop', description=__doc__.splitlines()[0])
    ap.add_argument('--plant', choices=sorted(PLANTS), default='sim',
                    help='plant side: the simulator (plant_sim) or the drive (hardware_bridge)')
    ap.add_argument('--nodes', default=','.join(LOOP_NODES),
                    help='co-located nodes besides the plant side (default: %(default)s; '
                         f'may add {", ".join(GUESTS + LOOP_TOOLS)})')
    args = ap.parse_args(ours)
    names = [PLANTS[args.plant]] + [n for n in args.nodes.split(',') if n]
    known = set(PLANTS.values()) | set(LOOP_NODES) | set(GUESTS) | set(LOOP_TOOLS)
    for n in names:
        if n not in known:
            raise UsageError(f'--nodes: unknown node {n!r}: expected some of '
                             f'{", ".join(LOOP_NODES + GUESTS + LOOP_TOOLS)}')
    return names, ros


def main(argv=None) -> int:
    argv = list(sys.argv if argv is None else argv)

    def body() -> int:
        names, ros = parse(argv[1:])
        files, overrides, node_name, namespace = parse_ros_args(ros)
        if node_name:
            raise UsageError('-r __node:= would give every co-located node the same name; '
                             'rename single nodes with -r <node>:__node:=<name>')
        modules = {n: importlib.import_module(f'{__package__}.{n}') for n in names}
        if 'estimator' in names and not any(k.endswith('estimator.node.timer_period')
                                            for k in overrides):
            # states arrive in the loop thread itself: the stale check only matters when that
            # thread stalls, and a 1 kHz executor timer costs the loop a GIL hand-over per tick
            overrides = dict(overrides, **{'estimator:estimator.node.timer_period':
                                           COMPOSED_STALE_CHECK})
            ros = ros + ['-p', f'estimator:estimator.node.timer_period:={COMPOSED_STALE_CHECK}']
        # a guest takes what is addressed to it by name: the /** sections are the plant's
        params = {n: load(modules[n].SCHEMA, files, overrides, node=n, namespace=namespace,
                          wildcards=n not in GUESTS)
                  for n in names}
        if params[names[0]].get('sim_node.lockstep'):
            raise UsageError('lock-step runs each node as its own process '
                             '(scripts/run_stack --mode lockstep); eha_loop is real time only')
        sys.setswitchinterval(GIL_SWITCH_INTERVAL)

        def make_nodes():
            from .compose import Bus, composed_base
            bus = Bus()
            bus.guests.update(n for n in names if n in GUESTS)
            transport = composed_base(bus)
            nodes = [modules[n].make_node(params[n], transport) for n in names]
            bus.finalize()
            nodes[0].get_logger().info(
                f'eha_loop: {", ".join(names)} in one process; in-process topics: '
                f'{", ".join(bus.local_topics())}')
            return nodes

        return common.spin([argv[0]] + ros, make_nodes)

    return guarded('eha_loop', body)


if __name__ == '__main__':
    sys.exit(main())
