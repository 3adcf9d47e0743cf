"""Loop supervisor: the 1 kHz loop state(k) -> estimate(k) -> command(k) watched as a whole.

Runs in the switch manager (it takes all three streams and owns the safe state, so the
watch costs no extra message). The first condition met trips it, latched until
:meth:`LoopSupervisor.reset`; the node then enters the safe state (core.loop.safe_state: hold,
drives off, valves closed), logs one line and reports ERROR on /diagnostics.

- stalled: a stream silent for ``stall_timeout`` seconds of wall time, counted only while
  the supervisor itself is awake (a process-wide pause is not an upstream stall). The first
  silent link names the node: no state (plant side), states but no estimate (estimator),
  estimates but no command (controller). Before the first command: ``start_timeout``; the
  stall and unanswered checks start ``start_grace`` after it (the start-up transient).
- unanswered (real time only): more than ``max_unanswered`` of the ticks of the last
  ``window`` had no command(k) when state(k+1) arrived (the loop cannot hold real time).
- rejected: ``reject_time`` of estimates in a row made without the position measurement,
  which the estimator refused (out of range, non-finite) with no sensor-fault verdict of its
  own (that one has its own safe-state path, core.loop.safe_state).
- limit cycle: within the last ``window``, the speed command at |u| >= ``saturation`` x
  omega_max on ``cycle_share`` of the ticks with ``cycle_reversals`` sign reversals between
  saturated commands (bang-bang oscillation; a step saturates one way, and the sweeps stay
  below a third of the speed limit).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, fields

STALLED, UNANSWERED, REJECTED, LIMIT_CYCLE = 'stalled', 'unanswered', 'rejected', 'limit_cycle'
STREAMS = (('state', 'plant side'), ('estimate', 'estimator'), ('command', 'controller'))


@dataclass
class SupervisorParams:
    """switch.supervisor.* (core.redundancy.params: units, ranges, defaults) + the loop's."""
    Ts: float                       # [s] loop period
    omega_max: float                # [rad/s] speed limit of the drive
    realtime: bool                  # lock-step: no unanswered check, lock-step stall timeout
    stall_timeout: float
    lockstep_stall_timeout: float
    start_timeout: float
    start_grace: float              # switch.node.arm_time: the start-up transient
    window: float
    max_unanswered: float
    reject_time: float
    saturation: float
    cycle_share: float
    cycle_reversals: int

    @classmethod
    def from_params(cls, p: dict, realtime: bool = True) -> 'SupervisorParams':
        s = 'switch.supervisor.'
        return cls(Ts=p['plant.sim.Ts'], omega_max=p['plant.drive.omega_max'],
                   realtime=realtime, start_grace=p['switch.node.arm_time'], **{f.name: p[s + f.name] for f in fields(cls)
                                         if s + f.name in p})


@dataclass
class Trip:
    kind: str           # STALLED, UNANSWERED, REJECTED or LIMIT_CYCLE
    message: str        # one line: what, which node, how long
    t: float            # wall time of the trip [s] (the caller's clock)
    seq: int            # the tick it tripped on: the estimate's or command's seq, the newest
                        # state seq for the wall-clock checks (a starved node's queues lag
                        # apart: a state seq would date an estimate's trip too early)


class LoopSupervisor:
    """Feed it the three streams (and call :meth:`check` on a wall-clock timer); ``trip`` is
    the first condition met, None while the loop is healthy."""

    def __init__(self, p: SupervisorParams):
        self.p = p
        self.n = max(1, int(round(p.window / p.Ts)))
        self.reject_n = max(1, int(round(p.reject_time / p.Ts)))
        self.reset(None)

    def reset(self, now: float | None):
        """Re-arm (after the operator left the safe state): windows cleared, stall watch anew."""
        self.trip: Trip | None = None
        self.last = {name: now for name, _ in STREAMS}   # wall time each stream's seq last advanced
        self.seq = {name: -1 for name, _ in STREAMS}
        self.first_state = None
        self.judged_from = None          # first command + start_grace
        self.watch_since = now           # awake since (see check)
        self.last_check = now
        self.answered = deque()                # per tick: command(k) before state(k+1)
        self.n_answered = 0
        self.sat = deque()                     # per command: -1, 0, +1 (saturated sign)
        self.n_sat = 0                         # saturated commands in self.sat
        self.reversals = deque()               # command seq of each saturated sign reversal
        self.last_sat_sign = 0
        self.rejected_run = 0
        self.max_rejected_run = 0

    # ---- streams ----
    def state(self, seq: int, now: float):
        s = self.seq['state']
        if s >= 0 and seq > s and self.p.realtime and self.seq['command'] >= 0:
            self._answer(self.seq['command'] >= s)   # command(s) in before state(s+1)
            for _ in range(min(int(seq - s - 1), self.n)):
                self._answer(False)                  # states lost on the way
            self._judge_answers(now)
        if seq > s:
            self.seq['state'] = seq
            self.last['state'] = now
        if self.first_state is None:
            self.first_state = now

    def estimate(self, seq: int, rejected: bool, stale: bool, now: float):
        """``rejected``: made without the position measurement, which the estimator refused
        or held back as a suspected jump's (not one it isolated after its own sensor-fault
        verdict: core.loop.safe_state acts on that)."""
        self._progress('estimate', seq, now)
        if stale:                            # no state: the stall check's business
            return
        self.rejected_run = self.rejected_run + 1 if rejected else 0
        self.max_rejected_run = max(self.max_rejected_run, self.rejected_run)
        if self.rejected_run >= self.reject_n:
            self._trip(REJECTED, f'the estimator has taken no position measurement for '
                                 f'{self.rejected_run * self.p.Ts * 1e3:.0f} ms (out of '
                                 f'range, non-finite or held back as a suspected jump), no '
                                 f'sensor-fault verdict', now, seq)

    def command(self, seq: int, speed: float, now: float):
        self._progress('command', seq, now)
        limit = self.p.saturation * self.p.omega_max
        sign = (speed >= limit) - (speed <= -limit)
        self.sat.append(sign)
        self.n_sat += sign != 0
        if len(self.sat) > self.n:
            self.n_sat -= self.sat.popleft() != 0
        if sign:
            if self.last_sat_sign and sign != self.last_sat_sign:
                self.reversals.append(seq)
            self.last_sat_sign = sign
        while self.reversals and self.reversals[0] <= seq - self.n:
            self.reversals.popleft()
        if len(self.reversals) >= self.p.cycle_reversals:
            share = self.saturated_share
            if share >= self.p.cycle_share:
                self._trip(LIMIT_CYCLE, f'saturation limit cycle: speed command at the '
                                        f'{self.p.omega_max:.0f} rad/s limit on {100 * share:.0f} '
                                        f'% of the last {self.p.window:g} s with '
                                        f'{len(self.reversals)} reversals', now, seq)

    def check(self, now: float):
        """Wall-clock check of the stall conditions (call it every few tens of ms)."""
        gap_limit = 0.5 * self.stall_timeout
        if self.last_check is None or now - self.last_check > gap_limit:
            self.watch_since = now       # we were not watching: count silence from now
        self.last_check = now
        if self.trip is not None or self.first_state is None:
            return
        if self.seq['command'] < 0 or now < self.judged_from:
            if self.seq['command'] < 0 and \
                    now - max(self.first_state, self.watch_since) > self.p.start_timeout:
                silent = next(node for name, node in STREAMS[1:] if self.seq[name] < 0)
                self._trip(STALLED, f'{silent}: no answer {self.p.start_timeout:g} s after '
                                    f'the first state (not started, or stopped)', now)
            return
        stalled = [name for name, _ in STREAMS
                   if now - max(self.last[name] or now, self.watch_since, self.judged_from)
                   > self.stall_timeout]
        if stalled:
            # the culprit: the first silent link behind its upstream (lock-step: everything
            # waits for it; real time: a link one tick behind but not silent is only busy),
            # else the first silent stream (the plant side when the states stopped)
            name = stalled[0]
            for (up, _), (down, _) in zip(STREAMS, STREAMS[1:]):
                if down in stalled and self.seq[down] < self.seq[up]:
                    name = down
                    break
            node = dict(STREAMS)[name]
            silent_s = now - (self.last[name] or self.judged_from)
            self._trip(STALLED, f'{node} stalled: no new {name} for '
                                f'{silent_s:.2f} s (newest seq {self.seq[name]}, '
                                f'state seq {self.seq["state"]})', now)

    def _progress(self, name: str, seq: int, now: float):
        """A stream is alive while its seq advances (a lock-step plant re-publishes state(k)
        while it waits, a stale estimator predicts with the old seq)."""
        if seq > self.seq[name]:
            if name == 'command' and self.seq[name] < 0:
                self.judged_from = now + self.p.start_grace
            self.seq[name] = seq
            self.last[name] = now

    # ---- verdicts ----
    @property
    def stall_timeout(self) -> float:
        return self.p.stall_timeout if self.p.realtime else self.p.lockstep_stall_timeout

    def _answer(self, ok: bool):
        self.answered.append(ok)
        self.n_answered += ok
        if len(self.answered) > self.n:
            self.n_answered -= self.answered.popleft()

    @property
    def unanswered_share(self) -> float:
        return 1.0 - self.n_answered / len(self.answered) if self.answered else 0.0

    @property
    def saturated_share(self) -> float:
        return self.n_sat / self.n

    def _judge_answers(self, now: float):
        if len(self.answered) < self.n or now < self.judged_from or \
                now - self.last['command'] > 5 * self.p.Ts:
            return           # commands stopped (for now): the stall check names the node
        if self.unanswered_share > self.p.max_unanswered:
            self._trip(UNANSWERED, f'the loop cannot hold real time: '
                                   f'{100 * self.unanswered_share:.0f} % of the ticks of the last '
                                   f'{self.p.window:g} s unanswered (command(k) after '
                                   f'state(k+1))', now)

    def _trip(self, kind: str, message: str, now: float, seq: int | None = None):
        if self.trip is None:
            self.trip = Trip(kind, message, now, self.seq['state'] if seq is None else seq)

    def values(self) -> dict:
        """For /diagnostics."""
        return {'tripped': self.trip.kind if self.trip else '',
                'unanswered_share': round(self.unanswered_share, 4),
                'saturated_share': round(self.saturated_share, 4),
                'saturated_reversals': len(self.reversals),
                'rejected_run_max_s': self.max_rejected_run * self.p.Ts,
                'stall_timeout_s': self.stall_timeout}
