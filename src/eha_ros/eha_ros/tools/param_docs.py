"""Write the parameter reference (docs/parameters.md) from the node schemas.

    python -m eha_ros.tools.param_docs [--out docs/parameters.md] [--check]

One Markdown table per node of eha_ros.core.config.registry (parameter, type, unit, default, range,
description), so the reference cannot drift from what the nodes accept. tests/test_docs.py
fails when the committed file differs from what this writes.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

from ..core.config.cli import UsageError, guarded
from ..core.config.params import check_parts

PROG = 'param_docs'
COMMAND = 'python -m eha_ros.tools.param_docs'


def _default_out() -> str:
    """docs/parameters.md of the checkout this module sits in (src/eha_ros/eha_ros/tools/)."""
    root = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), *['..'] * 4))
    if os.path.isdir(os.path.join(root, 'src', 'eha_msgs')):
        return os.path.join(root, 'docs', 'parameters.md')
    return os.path.join('docs', 'parameters.md')     # installed package: relative to the cwd


DEFAULT_OUT = _default_out()


def _number(value) -> str:
    """Shortest exact text of a number: 0.001, 1e-05 -> 1e-5, 1379000000.0 -> 1.379e9."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    value = float(value)
    if not math.isfinite(value):
        return str(value)
    text = repr(value)
    if value != 0 and (abs(value) >= 1e5 or abs(value) < 1e-3):
        for digits in range(17):
            sci = f'{value:.{digits}e}'
            if float(sci) == value:
                mantissa, exp = sci.split('e')
                text = f'{mantissa}e{int(exp)}'
                break
    return text


def _value(value) -> str:
    if isinstance(value, str):
        return value if value else "''"
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_value(v) for v in value) + ']'
    if isinstance(value, (bool, int, float)):
        return _number(value)
    return str(value)


def _cell(text: str) -> str:
    return ' '.join(str(text).split()).replace('|', '\\|')


def _code(text: str) -> str:
    return f'`{text}`' if text else ''


def _range(param) -> str:
    parts = []
    if param.choices is not None:
        parts.append('one of ' + ', '.join(_code(_value(c)) for c in param.choices))
    if param.min is not None and param.max is not None:
        parts.append(f'[{_number(param.min)}, {_number(param.max)}]')
    elif param.min is not None:
        parts.append(f'>= {_number(param.min)}')
    elif param.max is not None:
        parts.append(f'<= {_number(param.max)}')
    if param.type.endswith('[]'):
        parts.append(f'length >= {param.min_len}')
    return '; '.join(parts)


def _node_files(node: str) -> list[str]:
    from ..core.config.registry import NODE_FILES
    return list(NODE_FILES.get(node, []))


def schemas() -> list:
    """(node, Schema) for every node, in the order of node_names()."""
    from ..core.config.registry import node_names, schema_for
    out = []
    for node in node_names():
        try:
            out.append((node, schema_for(node)))
        except Exception as err:
            raise UsageError(f'cannot load the schema of node {node!r}: '
                             f'{type(err).__name__}: {err}') from None
    return out


def render() -> str:
    """The whole of docs/parameters.md."""
    nodes = schemas()
    total = sum(len(schema.params) for _, schema in nodes)
    lines = [
        '# Parameter reference',
        '',
        f'Generated from the parameter schemas (`eha_ros.core.config.registry`) by '
        f'`eha_ros.tools.param_docs`: do not edit by hand. After changing a schema, regenerate '
        f'with `.venv/bin/{COMMAND}` (tests/test_docs.py fails until the file matches).',
        '',
        f'{len(nodes)} nodes, {total} parameters. Each node checks its parameters against '
        'this schema before ROS starts (`.venv/bin/python -m eha_ros.tools.check_config '
        '--node NODE FILE...` checks files without starting anything). Units are SI; '
        '"required" means the key has no default and must be set in a params file; '
        'range bounds are inclusive. A file of `config/` lists only the keys that differ '
        'from these defaults (or that a user is expected to edit); tests/test_config_home.py '
        'keeps it so.',
        '',
    ]
    lines += [f'- [{node}](#{node}) ({len(schema.params)})' for node, schema in nodes]
    for node, schema in nodes:
        lines += ['', f'## {node}', '']
        files = _node_files(node)
        if files:
            lines += ['Read from ' + ', '.join(f'`config/{f}`' for f in files)
                      + ' (later files override earlier ones).', '']
        lines += ['| parameter | type | unit | default | range | description |',
                  '| --- | --- | --- | --- | --- | --- |']
        for p in schema.params:
            default = 'required' if p.required else _code(_value(p.default))
            row = [_code(p.name), p.type, p.unit, default, _range(p), p.doc]
            lines.append('| ' + ' | '.join(_cell(c) for c in row) + ' |')
        checks = [' '.join((c.__doc__ or c.__qualname__).split()) for c in check_parts(schema)]
        if checks:
            lines += ['', 'Checks across keys (the node and check_config refuse the same files):']
            lines += [f'- `{c.__module__}.{c.__qualname__}`: {text}'
                      for c, text in zip(check_parts(schema), checks)]
    return '\n'.join(lines) + '\n'


def _shown(path: str) -> str:
    rel = os.path.relpath(os.path.abspath(path))
    return path if rel.startswith('..') else rel


class _Parser(argparse.ArgumentParser):
    def error(self, message):           # one line, not usage + error
        self.exit(2, f'{self.prog}: error: {message} (see --help)\n')


def main(argv=None) -> int:
    ap = _Parser(
        prog=PROG,
        description='Write the parameter reference, one Markdown table per node (parameter, '
                    'type, unit, default, range, description), from the schemas of '
                    'eha_ros.core.config.registry.',
        epilog='Exit codes: 0 written or up to date; 1 --check found the file out of date or '
               'missing; 2 error (one line on stderr).')
    ap.add_argument('--out', default=DEFAULT_OUT,
                    help='Markdown file to write (default: docs/parameters.md of the repository)')
    ap.add_argument('--check', action='store_true',
                    help='write nothing; exit 1 when the file differs from what would be '
                         'generated (or is missing), 0 when it is up to date')
    args = ap.parse_args(argv)
    shown = _shown(args.out)

    def run():
        text = render()
        if args.check:
            try:
                with open(args.out, encoding='utf-8') as fh:
                    current = fh.read()
            except FileNotFoundError:
                current = None
            except OSError as err:
                raise UsageError(f'cannot read {shown}: {err.strerror or err}') from None
            if current != text:
                state = 'missing' if current is None else 'out of date with the schemas'
                print(f'{PROG}: {shown} is {state}: run {COMMAND} --out {shown}',
                      file=sys.stderr, flush=True)
                return 1
            print(f'{PROG}: {shown} is up to date')
            return 0
        try:
            with open(args.out, 'w', encoding='utf-8') as fh:
                fh.write(text)
        except OSError as err:
            raise UsageError(f'cannot write {shown}: {err.strerror or err}') from None
        print(f'{PROG}: wrote {shown}')
        return 0

    return guarded(PROG, run)


if __name__ == '__main__':
    sys.exit(main())
