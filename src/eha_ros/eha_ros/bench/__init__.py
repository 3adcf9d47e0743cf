"""Benchmarks: each module here has ``run(args) -> dict`` of flat keys in SI units.

``scripts/bench <name>`` (``python -m eha_ros.bench <name>``) runs one and writes
``out/bench/<name>.json`` with the machine's core count and the command that produced it.
"""


def arg(args, name: str, default):
    """A benchmark option from argparse args or a dict; ``default`` when absent or None."""
    if args is None:
        return default
    value = args.get(name) if isinstance(args, dict) else getattr(args, name, None)
    return default if value is None else value
