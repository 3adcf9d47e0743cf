"""Benchmarks: each module here has ``run(args) -> dict`` of flat keys in SI units.

``scripts/bench <name>`` (``python -m eha_ros.bench <name>``) runs one and writes
``out/bench/<name>.json`` with the machine's core count and the command that produced it.
"""
