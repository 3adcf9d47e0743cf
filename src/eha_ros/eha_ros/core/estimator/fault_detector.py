"""Position-sensor fault detector on the filter's innovations (thesis 4.1: the innovation and
NIS of the Kalman filter as a fault-detection signal).

- jump: |innovation| / sqrt(S) above ``JUMP_THRESHOLD`` for ``jump_debounce`` samples, and
  (with ``jump_step`` > 0) the run began with a step of the position innovation away from
  zero of at least ``jump_step`` within one sample, while the pressure innovations stayed
  below ``jump_pressure_veto`` (normalised) and the measured pressure difference moved by
  less than COMPRESSION_SHARE of what compressing the oil by that step takes (2 beta A_p /
  V_d per m, eq. 3.20-3.21 at mid-stroke): a sensor jump moves the reading at once and
  leaves the pressure sensors alone; the piston itself can move that fast only by
  compressing the oil (a 5 kN load step moves it 0.22 mm within one tick: V_d/(beta A_p)
  times 19 bar), which the pressure sensors see, on the run's first sample or the next
  (VETO_SAMPLES). The measured p_D speaks where the innovation cannot: a 10 kN step on a
  beta x0.69 plant (random:200) read p_B below 0 bar gauge on its first sample, which was
  rejected, so that sample had no pressure innovation; p_D had moved by 38 bar on the next
  valid one, where a sensor jump moves it by nothing (the loop's answer reaches the
  pressures a drive delay later). The same run's innovation then fell back from -377 to
  -184 um while still beyond the threshold: that is the filter catching up, not a new
  jump. Later
  samples' pressure innovations are the loop's own answer to the jump (the estimate moved,
  the controller commanded, the pump compressed the oil): a 1 mm bias on Table 4.5 plant 36
  gave -8.0 and -10.6 sigma on p_B at its third and fourth samples, and a veto there left the
  bias undetected as a jump (issue 42, 2 % of the sensor_fault runs once each run drew its own
  noise). A large innovation without that step is left to the CUSUM (drift / model mismatch),
  not called a sensor jump. The samples of a run that began out of quiet innovations, until
  it is a jump (:func:`suspect`), are not taken by the estimator (its isolate stage): under a
  varying load the filter's gain would otherwise follow a jumped reading before the debounce
  decides;
- stuck: the reading of a noisy sensor unchanged (bit for bit) for
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

import numpy as np
from numba import njit

from ..plant.chambers import stiffness as chamber_stiffness
from ..redundancy.health import shaft_pressure
from . import sensor_band

NONE, JUMP, STUCK, DRIFT = 0, 1, 2, 3
VETO_SAMPLES = 2        # a jump's samples whose pressure innovation can veto it (see above)
# share of the p_D that compressing the oil of both chambers by a jump's step takes (nominal
# plant) that the measured p_D must move by on the jump's first samples to veto it: a load
# step moves it by about 0.35-1.4 of that (half when the unloaded chamber sits on its check
# valve and only the loaded one compresses; beta x0.7-1.4 over the family: 38 bar for 0.43 mm
# on the beta x0.69 plant below), a sensor jump by the pressure noise only
COMPRESSION_SHARE = 0.25
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


# knobs until issue 44 that changed no campaign figure at half and twice these values
# (scripts/ablation --vary, random:50, tuning seed 1): the jump's normalised innovation, the
# CUSUM's allowance and debounce
JUMP_THRESHOLD = 8.0
DRIFT_K = 0.5
DRIFT_DEBOUNCE = 5
# a run is suspect (its samples held back: :func:`suspect`) only when it begins after this
# many quiet samples: the position's innovation within the jump threshold and the pressures'
# within the veto. In a load step's transient the innovation dips under the threshold and
# steps away again while the filter catches up (random:200 plant 194, C_eq x14.5, the 10 kN
# step of the Table 3.4 sine: a run 2 samples after a vetoed one); held back, that run became
# a jump and the safe state
QUIET_SAMPLES = 100

# constants (FK_*) and state (FS_*) of one detector: its own two arrays, which the estimator's
# compiled path (core.estimator.stepper) reads and writes in place through slices
(FK_JUMP, FK_JUMP_N, FK_STUCK_N, FK_DRIFT_K, FK_DRIFT_H, FK_DRIFT_N, FK_HOLD, FK_JUMP_STEP,
 FK_JUMP_PVETO,
 FK_PD_PER_M,   # p_D (Pa) per m of piston travel by compressing the oil (0: none)
 # the shaft's torque balance (eq. 3.17, health.shaft_pressure): k_T, b_eq, J_eq, D_p, Ts
 FK_TB_KT, FK_TB_B, FK_TB_J, FK_TB_DP, FK_TS) = range(15)
NFK = 15
(FS_NJUMP, FS_NSAME, FS_NDRIFT, FS_GPOS, FS_GNEG, FS_ZPREV, FS_HAS_ZPREV, FS_YPREV,
 FS_STEPPED, FS_CODE) = range(10)
FS_HOLD = 10            # 3 entries: JUMP, STUCK, DRIFT (ticks the verdict stays reported)
FS_DET = 13             # 3 entries: detections counted
# the last measured p_D (of a sample that had the pressures), the one before a jump's run
# (its reference) and the run's innovation step away from zero; the last valid reading of
# each chamber's sensor (A, B) and those before the run (for a sample with one valid sensor)
FS_PD1, FS_PDREF, FS_STEP = 16, 17, 18
FS_P1, FS_PREF = 19, 21
# the active motor's previous speed (NaN: none), the torque balance's p_D averaged over
# PV_MEAN_TIME (NaN: none since a sample without it) and that average before the run
FS_W1, FS_PVM, FS_PVREF = 23, 24, 25
FS_SUSPECT = 26         # samples the estimator held back as suspect (:func:`suspect`; isolate)
# samples since the last loud one (before this one: the position's or a pressure's innovation
# beyond its jump threshold or veto), and whether the current run began after QUIET_SAMPLES
# of them (only such a run is suspect)
FS_SINCE, FS_QUIET = 27, 28
NFS = 29
CODES = (JUMP, STUCK, DRIFT)
# [s] the torque balance's p_D is averaged over this (first order) for the reference of a
# jump's run: from one tick to the next it swings by about 20 bar rms (Table 4.5 under the
# Table 3.4 sine, mostly at 160 Hz: the drive's current and the speed's difference over one
# tick), as much as a 10 kN step moves it on a soft plant. A 10 ms mean passes 1/10 of that
# ripple and lags the sine's 3 Hz by 0.2 rad
PV_MEAN_TIME = 0.01


@njit(cache=True)
def _max(a, b):
    """Python's max(a, b)."""
    return b if b > a else a


@njit(cache=True)
def _report(k, s, now_jump, now_stuck, now_drift) -> int:
    """Holds: an active condition is reported for FK_HOLD ticks after it clears; the code is
    the first held of jump, stuck, drift."""
    for i in range(3):
        active = now_jump if i == 0 else (now_stuck if i == 1 else now_drift)
        if active:
            if s[FS_HOLD + i] == 0:
                s[FS_DET + i] += 1
            s[FS_HOLD + i] = k[FK_HOLD] + 1
        elif s[FS_HOLD + i] > 0:
            s[FS_HOLD + i] -= 1
    code = NONE
    for i in range(3):
        if s[FS_HOLD + i] > 0:
            code = i + 1          # JUMP, STUCK, DRIFT = 1, 2, 3
            break
    s[FS_CODE] = code
    return code


@njit(cache=True)
def _compressed(k, s, pz, pa, pb, pv) -> bool:
    """The jump veto on one of a run's first VETO_SAMPLES samples (detect's docstring): True
    when the oil compressed."""
    # the oil compressed: the pressures' innovation, or the measured p_D itself moved
    # from its last value before the run; with one sensor valid (the other one failed or
    # out of its range), that chamber's pressure; none valid: no veto by them
    compressed = COMPRESSION_SHARE * k[FK_PD_PER_M] * s[FS_STEP]
    if pa == pa and pb == pb:
        moved = abs(pa - pb - s[FS_PDREF]) >= compressed
    elif pa == pa:
        moved = abs(pa - s[FS_PREF]) >= 0.5 * compressed
    elif pb == pb:
        moved = abs(pb - s[FS_PREF + 1]) >= 0.5 * compressed
    else:
        moved = False
    # a reading missing: the loaded chamber's may be the one, and the other one may sit on
    # its check valve and not move; the shaft feels the load's torque within the tick
    if not (pa == pa and pb == pb) and not moved:
        moved = abs(pv - s[FS_PVREF]) >= compressed        # False when either is NaN
    return pz >= k[FK_JUMP_PVETO] or (compressed > 0.0 and moved)


@njit(cache=True)
def suspect(k, s) -> bool:
    """The last sample began or continues a run that is a jump once it lasts FK_JUMP_N
    samples (its step not vetoed), the run began after QUIET_SAMPLES quiet samples (position
    innovation within FK_JUMP, pressures' within FK_JUMP_PVETO), and it has not lasted longer
    than FK_JUMP_N yet: a jump suspected, or just detected. The estimator does not take such
    a sample (isolate)."""
    return 0 < s[FS_NJUMP] <= k[FK_JUMP_N] and s[FS_STEPPED] > 0.5 and s[FS_QUIET] > 0.5


@njit(cache=True)
def detect(k, s, z, innovation, S, pz, pa, pb, w, i, displacement) -> int:
    """One position sample z (m) with its innovation (m) and innovation variance S (m^2); pz:
    the largest normalised pressure innovation of the same update (0: none); pa, pb: the
    measured chamber pressures of the sample (Pa; NaN: that reading not valid); w, i: the
    active motor's measured speed (rad/s) and current (A) (NaN: not valid); displacement: the
    pump's displacement over its nominal FK_TB_DP as the estimator has learned it (1 + delta,
    :mod:`.adapt`; 1 without that state). Returns the code.

    r = innovation / sqrt(S)
    jump:  |r| > FK_JUMP for FK_JUMP_N samples, the run began with an innovation step
           away from zero, step = sign(innovation) (innovation - previous innovation),
           >= FK_JUMP_STEP, and on its first VETO_SAMPLES samples no pressure innovation
           >= FK_JUMP_PVETO and |pd - the last pd before the run| below
           c = COMPRESSION_SHARE FK_PD_PER_M step (pd = pa - pb); with one valid reading,
           its change from its last valid value before the run below c / 2 (one chamber's
           share of the compression); with either reading not valid, also the torque
           balance's p_D, pv = (k_T i - b_eq w - J_eq dw/dt) / (D_p displacement) (eq. 3.17:
           the pump's torque on the shaft), moved by less than c from its mean over
           PV_MEAN_TIME before the run (not c / 2: the drive's current ripples by several A
           from one tick to the next)
    stuck: z equal to the previous z for FK_STUCK_N samples
    drift: g+ = max(0, g+ + r - FK_DRIFT_K), g- = max(0, g- - r - FK_DRIFT_K) above FK_DRIFT_H
           for FK_DRIFT_N samples"""
    r = innovation / math.sqrt(S) if S > 0.0 else 0.0
    # the pump's pressure difference from the shaft's torque balance (NaN without a valid speed
    # now and one sample before, or a current), through the displacement the estimator learned:
    # with the nominal one a D_p x0.8 pump's load step read 20 % short and was taken for a jump
    pv = shaft_pressure(i, w, (w - s[FS_W1]) / k[FK_TS], k[FK_TB_KT], k[FK_TB_B], k[FK_TB_J],
                        k[FK_TB_DP] * displacement)
    s[FS_NJUMP] = s[FS_NJUMP] + 1 if abs(r) > k[FK_JUMP] else 0
    # a jump starts with a one-sample innovation step, and the pressures stay quiet on it and
    # the next sample (a load step's pressure innovation can come a sample late)
    if s[FS_NJUMP] == 1:
        # the step away from zero: an innovation falling back (the filter catching up with a
        # transient) is not a jump's onset
        s[FS_STEP] = math.copysign(1.0, innovation) * (innovation - s[FS_YPREV])
        s[FS_STEPPED] = 1.0 if s[FS_STEP] >= k[FK_JUMP_STEP] else 0.0
        s[FS_PDREF] = s[FS_PD1]
        s[FS_PREF] = s[FS_P1]
        s[FS_PREF + 1] = s[FS_P1 + 1]
        s[FS_PVREF] = s[FS_PVM]
        s[FS_QUIET] = 1.0 if s[FS_SINCE] >= QUIET_SAMPLES else 0.0
    loud = abs(r) > k[FK_JUMP] or pz >= k[FK_JUMP_PVETO]
    s[FS_SINCE] = 0.0 if loud else min(s[FS_SINCE] + 1.0, QUIET_SAMPLES)
    if 0 < s[FS_NJUMP] <= VETO_SAMPLES and _compressed(k, s, pz, pa, pb, pv):
        s[FS_STEPPED] = 0.0
    s[FS_YPREV] = innovation
    if pa == pa and pb == pb:
        s[FS_PD1] = pa - pb
    if pa == pa:
        s[FS_P1] = pa
    if pb == pb:
        s[FS_P1 + 1] = pb
    # m += Ts / PV_MEAN_TIME (pv - m); restarted at the first pv after a sample without one
    if pv != pv or s[FS_PVM] != s[FS_PVM]:
        s[FS_PVM] = pv
    else:
        s[FS_PVM] += min(k[FK_TS] / PV_MEAN_TIME, 1.0) * (pv - s[FS_PVM])
    s[FS_W1] = w
    same = s[FS_HAS_ZPREV] > 0.5 and z == s[FS_ZPREV]
    s[FS_NSAME] = s[FS_NSAME] + 1 if same else 0
    s[FS_ZPREV] = z
    s[FS_HAS_ZPREV] = 1.0
    s[FS_GPOS] = _max(0.0, s[FS_GPOS] + r - k[FK_DRIFT_K])
    s[FS_GNEG] = _max(0.0, s[FS_GNEG] - r - k[FK_DRIFT_K])
    s[FS_NDRIFT] = s[FS_NDRIFT] + 1 if _max(s[FS_GPOS], s[FS_GNEG]) > k[FK_DRIFT_H] else 0
    # a jump moves the reading; identical readings behind a big innovation are a stuck
    # sensor (reported when stuck_samples is reached), not a jump
    now_jump = (s[FS_NJUMP] >= k[FK_JUMP_N] and s[FS_NSAME] < k[FK_JUMP_N]
                and s[FS_STEPPED] > 0.5)
    now_stuck = s[FS_NSAME] + 1 >= k[FK_STUCK_N]
    now_drift = s[FS_NDRIFT] >= k[FK_DRIFT_N] and s[FS_NSAME] < k[FK_JUMP_N]
    if now_jump:              # a jump is not a drift: restart the CUSUM behind it
        s[FS_GPOS] = 0.0
        s[FS_GNEG] = 0.0
        s[FS_NDRIFT] = 0
        now_drift = False
    return _report(k, s, now_jump, now_stuck, now_drift)


@njit(cache=True)
def no_sample(k, s) -> int:
    """A tick with no usable position (rejected or stale): holds count down; the next
    sample's speed has no previous one to differ from."""
    s[FS_W1] = math.nan
    return _report(k, s, False, False, False)


def torque_balance(p: dict, Ts: float) -> tuple:
    """(k_T, b_eq, J_eq, D_p, Ts): the constants of the shaft's torque balance
    (health.shaft_pressure), dw/dt over one sample of Ts."""
    return (p['plant.motor.k_T'], p['plant.motor.b_eq'], p['plant.motor.J_eq'],
            p['plant.pump.D_p'], Ts)


def pd_per_m(p: dict) -> float:
    """d p_D / dx by compressing the oil of both chambers at mid-stroke (eq. 3.20-3.21):
    A_p (beta / V_A + beta / V_B) = 2 beta A_p / V_d (Pa per m)."""
    A_p = p['plant.cylinder.A_p']
    k_a, k_b = chamber_stiffness.py_func(0.0, p['plant.cylinder.V_d'], A_p, p['plant.fluid.beta'],
                                         math.inf)
    return A_p * (k_a + k_b)


class FaultDetector:
    """Feed one sample per tick with :meth:`update`; read the code from its return value.
    Constants and state are the arrays ``k`` and ``s`` (FK_*, FS_*) of :func:`detect`."""

    def __init__(self, Ts: float, jump_threshold: float = JUMP_THRESHOLD, jump_debounce: int = 3,
                 stuck_samples: int = 25, drift_k: float = DRIFT_K,
                 drift_h: float = 150.0, drift_debounce: int = DRIFT_DEBOUNCE,
                 hold_time: float = 0.5,
                 jump_step: float = 0.0, jump_pressure_veto: float = 1e300,
                 pd_per_m: float = 0.0, torque_balance: tuple = (math.nan,) * 5):
        """torque_balance: :func:`torque_balance` (NaN: no veto by it)."""
        self.Ts = Ts
        self.k = np.zeros(NFK)
        self.k[:] = (jump_threshold, jump_debounce, stuck_samples, drift_k, drift_h,
                     drift_debounce, int(round(hold_time / Ts)), jump_step, jump_pressure_veto,
                     pd_per_m, *torque_balance)
        self.s = np.zeros(NFS)
        self.reset()
        # compiled (or loaded) now: no_sample() is first called by a stale tick, mid-run
        detect(self.k, self.s.copy(), 0.0, 0.0, 1.0, 0.0, math.nan, math.nan, math.nan,
               math.nan, 1.0)
        no_sample(self.k, self.s.copy())

    @classmethod
    def from_params(cls, p: dict, Ts: float) -> 'FaultDetector':
        f = 'estimator.fault.'
        return cls(Ts, jump_debounce=p[f + 'jump_debounce'], stuck_samples=p[f + 'stuck_samples'],
                   drift_h=p[f + 'drift_h'], hold_time=p['estimator.hold_time'],
                   jump_step=sensor_band.from_params(p).jump_step,
                   jump_pressure_veto=p[f + 'jump_pressure_veto'],
                   pd_per_m=pd_per_m(p), torque_balance=torque_balance(p, Ts))

    def reset(self):
        self.s[:] = 0.0
        self.s[FS_W1] = self.s[FS_PVM] = math.nan

    def start(self, z: float):
        """The first sample: the reference of the stuck test, nothing judged."""
        self.s[FS_ZPREV], self.s[FS_HAS_ZPREV] = z, 1.0

    def forget_speed(self):
        """States were lost: the next sample's speed has no previous one to differ from."""
        self.s[FS_W1] = math.nan

    def update(self, z: float, innovation: float, S: float, pz: float = 0.0,
               pa: float = math.nan, pb: float = math.nan, w: float = math.nan,
               i: float = math.nan, displacement: float = 1.0) -> int:
        return detect(self.k, self.s, float(z), float(innovation), float(S), float(pz),
                      float(pa), float(pb), float(w), float(i), float(displacement))

    def tick_without_sample(self) -> int:
        return no_sample(self.k, self.s)

    @property
    def code(self) -> int:
        return int(self.s[FS_CODE])

    @property
    def hold_ticks(self) -> int:
        return int(self.k[FK_HOLD])

    @property
    def detections(self) -> dict:
        """Faults detected so far, by code."""
        return {c: int(self.s[FS_DET + i]) for i, c in enumerate(CODES)}

    @property
    def suspect_samples(self) -> int:
        """Samples so far that the estimator held back as a suspected jump's (:func:`suspect`,
        counted by core.estimator.stepper.estimate; none with the isolate stage off)."""
        return int(self.s[FS_SUSPECT])
