"""Position-sensor fault detector on the filter's innovations (thesis 4.1: the innovation and
NIS of the Kalman filter as a fault-detection signal).

- jump: |innovation| / sqrt(S) above ``jump_threshold`` for ``jump_debounce`` samples, and
  (with ``jump_step`` > 0) the run began with a step of the position innovation of at least
  ``jump_step`` within one sample while the pressure innovations stayed below
  ``jump_pressure_veto`` (normalised): a sensor jump moves the reading at once and leaves the
  pressure sensors alone; the piston itself can move that fast only by compressing the oil
  (a 5 kN load step moves it 0.22 mm within one tick: V_d/(beta A_p) times 19 bar), which
  the pressure sensors see. A large innovation without that step is left to the CUSUM
  (drift / model mismatch), not called a sensor jump;
- stuck: the reading of a noisy sensor unchanged (within ``stuck_tolerance``) for
  ``stuck_samples`` samples; with the bench's ~10 um white noise and 1 um resolution two equal
  consecutive readings happen a few % of the time, 25 in a row practically never. (A
  noise-free sensor at standstill would look stuck: set stuck_samples high there.)
- drift: two-sided CUSUM of the normalised innovation r with allowance k and alarm level h,
  g+ = max(0, g+ + r - k), g- = max(0, g- - r - k), over h for ``drift_debounce`` samples.
A detected fault stays reported for ``hold_time`` after its condition clears; when several are
present the order is jump, stuck, drift.
"""
from __future__ import annotations

import math

from numba import njit

NONE, JUMP, STUCK, DRIFT = 0, 1, 2, 3
NAMES = {NONE: 'none', JUMP: 'jump', STUCK: 'stuck', DRIFT: 'drift'}


@njit(cache=True)
def pressure_z(y, S, m) -> float:
    """Largest |y_i| / sqrt(S_ii) of the pressure rows i = 1 .. m-1 of an innovation."""
    out = 0.0
    for i in range(1, m):
        v = abs(y[i]) / math.sqrt(S[i, i]) if S[i, i] > 0.0 else 0.0
        if v > out:
            out = v
    return out


class FaultDetector:
    """Feed one sample per tick with :meth:`update`; read the code from its return value."""

    def __init__(self, Ts: float, jump_threshold: float = 8.0, jump_debounce: int = 3,
                 stuck_samples: int = 25, stuck_tolerance: float = 0.0, drift_k: float = 0.5,
                 drift_h: float = 150.0, drift_debounce: int = 5, hold_time: float = 0.5,
                 jump_step: float = 0.0, jump_pressure_veto: float = 1e300):
        self.Ts = Ts
        self.jump_threshold, self.jump_debounce = jump_threshold, jump_debounce
        self.stuck_samples, self.stuck_tolerance = stuck_samples, stuck_tolerance
        self.drift_k, self.drift_h, self.drift_debounce = drift_k, drift_h, drift_debounce
        self.hold_ticks = int(round(hold_time / Ts))
        self.jump_step, self.jump_pressure_veto = jump_step, jump_pressure_veto
        self.reset()

    @classmethod
    def from_params(cls, p: dict, Ts: float) -> 'FaultDetector':
        f = 'estimator.fault.'
        return cls(Ts, p[f + 'jump_threshold'], p[f + 'jump_debounce'], p[f + 'stuck_samples'],
                   p[f + 'stuck_tolerance'], p[f + 'drift_k'], p[f + 'drift_h'],
                   p[f + 'drift_debounce'], p[f + 'hold_time'], p[f + 'jump_step'],
                   p[f + 'jump_pressure_veto'])

    def reset(self):
        self.n_jump = self.n_same = self.n_drift = 0
        self.g_pos = self.g_neg = 0.0
        self.z_prev = None
        self.y_prev = 0.0
        self.stepped = False       # the current run of large innovations began with a step
        self.hold = {JUMP: 0, STUCK: 0, DRIFT: 0}
        self.detections = {JUMP: 0, STUCK: 0, DRIFT: 0}
        self.code = NONE

    def update(self, z: float, innovation: float, S: float, pz: float = 0.0) -> int:
        """One position sample z (m) with its innovation (m) and innovation variance (m^2);
        pz: the largest normalised pressure innovation of the same update (0: none)."""
        r = innovation / math.sqrt(S) if S > 0.0 else 0.0
        self.n_jump = self.n_jump + 1 if abs(r) > self.jump_threshold else 0
        # a jump starts with a one-sample innovation step, and the pressures stay quiet
        # through the debounce (a load step's pressure innovation can come a sample late)
        if self.n_jump == 1:
            self.stepped = abs(innovation - self.y_prev) >= self.jump_step
        if pz >= self.jump_pressure_veto:
            self.stepped = False
        self.y_prev = innovation
        same = self.z_prev is not None and abs(z - self.z_prev) <= self.stuck_tolerance
        self.n_same = self.n_same + 1 if same else 0
        self.z_prev = z
        self.g_pos = max(0.0, self.g_pos + r - self.drift_k)
        self.g_neg = max(0.0, self.g_neg - r - self.drift_k)
        self.n_drift = self.n_drift + 1 if max(self.g_pos, self.g_neg) > self.drift_h else 0
        # a jump moves the reading; identical readings behind a big innovation are a stuck
        # sensor (reported when stuck_samples is reached), not a jump
        now = {JUMP: (self.n_jump >= self.jump_debounce and self.n_same < self.jump_debounce
                      and self.stepped),
               STUCK: self.n_same + 1 >= self.stuck_samples,
               DRIFT: self.n_drift >= self.drift_debounce and self.n_same < self.jump_debounce}
        if now[JUMP]:              # a jump is not a drift: restart the CUSUM behind it
            self.g_pos = self.g_neg = 0.0
            self.n_drift = 0
            now[DRIFT] = False
        for code, active in now.items():
            if active:
                if self.hold[code] == 0:
                    self.detections[code] += 1
                self.hold[code] = self.hold_ticks + 1
            elif self.hold[code] > 0:
                self.hold[code] -= 1
        self.code = next((c for c in (JUMP, STUCK, DRIFT) if self.hold[c] > 0), NONE)
        return self.code

    def tick_without_sample(self) -> int:
        """A tick with no usable position (rejected or stale): holds count down."""
        for code in self.hold:
            if self.hold[code] > 0:
                self.hold[code] -= 1
        self.code = next((c for c in (JUMP, STUCK, DRIFT) if self.hold[c] > 0), NONE)
        return self.code
