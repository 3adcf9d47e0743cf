"""One sweep run against a stream of plant ticks: reference (or load force) per tick, recording
by seq, gain and phase per finished frequency, and outputs under out/<run>/ that survive an
interruption.

Used by the sweep node (ticks from /eha/state) and by batch runs (ticks from a loop), so both
produce the same summary.json (contract: bandwidth_hz, phase_at_7hz_deg, points[]). A stepped
sine of the reference stops after the first frequency below -3 dB when asked (stop_at_db): the
bandwidth is then bracketed by the last two points. A stiffness run (excite='load') drives the
load force with the plan, holds the reference, and reports |F_L|/|x| per frequency (eq. 4.60).
A load step (excite='load' with a step plan and ``load_step``) reports the figures of the batch
campaigns' load_step scenario (core.sweep.analysis.load_step_figures) from the recorded truth,
the position sensor's Gauss-Markov offset and the estimate.
"""
from __future__ import annotations

import math
import os
import queue
import threading

import numpy as np

from ..io.report import write_csv, write_json
from ..redundancy.state_machine import FAILED_SAFE
from .analysis import (BANDWIDTH_DB, LOAD_STEP, load_step_figures, sine_point,
                       stiffness_kn_per_mm, stiffness_summary, summarize)
from .plots import bode_png, stiffness_png

COLUMNS = ('reference', 'estimate', 'measured', 'truth', 'command', 'motor_speed_0',
           'motor_speed_1', 'active_channel', 'load', 'sensor_offset')
LOAD_STEP_FIGURES = ('peak_deviation_m', 'steady_error_m', 'steady_error_truth_m',
                     'estimate_error_m')
EARLY_STEP_S = 0.1          # a load step reaching the plant earlier than planned by more: not ours


def filled(y: np.ndarray, need: float = 0.95):
    """y with its missing (non-finite) samples interpolated, or None when fewer than ``need``
    of them are there."""
    ok = np.isfinite(y)
    if not len(y) or ok.mean() < need:
        return None
    if ok.all():
        return y
    idx = np.arange(len(y))
    return np.interp(idx, idx[ok], y[ok])


class TrackingGuard:
    """Abort on a lost track: |reference - position| above ``limit`` for ``ticks`` ticks in a
    row (the sweep's abort, and the identification experiments')."""

    def __init__(self, limit: float, ticks: int):
        self.limit, self.ticks, self.count = limit, ticks, 0

    def update(self, reference: float, position: float, tick: int) -> str | None:
        """One tick; the reason (one line) once the error has persisted, else None."""
        err = abs(reference - position)
        self.count = self.count + 1 if err > self.limit else 0
        if self.count >= self.ticks:
            return (f'position error {err * 1e3:.2f} mm > {self.limit * 1e3:.2f} mm at tick '
                    f'{tick}')
        return None


class Writer:
    """Runs file writes on a background thread so 1 kHz callbacks never wait for the disk."""

    def __init__(self, background: bool = True):
        self.background = background
        self.q: queue.Queue = queue.Queue()
        self.thread = None
        if background:
            self.thread = threading.Thread(target=self._run, name='sweep_writer', daemon=True)
            self.thread.start()

    def submit(self, fn, *args):
        if self.background:
            self.q.put((fn, args))
        else:
            fn(*args)

    def _run(self):
        while True:
            item = self.q.get()
            if item is None:
                return
            fn, args = item
            try:
                fn(*args)
            except Exception as err:          # keep writing what can be written
                print(f'sweep: writing failed: {err!r}', flush=True)

    def close(self):
        if self.thread is not None:
            self.q.put(None)
            self.thread.join(timeout=30)


class SweepSession:
    """Stepped-sine (or chirp/step) plan + recording + incremental report.

    excite: 'reference' (the plan is the position reference) or 'load' (the plan is the
    external load force in N, the reference stays at ``position``). stop_at_db: end a stepped
    sine after the first point below this gain (None: run every frequency). load_step: the
    load_step scenario's t_step and steady window (core.sweep.analysis.LOAD_STEP) for a load run
    whose plan is a signals.Step: the summary holds its figures (LOAD_STEP_FIGURES)."""

    def __init__(self, plan, out_dir: str, meta: dict, output: str = 'auto',
                 abort_error: float = math.inf, abort_ticks: int = 20, model=None,
                 background_writes: bool = True, settle_periods: int = 2,
                 excite: str = 'reference', position: float = 0.0, stop_at_db=None,
                 stiffness_bound=None, load_step: dict | None = None):
        if excite not in ('reference', 'load'):
            raise ValueError(f'excite {excite!r}: expected reference or load')
        if load_step is not None and excite != 'load':
            raise ValueError('load_step: expected excite=load (the plan is the load force)')
        self.load_step = load_step
        self.step_figures: dict = {}             # load_step: figures, once the run finished
        self.plan = plan
        self.n = plan.n_ticks
        self.end = self.n                      # ticks that run (an early stop shortens it)
        self.excite = excite
        self.position = position if excite == 'load' else plan.offset
        self.stop_at_db = stop_at_db if excite == 'reference' else None
        self.stiffness_bound = stiffness_bound  # f_hz -> kN/mm (eq. 4.60), load runs
        self.Ts = plan.Ts
        self.out = out_dir
        os.makedirs(os.path.join(out_dir, 'data'), exist_ok=True)
        self.meta = dict(meta)
        self.output = output
        self.guard = TrackingGuard(abort_error, abort_ticks)
        self.model = model                     # callable freqs_hz -> (gain_db, phase_deg)
        self.settle = settle_periods
        self.ref = plan.array()
        self.data = {c: np.full(self.n, np.nan) for c in COLUMNS}
        self.seq0 = None
        self.points = []
        self.next_segment = 0
        self.aborted = None
        self.finished = False
        self.writer = Writer(background_writes)
        self._write_summary(complete=False, reason='running')

    # ---- ticks ----
    def start(self, seq0: int):
        """The plan's tick 0 is plant tick seq0."""
        self.seq0 = seq0

    def _plan_at(self, seq: int, rest: float) -> float:
        if self.seq0 is None:
            return float(rest)
        i = seq - self.seq0
        return float(self.ref[i]) if 0 <= i < self.end else float(rest)

    def reference_for(self, seq: int) -> float:
        """Position reference for plant tick seq (the offset outside the plan)."""
        if self.excite == 'load':
            return float(self.position)
        return self._plan_at(seq, self.plan.offset)

    def load_for(self, seq: int) -> float:
        """External load force for plant tick seq (0 unless a stiffness run)."""
        return self._plan_at(seq, 0.0) if self.excite == 'load' else 0.0

    def record(self, column: str, seq: int, value: float):
        if self.seq0 is None:
            return
        i = seq - self.seq0
        if 0 <= i < self.n:
            self.data[column][i] = value

    def record_many(self, column: str, seq: int, values):
        """:meth:`record` of consecutive ticks seq, seq + 1, ... (batch)."""
        if self.seq0 is None:
            return
        i0, values = seq - self.seq0, np.asarray(values, float)
        lo, hi = max(i0, 0), min(i0 + len(values), self.n)
        if lo < hi:
            self.data[column][lo:hi] = values[lo - i0:hi - i0]

    def check_error(self, seq: int, position: float) -> bool:
        """Abort when |reference - position| exceeds the limit for abort_ticks ticks in a row."""
        if self.aborted or self.seq0 is None:
            return False
        why = self.guard.update(self.reference_for(seq), position, seq - self.seq0)
        if why:
            self.aborted = f'aborted: {why}'
        return why is not None

    def check_manager(self, state: str, reason: str) -> bool:
        """Abort on the loop's safe state (switch manager FAILED_SAFE): the actuator holds, so
        what follows is no response of the loop (and before the start, the sweep never runs)."""
        if self.aborted or state != FAILED_SAFE:
            return False
        self.aborted = f'aborted: safe state: switch manager {FAILED_SAFE} ({reason})'
        return True

    def progress(self, done_seq: int) -> list:
        """Analyse every segment whose data is complete up to done_seq; returns new points."""
        new = []
        segs = getattr(self.plan, 'segments', [])
        while self.next_segment < len(segs) and self.seq0 is not None and \
                not self.stopped_early and done_seq - self.seq0 >= segs[self.next_segment].stop:
            seg = segs[self.next_segment]
            point = self._analyse(seg)
            if point is not None:
                self.points.append(point)
                new.append(point)
            self.writer.submit(self._write_segment, self.next_segment, seg)
            self.next_segment += 1
            if (point is not None and self.stop_at_db is not None
                    and point.gain_db < self.stop_at_db and self.next_segment < len(segs)):
                # the plan ends where the next sine would start: the reference rests at the
                # offset (a relax shorter than the analysis lag cuts a started sine short)
                self.end = segs[self.next_segment].start
            self._write_summary(complete=False, reason='running')
        return new

    @property
    def stopped_early(self) -> bool:
        """The plan was cut short at the bandwidth (stop_at_db)."""
        return self.end < self.n

    @property
    def n_run(self) -> int:
        """Ticks of the run: the plan, or up to the early stop plus the rest after it."""
        if not self.stopped_early:
            return self.n
        return min(self.n, self.end + int(round(getattr(self.plan, 'relax_s', 0.0) / self.Ts)))

    def describe(self, point) -> str:
        """One progress line per measured frequency ('<f> Hz: ...')."""
        if self.excite == 'load':
            return (f'{point.freq_hz:6.2f} Hz: |F|/|x| {stiffness_kn_per_mm(point):7.1f} kN/mm '
                    f'coherence {point.coherence:.4f}')
        return (f'{point.freq_hz:6.2f} Hz: {point.gain_db:7.2f} dB {point.phase_deg:7.1f} deg '
                f'coherence {point.coherence:.4f}')

    def output_column(self, sl=slice(None)) -> str:
        if self.load_step is not None:
            return 'truth'                         # the figures are defined on the truth
        if self.output != 'auto':
            return self.output
        return 'truth' if np.isfinite(self.data['truth'][sl]).mean() > 0.9 else 'estimate'

    def _analyse(self, seg):
        sl = slice(seg.start, seg.stop)
        col = self.output_column(sl)
        u, y = self.ref[sl], self.data[col][sl]
        if self.excite == 'load' and np.isfinite(self.data['load'][sl]).all():
            u = self.data['load'][sl]              # the force the plant applied (its truth)
        y = filled(y)
        if y is None:
            return None                            # too much missing: no point, not a wrong one
        return sine_point(u, y, seg.freq_hz, self.Ts, self.settle)

    def _analyse_load_step(self) -> tuple[dict, str | None]:
        """(figures, None) of a finished load step, or ({}, why not). The figures are the batch
        campaigns' (core.sweep.analysis.load_step_figures) with the held position as 0, the
        step where the truth first reports the load minus one tick (the batch record's truth
        is the state at the start of a tick, the load acts during it)."""
        n, d = self.n_run, self.data
        if not np.isfinite(d['truth'][:n]).any():
            return {}, 'the load step needs /eha/sim/truth (the simulator\'s ground truth)'
        cols = {c: filled(d[c][:n]) for c in ('truth', 'sensor_offset', 'estimate', 'load')}
        missing = [c for c, v in cols.items() if v is None]
        if missing:
            return {}, f'{", ".join(missing)}: recorded on fewer than 95 % of the ticks'
        planned = self.load_step['t_step']
        on = np.nonzero(np.abs(cols['load']) >= 0.5 * abs(self.plan.amplitude))[0]
        if not len(on):
            return {}, 'the load step never reached the plant (/eha/sim/truth load_force)'
        t_step = (on[0] - 1) * self.Ts
        window = list(self.load_step['steady'])
        if t_step < planned - EARLY_STEP_S:
            return {}, (f'a load reached the plant at {t_step:.3f} s, before the step planned at '
                        f'{planned:g} s (another source on /eha/sim/load_force?)')
        if t_step + window[1] > n * self.Ts + 0.5 * self.Ts:
            return {}, (f'the load step reached the plant at {t_step:.3f} s, '
                        f'{(t_step - planned) * 1e3:.0f} ms after the plan: the run of '
                        f'{n * self.Ts:g} s ends before its steady window (the sweep lagged behind '
                        f'the plant; a longer sweep.load_step_duration covers it)')
        x = cols['truth'] - self.position
        sig = {'t': np.arange(n) * self.Ts, 'truth': x, 'sensor_lf': x + cols['sensor_offset'],
               'estimate': cols['estimate'] - self.position}
        figs = load_step_figures(sig, {'t_step': t_step, 'steady': window}, self.Ts)
        figs['step_time_s'] = float(t_step)
        return figs, None

    # ---- outputs ----
    @property
    def files(self) -> list[str]:
        """What the run writes into its folder (besides data/)."""
        plot = [] if self.load_step is not None else \
            ['stiffness.png' if self.excite == 'load' else 'bode.png']
        return ['summary.json', 'data.csv'] + plot

    def _write_segment(self, i, seg):
        sl = slice(seg.relax_start, seg.stop)
        cols = {'tick': np.arange(sl.start, sl.stop), **{c: self.data[c][sl] for c in COLUMNS}}
        write_csv(os.path.join(self.out, 'data', f'segment_{i:02d}_{seg.freq_hz:g}hz.csv'), cols)

    def _summary(self, complete: bool, reason: str) -> dict:
        s = summarize(self.points)
        s.update({'complete': complete, 'status': reason, 'output': self.output_column(),
                  'excite': self.excite, 'stopped_at_bandwidth': self.stopped_early,
                  'frequencies_planned_hz': [seg.freq_hz for seg in getattr(self.plan, 'segments', [])]})
        if self.excite == 'load':                # x/F in m/N: no bandwidth, no tracking phase
            s.update(bandwidth_hz=None, phase_at_7hz_deg=None, peak_gain_db=None,
                     peak_gain_freq_hz=None)
        if self.load_step is not None:
            s.update({k: None for k in LOAD_STEP_FIGURES}, analysis='load_step',
                     load_n=float(self.plan.amplitude), step_time_s=None,
                     steady_window_s=list(self.load_step['steady']))
            s.update(self.step_figures)
        elif self.excite == 'load':
            s.update(stiffness_summary(self.points, self.stiffness_bound), analysis='stiffness')
        else:
            s['analysis'] = 'frequency_response'
        s.update(self.meta)
        return s

    def _write_summary(self, complete: bool, reason: str):
        summary = self._summary(complete, reason)
        self.writer.submit(write_json, os.path.join(self.out, 'summary.json'), summary)
        return summary

    def finish(self, complete: bool | None = None, reason: str | None = None) -> dict:
        """Final summary, full data CSV and Bode plot; complete only if every point was analysed."""
        if self.finished:
            return self._summary(self.complete, self.reason)
        segs = getattr(self.plan, 'segments', [])
        if self.stopped_early:
            segs = segs[:self.next_segment]
        why = None
        if self.load_step is not None and reason is None and self.aborted is None:
            self.step_figures, why = self._analyse_load_step()
        if complete is None:
            complete = self.aborted is None and len(self.points) == len(segs) and why is None
        reason = reason or why
        if reason is None and self.aborted is None and not complete:
            reason = (f'{len(self.points)} of {len(segs)} frequencies measured (the others had '
                      f'too little data)')
        reason = reason or self.aborted or 'complete'
        self.complete, self.reason = complete, reason
        summary = self._write_summary(complete, reason)
        cols = {'tick': np.arange(self.n), **self.data}
        self.writer.submit(write_csv, os.path.join(self.out, 'data.csv'), cols)
        if self.points and self.excite == 'load':
            self.writer.submit(stiffness_png, os.path.join(self.out, self.files[-1]),
                               summary['stiffness'], f'dynamic stiffness |F_L|/|x| '
                               f'({summary["output"]}), {"complete" if complete else reason}')
        elif self.points:
            model = None
            if self.model is not None:
                f = np.logspace(np.log10(min(p.freq_hz for p in self.points) * 0.8),
                                np.log10(max(p.freq_hz for p in self.points) * 1.2), 200)
                model = (f, *self.model(f))
            title = f'closed loop x/x_ref ({summary["output"]}), {"complete" if complete else reason}'
            self.writer.submit(bode_png, os.path.join(self.out, self.files[-1]), summary['points'],
                               model, title)
        self.writer.close()
        self.finished = True
        return summary


def from_params(p: dict, plan, out: str, meta: dict, model=None, **kw):
    """The SweepSession of validated sweep parameters (node and batch run alike)."""
    from .analysis import stiffness_bound
    stiff, step = p['sweep.mode'] == 'stiffness', p['sweep.mode'] == 'load_step'
    load = stiff or step
    return SweepSession(plan, out, meta, p['sweep.output'], p['sweep.abort_error'],
                        p['sweep.abort_ticks'], None if load else model,
                        settle_periods=p['sweep.settle_periods'],
                        excite='load' if load else 'reference', position=p['sweep.offset'],
                        stop_at_db=BANDWIDTH_DB if p['sweep.stop_at_bandwidth'] and
                        p['sweep.mode'] == 'stepped' else None,
                        stiffness_bound=stiffness_bound() if stiff else None,
                        load_step={k: LOAD_STEP[k] for k in ('t_step', 'steady')}
                        if step else None, **kw)


def _um(value) -> str:
    return 'n/a' if value is None else f'{value * 1e6:.1f} um'


def print_table(summary: dict, out=print):
    """The summary table scripts/run prints."""
    state = 'complete' if summary['complete'] else 'INCOMPLETE: ' + summary['status']
    if summary.get('analysis') == 'load_step':
        w = summary.get('steady_window_s')
        out(f'load step of {summary["load_n"] / 1e3:g} kN'
            + ('' if summary.get('step_time_s') is None else
               f' at {summary["step_time_s"]:.3f} s') + ', reference held'
            + ('' if w is None else f'; steady window {w[0]:g}-{w[1]:g} s after the step'))
        for key, text in (('peak_deviation_m', 'peak deviation |x - x_before| (truth)'),
                          ('steady_error_m', 'steady error (truth + sensor offset)'),
                          ('steady_error_truth_m', 'steady error of the truth alone'),
                          ('estimate_error_m', 'estimate error (estimate - truth)')):
            out(f'  {text:40} {_um(summary.get(key)):>10}')
        out(f'load step: {state}')
        return
    if summary.get('excite') == 'load':
        out(f'{"freq [Hz]":>10} {"|F|/|x| [kN/mm]":>16} {"1/|M| [kN/mm]":>14} {"coherence":>10}')
        for p, k in zip(summary['points'], summary['stiffness']):
            b = k.get('bound_kn_per_mm')
            out(f'{p["freq_hz"]:10.2f} {k["stiffness_kn_per_mm"]:16.1f} '
                f'{"n/a" if b is None else "%.1f" % b:>14} {p["coherence"]:10.4f}')
        low, ratio = summary['stiffness_min_kn_per_mm'], summary['stiffness_min_ratio_to_bound']
        out(f'dynamic stiffness: min {"n/a" if low is None else "%.1f kN/mm" % low}'
            + ('' if ratio is None else f', {ratio:.2f} x the eq. 4.60 bound 1/|M| '
               f'({"met" if summary["stiffness_meets_bound"] else "NOT met"})')
            + f'; {state}')
        return
    out(f'{"freq [Hz]":>10} {"gain [dB]":>10} {"phase [deg]":>12} {"coherence":>10}')
    for p in summary['points']:
        out(f'{p["freq_hz"]:10.2f} {p["gain_db"]:10.2f} {p["phase_deg"]:12.1f} '
            f'{p["coherence"]:10.4f}')
    bw, ph7 = summary['bandwidth_hz'], summary['phase_at_7hz_deg']
    top = max((p['freq_hz'] for p in summary['points']), default=0)
    out(f'bandwidth (-3 dB): {"above %g Hz (not reached)" % top if bw is None else "%.2f Hz" % bw}'
        f'; phase at 7 Hz: {"n/a" if ph7 is None else "%.1f deg" % ph7}'
        f'; {state}')
