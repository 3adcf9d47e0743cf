"""Parameter schemas and the one loader for ROS params files (nodes and batch code alike).

A params file is in the ROS 2 format::

    /**:                       # applies to every node
      ros__parameters:
        plant: {pump: {D_p: 6.684e-7}}
    controller:                # applies to the node named 'controller'
      ros__parameters:
        rate_limit: 0.19

Nested mappings flatten to dotted names (``plant.pump.D_p``). Every error is a
:class:`ParamError` whose text is one line naming the file, the key, the value and
what was expected. No rclpy import here: nodes call :func:`load` with the files that
rcl will also read, batch code calls it directly.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Sequence

import yaml


class ParamError(Exception):
    """A configuration error; ``str(err)`` is one line fit for a user.

    ``key``: the parameter a cross-key check found wrong; Schema.validate puts the file that
    set it in front of the line, so the node and check_config print the same line."""

    def __init__(self, text: str, key: str | None = None):
        super().__init__(text)
        self.key = key


_REQUIRED = object()

# Accepted type names and their Python checks. Integers are accepted for floats.
_SCALAR = {
    'float': (float, int),
    'int': (int,),
    'bool': (bool,),
    'str': (str,),
}


@dataclass(frozen=True)
class Param:
    """One parameter: dotted name, type, SI unit, physical range and default."""

    name: str
    type: str = 'float'          # float | int | bool | str | float[] | int[] | str[]
    unit: str = ''
    default: Any = _REQUIRED
    min: float | None = None
    max: float | None = None
    choices: tuple | None = None
    doc: str = ''
    min_len: int = 1             # arrays only
    field: str | None = None     # the attribute it fills in a typed view (default: last part)

    @property
    def attr(self) -> str:
        """Name of the attribute this parameter fills (``field`` or the last dotted part)."""
        return self.field or self.name.rpartition('.')[2]

    @property
    def required(self) -> bool:
        return self.default is _REQUIRED

    def expected(self) -> str:
        """Human description of what the value must be."""
        text = self.type
        if self.choices is not None:
            text += ' one of ' + '|'.join(str(c) for c in self.choices)
        if self.min is not None or self.max is not None:
            lo = '-inf' if self.min is None else f'{self.min:g}'
            hi = 'inf' if self.max is None else f'{self.max:g}'
            text += f' in [{lo}, {hi}]'
        if self.unit:
            text += f' {self.unit}'
        return text

    def check(self, value: Any) -> Any:
        """Return the value coerced to the declared type, or raise ValueError."""
        if self.type.endswith('[]'):
            base = self.type[:-2]
            if not isinstance(value, (list, tuple)) or len(value) < self.min_len:
                raise ValueError
            return [self._check_scalar(base, v) for v in value]
        return self._check_scalar(self.type, value)

    def _check_scalar(self, base: str, value: Any) -> Any:
        kinds = _SCALAR[base]
        if isinstance(value, bool) and base != 'bool':
            raise ValueError
        if not isinstance(value, kinds):
            raise ValueError
        if base == 'float':
            value = float(value)
            if not math.isfinite(value):
                raise ValueError
        if base in ('float', 'int'):
            if self.min is not None and value < self.min:
                raise ValueError
            if self.max is not None and value > self.max:
                raise ValueError
        if self.choices is not None and value not in self.choices:
            raise ValueError
        return value


@dataclass
class Schema:
    """The parameters one node (or batch tool) accepts."""

    node: str
    params: Sequence[Param]
    # cross-key checks of the whole validated set (raises ParamError, one line): what the node
    # would refuse when it builds its core object, so check_config refuses exactly the same
    check: Callable[[dict], None] | None = field(default=None, compare=False, repr=False)
    by_name: dict = field(init=False, repr=False)

    def __post_init__(self):
        self.by_name = {p.name: p for p in self.params}
        if len(self.by_name) != len(self.params):
            raise ValueError(f'duplicate parameter in schema {self.node}')

    def __add__(self, other: 'Schema') -> 'Schema':
        """Shared parameters + a node's own: the result is named after the added (node) part
        and runs the cross-key checks of both (the shared part's first)."""
        return Schema(other.node, list(self.params) + list(other.params),
                      _chain(self.check, other.check))

    def defaults(self) -> dict:
        return {p.name: p.default for p in self.params if not p.required}

    def validate(self, values: Mapping[str, Any], sources: Mapping[str, str] | None = None,
                 context: str = '') -> dict:
        """Check values against the schema; fill defaults; return a new dict.

        ``sources`` maps a key to where it came from (a file name) for the message;
        ``context`` names the inputs as a whole for a missing key.
        """
        sources = sources or {}
        out = {}
        for key, value in values.items():
            where = sources.get(key, context or 'parameters')
            spec = self.by_name.get(key)
            if spec is None:
                raise ParamError(f'{where}: unknown parameter {key!r} = {value!r} for node '
                                 f'{self.node!r}: expected one of the schema\'s keys '
                                 f'({_near(key, self.by_name)})')
            try:
                out[key] = spec.check(value)
            except ValueError:
                raise ParamError(f'{where}: {key} = {value!r}: expected {spec.expected()}'
                                 f'{_yaml_float_hint(spec, value)}') from None
        for spec in self.params:
            if spec.name in out:
                continue
            if spec.required:
                raise ParamError(f'{context or "parameters"}: missing required parameter '
                                 f'{spec.name!r} for node {self.node!r}: expected '
                                 f'{spec.expected()}')
            out[spec.name] = spec.default
        if self.check is not None:
            try:
                self.check(out)
            except ParamError as err:
                if err.key is None:
                    raise
                raise ParamError(f'{sources.get(err.key) or context or "parameters"}: {err}',
                                 err.key) from None
        return out


def _chain(*checks):
    """One cross-key check that runs the given ones (None skipped) in order."""
    run = [p for c in checks if c is not None for p in getattr(c, 'parts', [c])]
    if len(run) <= 1:
        return run[0] if run else None

    def check(values: dict) -> None:
        for c in run:
            c(values)
    check.parts = run        # each one's docstring is a line of the parameter reference
    return check


def check_parts(schema: 'Schema') -> list:
    """The cross-key checks a schema runs, in order."""
    return [] if schema.check is None else list(getattr(schema.check, 'parts', [schema.check]))


def _near(key: str, names: Iterable[str]) -> str:
    import difflib
    close = difflib.get_close_matches(key, list(names), n=2, cutoff=0.6)
    return 'did you mean ' + ' or '.join(close) + '?' if close else 'see docs/parameters.md'


def flatten(tree: Mapping, prefix: str = '') -> dict:
    """Nested mappings to dotted keys, as rcl does for params files."""
    out = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = value
    return out


def fully_qualified(node: str, namespace: str = '/') -> str:
    ns = namespace.strip('/')
    return f'/{ns}/{node}' if ns else f'/{node}'


def _section_class(section: str, fqn: str):
    """How a params-file top-level key applies to a node, as rcl/rclpy do it.

    Returns 'wild' (wildcard section that matches), 'named' (the node's fully qualified name;
    a name without a leading slash is taken from the root), or None. rclpy gives named
    assignments precedence over wildcard ones whatever their order (rclpy PR #547).
    """
    import re
    name = section if section.startswith('/') else '/' + section
    if '*' not in name:
        return 'named' if name == fqn else None
    # '**' matches zero or more namespace tokens, '*' one token (or part of one)
    regex = ''.join('(/[^/]+)*' if t == '**' else '/' + re.escape(t).replace(r'\*', '[^/]*')
                    for t in name.split('/')[1:])
    return 'wild' if re.fullmatch(regex, fqn) else None


def read_params_sections(path: str, node: str, namespace: str = '/') -> tuple[dict, dict]:
    """Read one ROS params file: (wildcard assignments, named assignments) for this node."""
    try:
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
    except FileNotFoundError:
        raise ParamError(f'{path}: cannot read parameter file: no such file') from None
    except OSError as err:
        raise ParamError(f'{path}: cannot read parameter file: {err.strerror}') from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        problem = getattr(err, 'problem', None) or str(err).splitlines()[0]
        raise ParamError(f'{path}: malformed YAML{where}: {problem}: expected a ROS params file '
                         f'(node: ros__parameters: ...)') from None
    wild: dict = {}
    named: dict = {}
    if doc is None:
        return wild, named
    if not isinstance(doc, Mapping):
        raise ParamError(f'{path}: top level is {type(doc).__name__}: expected a mapping of '
                         f'node names to ros__parameters')
    fqn = fully_qualified(node, namespace)
    for section, body in doc.items():
        kind = _section_class(str(section), fqn)
        if kind is None:
            continue
        if not isinstance(body, Mapping) or 'ros__parameters' not in body:
            raise ParamError(f'{path}: section {section!r} = {body!r}: expected a mapping with '
                             f'a ros__parameters key')
        extra = [k for k in body if k != 'ros__parameters']
        if extra:
            raise ParamError(f'{path}: section {section!r} has key {extra[0]!r}: expected only '
                             f'ros__parameters')
        params = body['ros__parameters']
        if params is None:
            continue
        if not isinstance(params, Mapping):
            raise ParamError(f'{path}: {section}.ros__parameters = {params!r}: expected a mapping')
        (wild if kind == 'wild' else named).update(flatten(params))
    return wild, named


def read_params_file(path: str, node: str, namespace: str = '/') -> dict:
    """This node's flattened parameters from one file (named sections over wildcards)."""
    wild, named = read_params_sections(path, node, namespace)
    return {**wild, **named}


# Parameters every rclpy node accepts; batch code ignores them.
ROS_BUILTINS = ('use_sim_time', 'start_type_description_service')


def _yaml_float_hint(spec: 'Param', value) -> str:
    """YAML 1.1 (PyYAML, rcl) reads 5e-7 as a string: say how to write the number."""
    if not spec.type.startswith('float'):
        return ''
    for v in value if isinstance(value, (list, tuple)) else [value]:
        try:
            if isinstance(v, str) and math.isfinite(float(v)):
                return (f' ({v!r} is a string in YAML 1.1: a float needs a dot and a signed '
                        f'exponent, e.g. 5.0e-7)')
        except ValueError:
            continue
    return ''


def load(schema: Schema, files: Sequence[str] = (), overrides: Mapping[str, Any] | None = None,
         node: str | None = None, namespace: str = '/', wildcards: bool = True) -> dict:
    """Merge params files and overrides with rclpy's precedence, validate, fill defaults.

    Within a class later assignments win (files in order, then ``-p``); named assignments
    (the node's own sections, ``-p node:key:=value``) win over wildcard ones (``/**``
    sections, plain ``-p key:=value``), exactly as rclpy applies them. ``wildcards=False``:
    named assignments only (a guest node in eha_loop, whose /** sections are the plant's).
    """
    node = node or schema.node
    fqn = fully_qualified(node, namespace)
    wild: dict = {}
    named: dict = {}
    sources: dict = {}
    for path in files:
        w, n = read_params_sections(path, node, namespace)
        for target, part in ((wild, w if wildcards else {}), (named, n)):
            for key, value in part.items():
                target[key] = value
                sources[(target is named, key)] = path
    for key, value in (overrides or {}).items():
        target, name = wild, key
        if ':' in key:
            who, _, name = key.partition(':')
            if who not in (node, fqn, fqn.lstrip('/')):
                continue
            target = named
        elif not wildcards:
            continue
        target[name] = value
        sources[(target is named, name)] = 'command line'
    values = {**wild, **named}
    where = {k: sources.get((k in named, k)) for k in values}
    for key in ROS_BUILTINS:
        values.pop(key, None)
    context = ', '.join(files) if files else 'defaults'
    return schema.validate(values, where, context)


def override_arg(value: Any) -> str:
    """The text of ``-p key:=TEXT`` that rcl and :func:`parse_ros_args` read back as ``value``
    (YAML 1.1: a float keeps a dot and a signed exponent, 1e-12 -> 1.0e-12)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        mantissa, e, exponent = repr(value).partition('e')
        if '.' not in mantissa and mantissa.lstrip('-').isdigit():
            mantissa += '.0'
        return mantissa + (f'e{"" if exponent[0] in "+-" else "+"}{exponent}' if e else '')
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(override_arg(v) for v in value) + ']'
    return str(value)


CONFIG_ENV = 'EHA_CONFIG_DIR'
PACKAGE = 'eha_ros'


def checkout_config_dir() -> str:
    """config/ of the repository this module would sit in as a checkout
    (<repo>/src/eha_ros/eha_ros/core/config/params.py); it may not exist (installed)."""
    here = os.path.dirname(os.path.abspath(__file__))
    return os.path.normpath(os.path.join(here, *['..'] * 5, 'config'))


def _is_checkout_config(path: str) -> bool:
    root = os.path.dirname(path)
    return os.path.isdir(path) and os.path.isfile(os.path.join(root, 'src', PACKAGE, 'setup.py'))


def installed_config_dir() -> tuple[str | None, str]:
    """(share/eha_ros/config of the installed package found through the ament index, or None;
    what was looked at, for an error message). ament_index_python may be missing, or
    AMENT_PREFIX_PATH unset or without eha_ros."""
    try:
        from ament_index_python.packages import get_package_share_directory
    except ImportError:
        return None, 'share/eha_ros/config (ament_index_python not importable)'
    try:
        share = get_package_share_directory(PACKAGE, print_warning=False)
    except (LookupError, OSError, ValueError):      # PackageNotFoundError, AMENT_PREFIX_PATH unset
        prefixes = os.environ.get('AMENT_PREFIX_PATH') or 'unset'
        return None, f'share/eha_ros/config of the ament index (AMENT_PREFIX_PATH {prefixes})'
    path = os.path.join(share, 'config')
    return (path if os.path.isdir(path) else None), path


def default_config_dir() -> str:
    """The folder of the YAML files of config/: $EHA_CONFIG_DIR if set, else the repository's
    config/ when running from a checkout, else share/eha_ros/config of the installed package
    (colcon build, found through the ament index); else a ParamError (one line) naming the
    three places looked at. Never the current folder's ./config."""
    env = os.environ.get(CONFIG_ENV)
    if env:
        if not os.path.isdir(env):
            raise ParamError(f'{CONFIG_ENV}={env}: no such folder (expected the folder with '
                             f'plant.yaml and the other files of config/)')
        return env
    checkout = checkout_config_dir()
    if _is_checkout_config(checkout):
        return checkout
    installed, looked = installed_config_dir()
    if installed:
        return installed
    raise ParamError(f'config folder not found: ${CONFIG_ENV} is not set, {checkout} is not a '
                     f'checkout\'s config/, no {looked}; set {CONFIG_ENV} or source the '
                     f'install\'s setup.bash')


# --ros-args flags that take a value (rcl arguments.c), and the log levels rcl accepts
_VALUE_FLAGS = ('--params-file', '-p', '--param', '-r', '--remap', '--log-level',
                '--log-file-name', '-e', '--enclave')
_LOG_LEVELS = ('debug', 'info', 'warn', 'error', 'fatal', 'unset')


def parse_ros_args(argv: Sequence[str]) -> tuple[list[str], dict, str | None, str]:
    """Pick params files, -p overrides, node-name and namespace remaps out of --ros-args.
    A flag without its value or a log level rcl would refuse is a ParamError (one line)
    here, before rcl prints its own error and rclpy a traceback."""
    files: list[str] = []
    overrides: dict = {}
    name = None
    namespace = '/'
    in_ros = False
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg == '--ros-args':
            in_ros = True
        elif arg == '--':
            in_ros = False
        elif in_ros and arg in _VALUE_FLAGS:
            if i + 1 >= len(argv) or argv[i + 1] in ('--', '--ros-args'):
                raise ParamError(f'command line: --ros-args {arg} at the end without its value')
            value = argv[i + 1]
            if arg == '--params-file':
                files.append(value)
            elif arg in ('-p', '--param'):
                key, sep, text = value.partition(':=')
                if not sep:
                    raise ParamError(f'command line: -p {value!r}: expected name:=value')
                try:
                    overrides[key] = yaml.safe_load(text) if text else ''
                except yaml.YAMLError:
                    overrides[key] = text
            elif arg in ('-r', '--remap'):
                src, _, dst = value.partition(':=')
                if src == '__node' or src.endswith(':__node'):
                    name = dst
                elif src == '__ns' or src.endswith(':__ns'):
                    namespace = dst
            elif arg == '--log-level' and value.rpartition(':=')[2].lower() not in _LOG_LEVELS:
                raise ParamError(f'command line: --log-level {value!r}: expected one of '
                                 f'{", ".join(_LOG_LEVELS[:-1])} (or logger:=level)')
            i += 1
        i += 1
    return files, overrides, name, namespace
