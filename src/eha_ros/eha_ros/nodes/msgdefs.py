"""Full ROS 2 message definitions (ros2msg, as rosbag2 writes them into MCAP schemas).

The text of a type is its .msg file followed by every type it depends on, each after a line of
80 '=' and a ``MSG: pkg/Type`` header, so that readers without the packages (Foxglove,
mcap_ros2) can decode the CDR. The .msg files come from ``<prefix>/share/<pkg>/msg/``; when one
is missing the text is generated from the Python class' field types (comments and constants
lost, layout the same). Needs the generated message packages, not rclpy.
"""
from __future__ import annotations

import importlib
import os
import re
import sys

SEPARATOR = '=' * 80
_NAMESPACED = re.compile(r'([A-Za-z_][A-Za-z0-9_]*)/([A-Za-z_][A-Za-z0-9_]*)')
_IDL_TO_MSG = {'double': 'float64', 'float': 'float32', 'boolean': 'bool', 'octet': 'byte',
               'long double': 'float64'}


def split_type(type_name: str) -> tuple[str, str]:
    """'eha_msgs/msg/ActuatorState' or 'eha_msgs/ActuatorState' -> ('eha_msgs', 'ActuatorState')."""
    parts = type_name.split('/')
    if len(parts) == 3 and parts[1] == 'msg':
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise ValueError(f'{type_name!r}: expected pkg/msg/Type')


def message_class(type_name: str):
    """The generated Python class of a message type; ValueError if it is not installed."""
    pkg, name = split_type(type_name)
    try:
        return getattr(importlib.import_module(f'{pkg}.msg'), name)
    except (ImportError, AttributeError):
        raise ValueError(f'{type_name}: message package not installed') from None


def _prefixes() -> list[str]:
    env = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return env + [sys.prefix]


def msg_file_text(pkg: str, name: str) -> str | None:
    """Text of share/<pkg>/msg/<name>.msg under the first prefix that has it."""
    for prefix in _prefixes():
        path = os.path.join(prefix, 'share', pkg, 'msg', f'{name}.msg')
        if os.path.isfile(path):
            with open(path, encoding='utf-8') as fh:
                return fh.read()
    return None


def _msg_type(idl: str) -> str:
    """A field type as get_fields_and_field_types spells it -> .msg syntax."""
    m = re.fullmatch(r'sequence<(.+?)(?:, (\d+))?>', idl)
    if m:
        return _msg_type(m.group(1)) + (f'[<={m.group(2)}]' if m.group(2) else '[]')
    m = re.fullmatch(r'(.+?)\[(\d+)\]', idl)
    if m:
        return f'{_msg_type(m.group(1))}[{m.group(2)}]'
    return _IDL_TO_MSG.get(idl, idl)


def generated_text(cls) -> str:
    """A .msg text from the class' fields (fallback when the .msg file is not installed)."""
    return ''.join(f'{_msg_type(t)} {f}\n' for f, t in cls.get_fields_and_field_types().items())


def _deps(cls) -> list[str]:
    """Direct dependencies 'pkg/Type' of a message class, in field order."""
    out = []
    for t in cls.get_fields_and_field_types().values():
        for pkg, name in _NAMESPACED.findall(t):
            if f'{pkg}/{name}' not in out:
                out.append(f'{pkg}/{name}')
    return out


def definition(type_name: str) -> str:
    """The full ros2msg definition of a type: its text, then each dependency once."""
    pkg, name = split_type(type_name)
    cls = message_class(type_name)
    parts = [_text(pkg, name, cls)]
    seen = {f'{pkg}/{name}'}
    todo = _deps(cls)
    while todo:
        dep = todo.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        dpkg, dname = split_type(dep)
        dcls = message_class(dep)
        parts.append(f'{SEPARATOR}\nMSG: {dep}\n{_text(dpkg, dname, dcls)}')
        todo += [d for d in _deps(dcls) if d not in seen]
    return '\n'.join(p.rstrip('\n') + '\n' for p in parts)


def _text(pkg: str, name: str, cls) -> str:
    return msg_file_text(pkg, name) or generated_text(cls)


def header_first(cls) -> bool:
    """True when the first field is a std_msgs/Header (its stamp is the publish time)."""
    fields = list(cls.get_fields_and_field_types().items())
    return bool(fields) and fields[0][1] == 'std_msgs/Header'
