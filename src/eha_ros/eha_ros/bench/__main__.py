"""scripts/bench <name> [--out DIR] [--duration S] [--recordings PATH...]: run a benchmark,
write out/bench/<name>.json."""
from __future__ import annotations

import argparse
import datetime
import importlib
import os
import pkgutil
import platform
import sys

from ..core.config.cli import UsageError, guarded
from ..core.io.report import write_json

HERE = os.path.dirname(os.path.abspath(__file__))


def available() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules([HERE]) if not m.name.startswith('_'))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(prog='bench', description=__doc__.splitlines()[0])
    ap.add_argument('name', help='benchmark: ' + ', '.join(available()))
    ap.add_argument('--out', default='out/bench', help='output folder (default out/bench)')
    ap.add_argument('--duration', type=float, default=None,
                    help='measurement length in seconds where the benchmark has one')
    ap.add_argument('--recordings', nargs='+', default=None, metavar='PATH',
                    help='recordings for the benchmarks that fit them (identify)')
    args = ap.parse_args(argv)

    def run():
        if args.name not in available():
            raise UsageError(f'unknown benchmark {args.name!r}: expected one of '
                             f'{", ".join(available())}')
        module = importlib.import_module(f'{__package__}.{args.name}')
        print(f'bench {args.name}: running ...', file=sys.stderr, flush=True)
        result = module.run(args)
        result.update({'benchmark': args.name, 'cpu_cores': os.cpu_count(),
                       'machine': platform.machine(), 'python': platform.python_version(),
                       'command': 'scripts/bench ' + ' '.join(argv),
                       'timestamp': datetime.datetime.now(datetime.timezone.utc).isoformat()})
        path = os.path.join(args.out, f'{args.name}.json')
        write_json(path, result, sort_keys=True)
        for key in sorted(result):
            print(f'{key}: {result[key]}')
        print(f'bench {args.name}: wrote {path}')
        return 0

    return guarded('bench', run)


if __name__ == '__main__':
    sys.exit(main())
