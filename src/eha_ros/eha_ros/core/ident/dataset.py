"""Identification recordings (MCAP, thesis sec. 3.6) to arrays on the plant's tick grid, with
the checks that turn a user's mistake into one line naming the file (core.config.cli).

Each recording names its experiment on /eha/experiment (std_msgs/String, JSON: experiment,
version, plant_side, params). States come by seq (the plant tick); a command answers the state
of its seq and is applied from the next tick on, held until the next one (as the plant side
does); references and loads are aligned by their header stamps with the states'. Never read:
/eha/sim/truth (a bench has no truth).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from ..config.cli import UsageError
from ..io import recording as R
from .. import topics as T

EXPERIMENTS = ('drive', 'friction', 'leakage', 'validation')
VERSION = 1
STATE, COMMAND, REFERENCE, LOAD, META = (T.STATE.path, T.COMMAND.path, T.REFERENCE.path,
                                         T.LOAD_FORCE.path, T.EXPERIMENT.path)
TYPES = {STATE: 'eha_msgs/msg/ActuatorState', COMMAND: 'eha_msgs/msg/ActuatorCommand',
         REFERENCE: 'eha_msgs/msg/PositionReference', LOAD: 'eha_msgs/msg/ExternalLoad',
         META: 'std_msgs/msg/String'}
NEEDS = {'drive': (STATE, COMMAND), 'friction': (STATE,), 'leakage': (STATE, LOAD),
         'validation': (STATE, REFERENCE)}
MIN_DURATION = 2.0          # [s] shortest usable recording
MAX_MISSING = 0.05          # largest share of plant ticks without a recorded state
STAMP_SLACK = 0.5e-3        # [s] a message stamped up to this after a state counts for it
_STATE_FIELDS = ('position', 'motor_speed[0]', 'motor_speed[1]', 'motor_current[0]',
                 'motor_current[1]', 'pressure_a', 'pressure_b', 'active_channel',
                 'header.stamp.sec', 'header.stamp.nanosec')


@dataclass
class Recording:
    """One experiment on a gap-free tick grid (SI units); ``recorded`` marks the ticks that
    have a state (the others are interpolated and left out of every residual)."""
    path: str
    experiment: str
    plant_side: str
    params: dict
    Ts: float
    seq: np.ndarray
    t: np.ndarray               # [s] state stamps
    position: np.ndarray        # [m]
    motor_speed: np.ndarray     # [rad/s] (n, 2)
    motor_current: np.ndarray   # [A] (n, 2)
    pressure_a: np.ndarray      # [Pa]
    pressure_b: np.ndarray      # [Pa]
    channel: np.ndarray         # active channel per tick
    recorded: np.ndarray        # bool
    command: np.ndarray = field(default=None)      # [rad/s] command answering state k
    reference: np.ndarray = field(default=None)    # [m]
    load: np.ndarray = field(default=None)         # [N], eq. 3.23 sign

    @property
    def n(self) -> int:
        return len(self.seq)

    @property
    def p_d(self) -> np.ndarray:
        """Load pressure p_A - p_B [Pa]."""
        return self.pressure_a - self.pressure_b

    @property
    def speed(self) -> np.ndarray:
        """The active couple's motor speed [rad/s]."""
        return self.motor_speed[np.arange(self.n), self.channel]

    @property
    def current(self) -> np.ndarray:
        """The active couple's torque-generating current [A]."""
        return self.motor_current[np.arange(self.n), self.channel]

    @property
    def name(self) -> str:
        return os.path.basename(self.path)


def _fail(path: str, what: str) -> UsageError:
    return UsageError(f'{path}: {what}')


def metadata(path: str, topics: dict) -> dict:
    """The experiment's JSON from /eha/experiment, checked (one line on any mistake)."""
    if META not in topics or topics[META]['count'] == 0:
        raise _fail(path, f'no {META} message: not a recording of an identification '
                          f'experiment (expected one of {", ".join(EXPERIMENTS)})')
    (_, msg), *_ = R.read(path, [META])[META]
    try:
        meta = json.loads(msg.data)
    except (ValueError, TypeError) as err:
        raise _fail(path, f'{META} is not JSON: {err}') from None
    if not isinstance(meta, dict):
        raise _fail(path, f'{META}: expected a JSON object, got {type(meta).__name__}')
    exp = meta.get('experiment')
    if exp not in EXPERIMENTS:
        raise _fail(path, f'{META} names experiment {exp!r}: expected one of '
                          f'{", ".join(EXPERIMENTS)}')
    if meta.get('version') != VERSION:
        raise _fail(path, f'{META} version {meta.get("version")!r}: expected {VERSION}')
    if not isinstance(meta.get('params', {}), dict):
        raise _fail(path, f'{META} params: expected a JSON object')
    return meta


def _stamps(cols: dict) -> np.ndarray:
    return cols['header.stamp.sec'] + 1e-9 * cols['header.stamp.nanosec']


def _by_time(t_state: np.ndarray, records: list, name: str, before: float) -> np.ndarray:
    """A stamped topic's value held at each state time (``before`` until its first one)."""
    stamp = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for _, m in records])
    value = np.array([float(getattr(m, name)) for _, m in records])
    order = np.argsort(stamp, kind='stable')
    stamp, value = stamp[order], value[order]
    i = np.searchsorted(stamp, t_state + STAMP_SLACK, side='right') - 1
    return np.where(i >= 0, value[np.clip(i, 0, None)], before)


def load(path: str, Ts: float) -> Recording:
    """Read and check one recording; ``Ts`` the plant model's tick [s]."""
    topics = R.summary(path)             # a truncated or foreign file fails here, one line
    meta = metadata(path, topics)
    exp = meta['experiment']
    for topic in NEEDS[exp]:
        if topics.get(topic, {}).get('count', 0) == 0:
            raise _fail(path, f'the {exp} experiment needs {topic}, which the recording '
                              f'does not hold')
    for topic, info in topics.items():
        if topic in TYPES and info['count'] and info['type'] != TYPES[topic]:
            raise _fail(path, f'{topic} has type {info["type"]}: expected {TYPES[topic]}')
    wanted = [t for t in (STATE, COMMAND, REFERENCE, LOAD) if t in topics]
    msgs = R.read(path, wanted)
    s = R.columns(msgs[STATE], _STATE_FIELDS)
    seq = s['seq'].astype(np.int64)
    full = np.arange(seq[0], seq[-1] + 1)
    if len(full) * Ts < MIN_DURATION:
        raise _fail(path, f'{len(full) * Ts:.2f} s of states: expected at least '
                          f'{MIN_DURATION:g} s')
    missing = 1.0 - len(seq) / len(full)
    if missing > MAX_MISSING:
        raise _fail(path, f'{missing * 100:.1f} % of the ticks have no /eha/state: expected at '
                          f'most {MAX_MISSING * 100:g} %')
    t = _stamps(s)
    period = np.median(np.diff(t) / np.diff(seq))
    if not abs(period - Ts) <= 0.01 * Ts:
        raise _fail(path, f'states every {period * 1e3:.3g} ms: the plant model ticks every '
                          f'{Ts * 1e3:g} ms')
    at = np.searchsorted(full, seq)

    def grid(values):
        return np.interp(full, seq, np.asarray(values, float))

    recorded = np.zeros(len(full), bool)
    recorded[at] = True
    rec = Recording(
        path=path, experiment=exp, plant_side=str(meta.get('plant_side', '')),
        params=meta.get('params', {}), Ts=Ts, seq=full, t=grid(t), position=grid(s['position']),
        motor_speed=np.column_stack([grid(s['motor_speed[0]']), grid(s['motor_speed[1]'])]),
        motor_current=np.column_stack([grid(s['motor_current[0]']),
                                       grid(s['motor_current[1]'])]),
        pressure_a=grid(s['pressure_a']), pressure_b=grid(s['pressure_b']),
        channel=np.round(grid(s['active_channel'])).astype(int), recorded=recorded)
    if COMMAND in msgs:
        c = R.columns(msgs[COMMAND], ['motor_speed_ref'])
        cmd = np.full(len(full), np.nan)
        inside = (c['seq'] >= full[0]) & (c['seq'] <= full[-1])
        cmd[c['seq'][inside].astype(np.int64) - full[0]] = c['motor_speed_ref'][inside]
        rec.command = _hold(cmd)
    if REFERENCE in msgs:
        first = float(msgs[REFERENCE][0][1].position)
        rec.reference = _by_time(rec.t, msgs[REFERENCE], 'position', first)
    rec.load = _by_time(rec.t, msgs[LOAD], 'force', 0.0) if LOAD in msgs else \
        np.zeros(len(full))
    if not (np.all(np.isfinite(rec.position)) and np.all(np.isfinite(rec.motor_speed))
            and np.all(np.isfinite(rec.pressure_a)) and np.all(np.isfinite(rec.pressure_b))):
        raise _fail(path, 'non-finite values in /eha/state')
    return rec


def _hold(x: np.ndarray) -> np.ndarray:
    """Each NaN replaced by the last value before it (0 before the first)."""
    idx = np.where(np.isfinite(x), np.arange(len(x)), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, x[np.clip(idx, 0, None)], 0.0)


def load_all(paths, Ts: float, log=print) -> dict:
    """{experiment: Recording}: one recording of each of EXPERIMENTS, any order."""
    if not paths:
        raise UsageError(f'no recordings given: expected one each of {", ".join(EXPERIMENTS)}')
    seen: dict[str, str] = {}
    real = {}
    for path in paths:
        key = os.path.realpath(path)
        if key in real:
            raise UsageError(f'{path}: given twice')
        real[key] = path
        if not os.path.isfile(path):
            raise _fail(path, 'no such recording')
        exp = metadata(path, R.summary(path))['experiment']
        if exp in seen:
            raise _fail(path, f'a second recording of the {exp} experiment (the first: '
                              f'{seen[exp]}): expected one each')
        seen[exp] = path
    missing = [e for e in EXPERIMENTS if e not in seen]
    if missing:
        raise UsageError(f'no recording of the {" and ".join(missing)} experiment'
                         f'{"s" if len(missing) > 1 else ""} among {", ".join(paths)}: expected '
                         f'one each of {", ".join(EXPERIMENTS)}')
    out = {}
    for exp in EXPERIMENTS:
        out[exp] = load(seen[exp], Ts)
        log(f'identify: {exp}: {seen[exp]} ({out[exp].n * Ts:.1f} s, '
            f'{out[exp].plant_side or "?"} side)')
    return out
