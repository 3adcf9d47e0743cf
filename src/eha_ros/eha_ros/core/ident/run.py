"""One identification experiment against a stream of plant ticks: what to send for each tick
(the reference and load of a closed-loop plan, or the drive plan's motor-speed command), when
it is done, and why it stopped early. No I/O: the experiment node feeds it the loop's topics.

It stops (and from then on commands zero speed, a held reference, no load) on
- the loop's safe state (core.loop.safe_state): the switch manager in FAILED_SAFE, or an
  estimate whose consistency verdict calls for it (a position-sensor fault);
- the measured position beyond the stroke minus the margin (the drive plan's guard: nothing
  else watches the piston while no position controller runs);
- a closed loop that lost track: |reference - estimate| above ``abort_error`` for
  ``abort_ticks`` ticks in a row (the sweep's guard, core.sweep.session.TrackingGuard);
- the plant side no longer applying commands (eha/plant_state not ACTIVE: a drive disarmed).
"""
from __future__ import annotations

from ..loop import safe_state as SAFE
from ..redundancy.state_machine import FAILED_SAFE
from ..sweep.session import TrackingGuard
from .experiments import Limits, Plan


class ExperimentRun:
    """``plan`` run from plant tick ``seq0`` (:meth:`start`) on."""

    def __init__(self, plan: Plan, limits: Limits, abort_error: float, abort_ticks: int):
        self.plan = plan
        self.limits = limits
        self.guard = TrackingGuard(abort_error, abort_ticks)
        self.seq0: int | None = None
        self.stopped = ''                  # why it stopped early ('' while it may go on)
        self.part = -1                     # index of the plan part last reported

    # ---- timing
    def start(self, seq0: int) -> None:
        """The plan's tick 0 is plant tick ``seq0``."""
        self.seq0 = int(seq0)

    def index(self, seq: int) -> int | None:
        """The plan's tick of plant tick ``seq`` (None outside the plan or once stopped)."""
        if self.seq0 is None or self.stopped:
            return None
        i = seq - self.seq0
        return i if 0 <= i < self.plan.n_ticks else None

    def done(self, seq: int) -> bool:
        """The plan has run to its end by plant tick ``seq``."""
        return self.seq0 is not None and seq - self.seq0 >= self.plan.n_ticks

    # ---- what to send
    def reference_for(self, seq: int) -> float:
        """Position reference of plant tick ``seq`` (0, mid-stroke, outside the plan)."""
        i = self.index(seq)
        return 0.0 if i is None or self.plan.reference is None else float(self.plan.reference[i])

    def load_for(self, seq: int) -> float:
        """External load of plant tick ``seq`` (0 outside the plan)."""
        i = self.index(seq)
        return 0.0 if i is None or self.plan.load is None else float(self.plan.load[i])

    def command_for(self, seq: int, position: float) -> float:
        """Drive plan: the motor-speed command of tick ``seq``, the plan's speed sine
        minus the slow position loop's ``position_gain x`` (x measured, centre 0), at most
        omega_max; zero once stopped."""
        if self.stopped:
            return 0.0
        i = self.index(seq)
        ff = 0.0 if i is None or self.plan.speed is None else float(self.plan.speed[i])
        u = ff - self.plan.position_gain * position
        return max(-self.limits.omega_max, min(self.limits.omega_max, u))

    # ---- guards: each returns the reason when it stops the run (once), else ''
    def stop(self, why: str) -> str:
        if self.stopped or not why:
            return ''
        self.stopped = why
        return why

    def on_state(self, seq: int, position: float) -> str:
        if abs(position) > self.limits.reach:
            return self.stop(f'measured position {position * 1e3:+.2f} mm at tick {seq}: beyond '
                             f'+-{self.limits.reach * 1e3:g} mm (the stroke minus its margin)')
        return ''

    def on_estimate(self, seq: int, position: float, consistency: int) -> str:
        if SAFE.position_fault(consistency):
            return self.stop(f'safe state: {SAFE.manager_reason(consistency)}')
        i = self.index(seq)
        if i is None or self.plan.reference is None:
            return ''
        return self.stop(self.guard.update(self.reference_for(seq), position, i))

    def on_manager(self, state: str, reason: str) -> str:
        if state == FAILED_SAFE:
            return self.stop(f'safe state: switch manager {FAILED_SAFE} ({reason})')
        return ''

    def on_plant_active(self, active: bool) -> str:
        if not active and self.seq0 is not None:
            return self.stop('the plant side stopped applying commands (eha/plant_state not '
                             'ACTIVE: disarmed or deactivated)')
        return ''

    # ---- progress
    def new_part(self, seq: int) -> dict | None:
        """The plan part tick ``seq`` entered, once per part (for a progress line)."""
        i = self.index(seq)
        if i is None:
            return None
        for n, part in enumerate(self.plan.parts):
            if n > self.part and part['start'] <= i < part['stop']:
                self.part = n
                return part
        return None

    def describe(self, part: dict) -> str:
        """One progress line of a plan part."""
        n, total = self.plan.parts.index(part) + 1, len(self.plan.parts)
        t = part['start'] * self.plan.Ts
        what = {'sine': lambda: f'{part["freq_hz"]:g} Hz sine',
                'hold': lambda: f'load {part["load_n"]:g} N held',
                'step': lambda: f'step of {part["amplitude"] * 1e3:+g} mm'}[part['name']]()
        return (f'experiment {self.plan.kind}: part {n}/{total}: {what} '
                f'(at {t:.1f} of {self.plan.duration_s:.1f} s)')
