"""The identification experiments of thesis section 3.6 as plans: per-tick signals and what
they are, inside the actuator's limits (issue 43).

- drive: a stepped sine of the motor-speed reference, sent straight to the drive on
  /eha/command (no position controller), plus a slow proportional loop on the measured
  position that keeps the piston in its stroke (sec. 3.6.1, Fig. 3.36: 1000 rpm, 1-15 Hz);
- friction: closed-loop position sines of rising frequency, so of rising piston speed, no load
  (sec. 3.6.3, Fig. 3.40-3.42);
- leakage: the reference held at 0 against constant loads of several levels, each held until
  the motor speed that holds it has settled (sec. 3.6.3, Fig. 3.44);
- validation: a closed-loop step and a sine (sec. 3.6.4, Fig. 3.45).

Every plan is checked before anything moves against the stroke minus a margin, the drive's
speed limit (plant.drive.omega_max) and its current limit (the current-limited acceleration,
core.controller.antiwindup.current_accel); a plan beyond them is a UsageError naming the
parameter. The signals are core.sweep.signals' (each written once there).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..config.cli import UsageError
from ..controller.antiwindup import current_accel
from ..sweep.signals import Staircase, Step, SteppedSine, check_limits

KINDS = ('drive', 'friction', 'leakage', 'validation')
VERSION = 1                 # of the /eha/experiment message
PREFIX = 'experiment.'
SPEED_SHARE = 0.8           # peak motor speed: at most this share of omega_max (the loop
                            # supervisor takes >= 0.95 for a saturated command)
ACCEL_SHARE = 0.5           # peak motor acceleration: at most this share of the current-limited
                            # one (the rest of the current for friction, load and the speed
                            # loop's error)
CURRENT_SHARE = 0.5         # the current that holds a load: at most this share of I_max
LOAD_SHARE = 0.5            # a held load: at most this share of A_p x the relief's crack pressure
POSITION_LOOP_RATIO = 5.0   # drive: the position loop's bandwidth at most the lowest sine / this


@dataclass(frozen=True)
class Limits:
    """What every plan must stay inside, from the plant parameters (plant.*)."""
    Ts: float                   # [s] tick
    stroke: float               # [m] end stop to end stop
    margin: float               # [m] kept from the end stops
    omega_max: float            # [rad/s] the drive's speed limit
    accel_max: float            # [rad/s^2] the motor's current-limited acceleration
    ratio: float                # [rad/m] motor angle per piston travel, A_p / D_p
    hold_force: float           # [N] the largest load held: relief and current bound

    @classmethod
    def from_params(cls, p: dict) -> 'Limits':
        P = 'plant.'
        ratio = p[P + 'cylinder.A_p'] / p[P + 'pump.D_p']
        margin = p[PREFIX + 'stroke_margin']
        force_current = CURRENT_SHARE * p[P + 'drive.I_max'] * p[P + 'motor.k_T'] * ratio
        force_relief = LOAD_SHARE * p[P + 'cylinder.A_p'] * p[P + 'valves.relief_crack']
        return cls(Ts=p[P + 'sim.Ts'], stroke=p[P + 'cylinder.stroke'], margin=margin,
                   omega_max=p[P + 'drive.omega_max'],
                   accel_max=current_accel(p[P + 'motor.k_T'], p[P + 'drive.I_max'],
                                           p[P + 'motor.J_eq']),
                   ratio=ratio, hold_force=min(force_current, force_relief))

    @property
    def reach(self) -> float:
        """[m] |x| allowed: half the stroke minus the margin."""
        return self.stroke / 2 - self.margin


@dataclass
class Plan:
    """One experiment, tick by tick from its start. Closed-loop plans give ``reference``
    (and ``load``); the drive plan gives ``speed``, the feed-forward of the motor-speed
    command, to which the node adds ``-position_gain * x`` (x: the measured position)."""
    kind: str
    Ts: float
    n_ticks: int
    summary: str                                # one line: what it does
    reference: np.ndarray | None = None         # [m] position reference per tick
    load: np.ndarray | None = None              # [N] external load per tick (F_L, eq. 3.32)
    speed: np.ndarray | None = None             # [rad/s] motor-speed reference per tick
    position_gain: float = 0.0                  # [rad/s per m] drive: slow position loop
    parts: list = field(default_factory=list)   # what each stretch of ticks is
    params: dict = field(default_factory=dict)  # the experiment's own parameters

    @property
    def duration_s(self) -> float:
        return self.n_ticks * self.Ts

    def message(self, plant_side: str, start_seq: int) -> dict:
        """The /eha/experiment message of a run whose tick 0 is plant tick ``start_seq``
        (parts' start/stop are ticks from there)."""
        params = dict(self.params, Ts=self.Ts, n_ticks=self.n_ticks, start_seq=int(start_seq),
                      parts=self.parts)
        if self.kind == 'drive':
            params['position_gain'] = self.position_gain
        return {'experiment': self.kind, 'version': VERSION, 'plant_side': plant_side,
                'params': params}


def own_params(p: dict, kind: str) -> dict:
    """experiment.<kind>.* without the prefix (the /eha/experiment message's params)."""
    pre = f'{PREFIX}{kind}.'
    return {k[len(pre):]: v for k, v in p.items() if k.startswith(pre)}


def sine_parts(sig: SteppedSine, offset: int = 0) -> list:
    return [{'name': 'sine', 'freq_hz': s.freq_hz, 'amplitude': s.amplitude,
             'start': offset + s.start, 'stop': offset + s.stop} for s in sig.segments]


def _name(kind: str, key: str) -> str:
    return f'{PREFIX}{kind}.{key}'


def check_position_sines(kind: str, freqs, amplitude: float, L: Limits) -> None:
    """Closed-loop position sines A sin(2 pi f t): inside the stroke, at most Nyquist/10, and a
    motor speed (A 2 pi f A_p/D_p) and acceleration (A (2 pi f)^2 A_p/D_p) within their
    shares of the drive's limits."""
    f = max(freqs)
    try:
        check_limits(f, amplitude, 0.0, L.stroke, L.Ts, L.margin)
    except UsageError as err:
        raise UsageError(f'{PREFIX}{kind}: {err}') from None
    w = 2 * math.pi * f
    speed, accel = amplitude * w * L.ratio, amplitude * w * w * L.ratio
    where = f'{_name(kind, "amplitude")} {amplitude * 1e3:g} mm at {f:g} Hz'
    if speed > SPEED_SHARE * L.omega_max:
        raise UsageError(f'{where} needs {speed:.0f} rad/s of motor speed: beyond '
                         f'{SPEED_SHARE:.0%} of plant.drive.omega_max ({L.omega_max:.0f} rad/s)')
    if accel > ACCEL_SHARE * L.accel_max:
        raise UsageError(f'{where} accelerates the motor at {accel:.0f} rad/s^2: beyond '
                         f'{ACCEL_SHARE:.0%} of its current-limited {L.accel_max:.0f} rad/s^2 '
                         f'(k_T I_max / J_eq)')


def check_drive(freqs, amplitude: float, bandwidth: float, L: Limits) -> None:
    """Speed sines A sin(2 pi f t) from rest with the position loop: the piston travels at most
    2 A / (2 pi f_min A_p/D_p) (one half period of the lowest sine), which must stay inside
    the stroke; the loop adds at most 2 A f_b / f_min of speed; the peak acceleration
    A 2 pi f_max within its share of the current-limited one; the loop well below the
    lowest sine."""
    lo, hi = min(freqs), max(freqs)
    if hi > 0.05 / L.Ts:
        raise UsageError(f'{_name("drive", "freqs")}: {hi:g} Hz is above Nyquist/10 = '
                         f'{0.05 / L.Ts:g} Hz')
    if bandwidth > lo / POSITION_LOOP_RATIO:
        raise UsageError(f'{_name("drive", "position_bandwidth")} {bandwidth:g} Hz: expected at '
                         f'most {lo / POSITION_LOOP_RATIO:g} Hz (the lowest sine {lo:g} Hz / '
                         f'{POSITION_LOOP_RATIO:g}: the loop must not follow the sweep)')
    travel = 2 * amplitude / (2 * math.pi * lo * L.ratio)
    where = f'{_name("drive", "amplitude")} {amplitude:g} rad/s'
    if travel > L.reach:
        raise UsageError(f'{where} at {lo:g} Hz moves the piston {travel * 1e3:.1f} mm: beyond '
                         f'the stroke limit of +-{L.reach * 1e3:g} mm (stroke minus '
                         f'{L.margin * 1e3:g} mm margin)')
    speed = amplitude * (1 + 2 * bandwidth / lo)
    if speed > SPEED_SHARE * L.omega_max:
        raise UsageError(f'{where} (+ the position loop: {speed:.0f} rad/s): beyond '
                         f'{SPEED_SHARE:.0%} of plant.drive.omega_max ({L.omega_max:.0f} rad/s)')
    accel = amplitude * 2 * math.pi * hi
    if accel > ACCEL_SHARE * L.accel_max:
        raise UsageError(f'{where} at {hi:g} Hz accelerates the motor at {accel:.0f} rad/s^2: '
                         f'beyond {ACCEL_SHARE:.0%} of its current-limited {L.accel_max:.0f} '
                         f'rad/s^2 (k_T I_max / J_eq)')


def drive(p: dict, L: Limits) -> Plan:
    k = 'drive'
    freqs, amp = tuple(p[_name(k, 'freqs')]), p[_name(k, 'amplitude')]
    bandwidth = p[_name(k, 'position_bandwidth')]
    check_drive(freqs, amp, bandwidth, L)
    sig = SteppedSine(0.0, 0.0, 0.0, p[_name(k, 'periods')], p[_name(k, 'relax')], amp, 0.0,
                      L.Ts, freqs)
    return Plan(k, L.Ts, sig.n_ticks,
                f'motor-speed sines of {amp:g} rad/s ({amp * 30 / math.pi:.0f} rpm) at '
                f'{_list(freqs)} Hz on /eha/command, no position controller (a '
                f'{bandwidth:g} Hz position loop keeps the piston centred)',
                speed=sig.array(), position_gain=2 * math.pi * bandwidth * L.ratio,
                parts=sine_parts(sig), params=own_params(p, k))


def friction(p: dict, L: Limits) -> Plan:
    k = 'friction'
    freqs, amp = tuple(p[_name(k, 'freqs')]), p[_name(k, 'amplitude')]
    check_position_sines(k, freqs, amp, L)
    sig = SteppedSine(0.0, 0.0, 0.0, p[_name(k, 'periods')], p[_name(k, 'relax')], amp, 0.0,
                      L.Ts, freqs)
    top = amp * 2 * math.pi * max(freqs)
    return Plan(k, L.Ts, sig.n_ticks,
                f'closed-loop position sines of {amp * 1e3:g} mm at {_list(freqs)} Hz (piston '
                f'speed up to {top * 1e3:.0f} mm/s), no load', reference=sig.array(),
                parts=sine_parts(sig), params=own_params(p, k))


def leakage(p: dict, L: Limits) -> Plan:
    k = 'leakage'
    loads = tuple(p[_name(k, 'loads')])
    worst = max(abs(f) for f in loads)
    if worst > L.hold_force:
        raise UsageError(f'{_name(k, "loads")}: {worst:g} N: expected at most '
                         f'{L.hold_force:.0f} N ({LOAD_SHARE:.0%} of A_p x the relief valve\'s '
                         f'cracking pressure, or the load {CURRENT_SHARE:.0%} of I_max holds)')
    sig = Staircase(loads, p[_name(k, 'hold')], p[_name(k, 'ramp')], p[_name(k, 'rest')], L.Ts)
    parts = [{'name': 'hold', 'load_n': s.amplitude, 'start': s.start, 'stop': s.stop}
             for s in sig.segments]
    return Plan(k, L.Ts, sig.n_ticks,
                f'reference held at 0 against loads of {_list(loads)} N, each held '
                f'{p[_name(k, "hold")]:g} s', reference=np.zeros(sig.n_ticks),
                load=sig.array(), parts=parts, params=own_params(p, k))


def validation(p: dict, L: Limits) -> Plan:
    k = 'validation'
    step, hold_s, rest_s = (p[_name(k, n)] for n in ('step', 'step_hold', 'rest'))
    f, amp = p[_name(k, 'sine_hz')], p[_name(k, 'sine_amplitude')]
    check_position_sines(k, (f,), amp, L)
    try:
        check_limits(0.0, step, 0.0, L.stroke, L.Ts, L.margin)
    except UsageError as err:
        raise UsageError(f'{_name(k, "step")}: {err}') from None
    up = Step(step, rest_s + hold_s, rest_s, 0.0, L.Ts).array()         # rest, then the step
    back = np.zeros(int(round(hold_s / L.Ts)))                            # back to 0, held
    sig = SteppedSine(0.0, 0.0, 0.0, p[_name(k, 'sine_periods')], rest_s, amp, 0.0, L.Ts, (f,))
    n_up, n_back = len(up), len(back)
    rest = int(round(rest_s / L.Ts))
    parts = [{'name': 'step', 'amplitude': step, 'start': rest, 'stop': n_up},
             {'name': 'step', 'amplitude': -step, 'start': n_up, 'stop': n_up + n_back}]
    parts += sine_parts(sig, n_up + n_back)
    ref = np.concatenate([up, back, sig.array()])
    return Plan(k, L.Ts, len(ref),
                f'closed-loop step of {step * 1e3:g} mm and back, then a {amp * 1e3:g} mm sine '
                f'at {f:g} Hz', reference=ref, parts=parts, params=own_params(p, k))


BUILDERS = {'drive': drive, 'friction': friction, 'leakage': leakage, 'validation': validation}


def build(p: dict, kind: str | None = None) -> Plan:
    """The plan of ``kind`` (default: experiment.kind) from validated parameters (plant.* and
    experiment.*); a plan beyond the actuator's limits is a UsageError (one line)."""
    return BUILDERS[kind or p[PREFIX + 'kind']](p, Limits.from_params(p))


def _list(values) -> str:
    return ', '.join(f'{v:g}' for v in values)
