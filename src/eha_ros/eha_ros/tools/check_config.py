"""Validate ROS params files against a node's schema without starting ROS.

    python -m eha_ros.tools.check_config --node plant_sim config/plant.yaml config/plant_sim.yaml
"""
from __future__ import annotations

import argparse
import sys

from ..core.cli import guarded
from ..core.params import load, parse_ros_args
from ..core.schemas import node_names, schema_for


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='check_config', description=__doc__.splitlines()[0])
    ap.add_argument('--node', required=True, help=f'node name: {", ".join(node_names())}')
    ap.add_argument('files', nargs='*', help='ROS params files, later ones override earlier')
    ap.add_argument('--show', action='store_true', help='print every resolved parameter')
    args, rest = ap.parse_known_args(argv)
    _, overrides, _, _ = parse_ros_args(rest)

    def run():
        values = load(schema_for(args.node), args.files, overrides, node=args.node)
        if args.show:
            for key in sorted(values):
                print(f'{key}: {values[key]!r}')
        print(f'check_config: ok: {len(values)} parameters for node {args.node!r} from '
              f'{", ".join(args.files) or "defaults"}')
        return 0

    return guarded('check_config', run)


if __name__ == '__main__':
    sys.exit(main())
