"""Validate ROS params files against a node's schema without starting ROS.

    python -m eha_ros.tools.check_config --node plant_sim config/plant.yaml config/plant_sim.yaml \
        [--ros-args] [-p [node:]key:=value ...]

The same checks as the node at start-up (types, ranges, the schema's cross-key checks), the
same one-line error, exit 2; -p overrides with the node's precedence (node:key over key).
"""
from __future__ import annotations

import argparse
import sys

from ..core.config.cli import UsageError, guarded
from ..core.config.params import load, parse_ros_args
from ..core.config.registry import node_names, schema_for


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='check_config', description=__doc__.splitlines()[0],
                                 epilog='-p [node:]key:=value overrides a parameter (with or '
                                        'without --ros-args before it)')
    ap.add_argument('--node', required=True, help=f'node name: {", ".join(node_names())}')
    ap.add_argument('files', nargs='*', help='ROS params files, later ones override earlier')
    ap.add_argument('--show', action='store_true', help='print every resolved parameter')
    args, rest = ap.parse_known_args(argv)

    def run():
        ros = rest if not rest or rest[0] == '--ros-args' else ['--ros-args'] + rest
        unknown = [a for a in rest if a.startswith('-') and a not in
                   ('--ros-args', '-p', '--param', '--params-file')]
        if unknown:
            raise UsageError(f'unknown argument {unknown[0]!r}: expected -p [node:]key:=value '
                             f'or --params-file FILE after the files')
        more, overrides, _, _ = parse_ros_args(ros)
        args.files += more
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
