"""Which reference goes with which estimate: a tick-locked reference source (the sweep, seq
k > 0) is applied when the estimate of tick k is handled, so reference timing does not depend on
DDS delivery order; in lock-step an estimate newer than the newest such reference waits for it
(at most ``wait`` s of wall time, counted). seq 0: untimed, applied at once; it ends the
tick-locked source (the sweep sends it when done): its queued references are dropped and no
estimate waits any more until the next seq > 0. No I/O; time passed in."""
from __future__ import annotations

from collections import deque

from ..stats import Counters


class TickSync:
    """The controller node's reference/estimate pairing (see the module text)."""

    def __init__(self, lockstep: bool, wait: float, depth: int = 2000,
                 counters: Counters | None = None):
        self.c = counters if counters is not None else Counters()
        self.lockstep = lockstep
        self.wait = wait
        self.pending = deque(maxlen=depth)   # (seq, position) waiting for estimate seq
        self.held = deque()                  # (arrival, estimate) waiting for their reference
        self.ref_seq = 0                     # newest tick-locked reference seen

    def reference(self, seq: int, position: float, last_seq: int) -> bool:
        """A reference arrived (``last_seq``: the newest estimate handled). True: apply it now;
        False: queued for its tick (held estimates may go then: :meth:`pop_ready`)."""
        if seq <= 0:                         # untimed: the tick-locked source (if any) ended
            self.ref_seq = 0
            self.pending.clear()
            return True
        self.ref_seq = max(self.ref_seq, seq)
        if seq > last_seq:
            self.pending.append((seq, position))
            return False
        return True

    def hold(self, estimate, now: float) -> bool:
        """An estimate (with its ``seq``) arrived: True when it has to wait for its reference."""
        if self.lockstep and self.ref_seq > 0 and estimate.seq > self.ref_seq:
            self.held.append((now, estimate))
            return True
        return False

    def pop_ready(self, now: float, force: bool = False):
        """The oldest held estimate if it may go now (its reference came, the source ended,
        it waited longer than ``wait``: counted as reference_wait_timeouts, or ``force``),
        else None."""
        if not self.held:
            return None
        arrived, estimate = self.held[0]
        late = 0 < self.ref_seq < estimate.seq
        if not (force or not late or now - arrived > self.wait):
            return None
        if late and not force:
            self.c.bump('reference_wait_timeouts')
        return self.held.popleft()[1]

    def due(self, seq: int) -> list:
        """The queued references of ticks up to ``seq``, in order (to apply before it)."""
        out = []
        while self.pending and self.pending[0][0] <= seq:
            out.append(self.pending.popleft()[1])
        return out
