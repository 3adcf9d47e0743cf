"""ADS symbol map: bridge role -> PLC symbol, PLC type and scale (config/ads_symbols.yaml).

Every role the bridge reads or writes must be mapped exactly once; each mapping names the PLC
symbol, its IEC 61131-3 type and ``scale`` (SI value = PLC value * scale, e.g. 0.001 for a
position in mm). Errors are :class:`ParamError` with one line naming the file, the key, the
value and what was expected.
"""
from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass
from typing import Mapping

import yaml

from ..config.params import ParamError

# IEC type -> (struct format, ADS data type id ADST_*, kind)
PLC_TYPES = {
    'BOOL': ('?', 33, 'bool'),
    'SINT': ('b', 16, 'int'), 'USINT': ('B', 17, 'int'), 'BYTE': ('B', 17, 'int'),
    'INT': ('h', 2, 'int'), 'UINT': ('H', 18, 'int'), 'WORD': ('H', 18, 'int'),
    'DINT': ('i', 3, 'int'), 'UDINT': ('I', 19, 'int'), 'DWORD': ('I', 19, 'int'),
    'LINT': ('q', 20, 'int'), 'ULINT': ('Q', 21, 'int'),
    'REAL': ('f', 4, 'real'), 'LREAL': ('d', 5, 'real'),
}

# role -> (direction, accepted kinds, SI unit, meaning)
NUMBER = ('real', 'int')
ROLES = {
    'plc_cycle': ('read', ('int',), '', 'PLC task cycle counter; data is stale while it stands still'),
    'position': ('read', NUMBER, 'm', 'piston position, 0 = mid-stroke'),
    'motor_speed_0': ('read', NUMBER, 'rad/s', 'motor speed of couple 0'),
    'motor_speed_1': ('read', NUMBER, 'rad/s', 'motor speed of couple 1'),
    'motor_current_0': ('read', NUMBER, 'A', 'torque current of couple 0'),
    'motor_current_1': ('read', NUMBER, 'A', 'torque current of couple 1'),
    'pressure_a': ('read', NUMBER, 'Pa', 'chamber A pressure (gauge)'),
    'pressure_b': ('read', NUMBER, 'Pa', 'chamber B pressure (gauge)'),
    'active_channel': ('read', ('int',), '', 'couple driving the piston, 0 or 1'),
    'valve_open_0': ('read', ('bool',), '', 'on-off valves of couple 0 open'),
    'valve_open_1': ('read', ('bool',), '', 'on-off valves of couple 1 open'),
    'drive_enabled_0': ('read', ('bool',), '', 'drive 0 enabled (status word)'),
    'drive_enabled_1': ('read', ('bool',), '', 'drive 1 enabled (status word)'),
    'drive_fault_0': ('read', ('bool',), '', 'drive 0 reports a fault'),
    'drive_fault_1': ('read', ('bool',), '', 'drive 1 reports a fault'),
    'bypass_open': ('read', ('bool',), '', 'A-B bypass valve open'),
    'speed_ref': ('write', NUMBER, 'rad/s', 'motor speed reference of the active couple'),
    'channel_cmd': ('write', ('int',), '', 'couple that should drive, 0 or 1'),
    'drive_enable_0': ('write', ('bool',), '', 'enable drive 0'),
    'drive_enable_1': ('write', ('bool',), '', 'enable drive 1'),
    'valve_cmd_0': ('write', ('bool',), '', 'open the valves of couple 0'),
    'valve_cmd_1': ('write', ('bool',), '', 'open the valves of couple 1'),
    'bypass_cmd': ('write', ('bool',), '', 'open the A-B bypass valve'),
    'heartbeat': ('write', ('int',), '', 'counter written every cycle; the PLC stops the drive '
                  'when it stands still'),
}
READ_ROLES = tuple(r for r, v in ROLES.items() if v[0] == 'read')
WRITE_ROLES = tuple(r for r, v in ROLES.items() if v[0] == 'write')


@dataclass(frozen=True)
class Symbol:
    """One mapped PLC variable."""

    role: str
    name: str
    plc_type: str
    scale: float = 1.0

    @property
    def fmt(self) -> str:
        return PLC_TYPES[self.plc_type][0]

    @property
    def ads_type(self) -> int:
        return PLC_TYPES[self.plc_type][1]

    @property
    def kind(self) -> str:
        return PLC_TYPES[self.plc_type][2]

    @property
    def size(self) -> int:
        return struct.calcsize('<' + self.fmt)

    def to_plc(self, value):
        """SI value -> PLC value (rounded and clamped to the integer type's range)."""
        if self.kind == 'bool':
            return bool(value)
        raw = value / self.scale
        if self.kind == 'real':
            return float(raw)
        lo, hi = int_range(self.fmt)
        return int(min(max(round(raw), lo), hi))

    def to_si(self, raw):
        if self.kind == 'bool':
            return bool(raw)
        return raw * self.scale if self.scale != 1.0 else raw


def int_range(fmt: str) -> tuple[int, int]:
    bits = 8 * struct.calcsize('<' + fmt)
    return (0, 2 ** bits - 1) if fmt.isupper() else (-2 ** (bits - 1), 2 ** (bits - 1) - 1)


class SymbolMap:
    """The validated map; ``read``/``write`` list the symbols in block order."""

    def __init__(self, symbols: Mapping[str, Symbol], path: str = ''):
        self.path = path
        self.by_role = dict(symbols)
        self.read = [self.by_role[r] for r in READ_ROLES]
        self.write = [self.by_role[r] for r in WRITE_ROLES]
        self.read_fmt = '<' + ''.join(s.fmt for s in self.read)
        self.write_fmt = '<' + ''.join(s.fmt for s in self.write)
        self.read_size = struct.calcsize(self.read_fmt)
        self.write_size = struct.calcsize(self.write_fmt)

    def __getitem__(self, role: str) -> Symbol:
        return self.by_role[role]

    def decode_read(self, raw: tuple) -> dict:
        """Raw values of the read block (struct order) -> {role: SI value}."""
        return {s.role: s.to_si(v) for s, v in zip(self.read, raw)}

    def encode_write(self, values: Mapping[str, object]) -> tuple:
        """{role: SI value} -> raw values of the write block (struct order)."""
        return tuple(s.to_plc(values[s.role]) for s in self.write)


def resolve_path(path: str, config_dir: str) -> str:
    """A relative map path is taken from the config folder."""
    return path if os.path.isabs(path) else os.path.join(config_dir, path)


def load_symbol_map(path: str) -> SymbolMap:
    """Read and validate a symbol map YAML file; one-line ParamError on any mistake."""
    try:
        with open(path, encoding='utf-8') as fh:
            doc = yaml.safe_load(fh)
    except FileNotFoundError:
        raise ParamError(f'{path}: cannot read symbol map: no such file') from None
    except OSError as err:
        raise ParamError(f'{path}: cannot read symbol map: {err.strerror}') from None
    except yaml.YAMLError as err:
        mark = getattr(err, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark else ''
        raise ParamError(f'{path}: malformed YAML{where}: expected a symbol map '
                         f'(symbols: {{role: {{symbol: NAME, type: TYPE}}}})') from None
    if not isinstance(doc, Mapping) or not isinstance(doc.get('symbols'), Mapping):
        raise ParamError(f'{path}: expected a mapping with a "symbols" key '
                         f'(symbols: {{role: {{symbol: NAME, type: TYPE}}}})')
    extra = [k for k in doc if k != 'symbols']
    if extra:
        raise ParamError(f'{path}: unknown top-level key {extra[0]!r}: expected only symbols')
    symbols = {}
    names = {}
    for role, entry in doc['symbols'].items():
        symbols[role] = _symbol(path, str(role), entry)
        other = names.setdefault(symbols[role].name, role)
        if other != role:
            raise ParamError(f'{path}: symbols.{role}.symbol = {symbols[role].name!r} is '
                             f'already mapped to {other}: expected one PLC symbol per role')
    missing = [r for r in ROLES if r not in symbols]
    if missing:
        raise ParamError(f'{path}: missing role {missing[0]!r} ({ROLES[missing[0]][3]}): '
                         f'every role of {", ".join(ROLES)} must be mapped')
    return SymbolMap(symbols, path)


def _symbol(path: str, role: str, entry) -> Symbol:
    import difflib
    if role not in ROLES:
        near = difflib.get_close_matches(role, list(ROLES), n=1)
        hint = f'did you mean {near[0]}?' if near else f'expected one of {", ".join(ROLES)}'
        raise ParamError(f'{path}: symbols.{role}: unknown role: {hint}')
    direction, kinds, unit, _ = ROLES[role]
    key = f'symbols.{role}'
    if not isinstance(entry, Mapping):
        raise ParamError(f'{path}: {key} = {entry!r}: expected {{symbol: NAME, type: TYPE}}')
    extra = [k for k in entry if k not in ('symbol', 'type', 'scale')]
    if extra:
        raise ParamError(f'{path}: {key}.{extra[0]}: unknown key: expected symbol, type, scale')
    name = entry.get('symbol')
    if not isinstance(name, str) or not name.strip() or any(c.isspace() for c in name.strip()):
        raise ParamError(f'{path}: {key}.symbol = {name!r}: expected a PLC symbol name such '
                         f'as GVL_EHA.fPosition')
    ptype = entry.get('type')
    if not isinstance(ptype, str) or ptype.upper() not in PLC_TYPES:
        raise ParamError(f'{path}: {key}.type = {ptype!r}: expected one of '
                         f'{", ".join(PLC_TYPES)}')
    ptype = ptype.upper()
    kind = PLC_TYPES[ptype][2]
    if kind not in kinds:
        want = {'bool': 'BOOL', 'int': 'an integer type', 'real': 'REAL or LREAL'}
        raise ParamError(f'{path}: {key}.type = {ptype}: wrong type for {role} '
                         f'({ROLES[role][3]}): expected {" or ".join(want[k] for k in kinds)}')
    scale = entry.get('scale', 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or \
            not math.isfinite(scale) or scale <= 0:
        raise ParamError(f'{path}: {key}.scale = {scale!r}: expected a positive number '
                         f'({unit or "SI"} per PLC unit)')
    if kind != 'real' and kind in kinds and kinds != NUMBER and scale != 1.0:
        raise ParamError(f'{path}: {key}.scale = {scale!r}: expected 1 for a {kind} role')
    return Symbol(role, name.strip(), ptype, float(scale))
