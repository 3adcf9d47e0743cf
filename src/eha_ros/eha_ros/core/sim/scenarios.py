"""Campaign scenarios: what one run does to the loop and which figures it yields.

A scenario is a YAML file (config/campaigns/<name>.yaml; users add their own)::

    name: step
    kind: step              # one of KINDS: the signals and the figures of merit
    description: 5 mm step from rest
    params: {amplitude: 0.005}          # overrides of the kind's defaults (KINDS[kind])
    specs:                              # pass/fail per figure (SI units)
      overshoot_pct: {max: 5.0}
      peak_deviation_m: {max_rel: {to: lin_peak_deviation_m, factor: 1.25, offset: 5.0e-5}}
      stiffness_kn_per_mm_7hz:          # cases: the first whose `where` column is true
        - {where: loaded_beyond_table, min_rel: {to: lin_loaded_stiffness_kn_per_mm_7hz}}
        - {min: 49.0}
    overrides:                          # optional: node parameters changed for every run, as
      controller:control.rate_limit: 5.0  # -p node:key:=value (e.g. reference limits lifted)
    oracle: false                       # optional: the estimator is given the plant's
                                        # parameters (core.sim.oracle, campaign --oracle)

One run (:func:`run`) = the batch closed loop (core.sim.batch.BatchLoop, compiled path) of the
stack -- nonlinear plant, Kalman estimator, QFT controller, switch manager, in the stack's tick
order -- on ONE plant variant (core.sim.family.plant_params) with one noise seed; estimator,
controller and switch manager keep the nominal parameters they are given (with ``oracle``
the estimator's model takes the variant's parameters instead).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np
import yaml

from ..config.cli import UsageError
from ..config.registry import LOOP_NODES
from ..config.params import default_config_dir
from ..sweep.analysis import LOAD_STEP, load_step_figures
from ..plant.faults import FAULTS
from .sensor_bound import steady_error_bound

# kind -> default params (SI units). Times in s from the start of the run.
KINDS = {
    # 5 mm step; overshoot and 2 % settling of the truth, steady error averaged over
    # [t_step + steady[0], t_step + steady[1]]; beside it that error's floor on the run's
    # sensor noise (core.sim.sensor_bound)
    'step': dict(amplitude=5e-3, t_step=0.1, duration=1.6, band=0.02, steady=[1.0, 1.5]),
    # load force step while holding 0 (sweep.analysis.LOAD_STEP, the sweep node's too)
    'load_step': LOAD_STEP,
    # stepped sine of the reference: gain and phase of truth vs reference per frequency
    'sweep': dict(amplitude=1e-3, freqs=[1.0, 2.0, 4.0, 7.0, 10.0, 15.0], settle_periods=2,
                  periods=6),
    # stepped sine of the load force, reference held: |F|/|x| per frequency (Fig. 4.52)
    'stiffness': dict(force=5e3, freqs=[1.0, 4.0, 7.0], settle_periods=2, periods=6),
    # sine tracking: RMSE(estimate - truth) / RMSE(raw sensor - truth) over the window
    'sine': dict(amplitude=5e-3, freq=1.0, duration=30.0, window=[6.0, 30.0]),
    # Table 3.4: 3 Hz 3 mm sine, 10 kN load step at 1 s, commanded switch to B at 3 s
    'switch': dict(amplitude=3e-3, freq=3.0, load=10e3, load_time=1.0, switch_time=3.0,
                   duration=4.0),
    # sensor fault while holding 0 (or tracking a sine; under a load held from load_time):
    # detection time of the estimator, the first report of the fault, false alarms before it
    'sensor_fault': dict(fault='msp_bias', magnitude=1e-3, t_fault=2.0, duration=3.0,
                         amplitude=0.0, freq=1.0, load=0.0, load_time=0.0),
    # a plant fault (core.plant.faults; on couple A) during the Table 3.4 sine under load: the
    # active couple's motor (the switch manager hands over to B), or a chamber pressure sensor
    'motor_fail': dict(amplitude=3e-3, freq=3.0, load=10e3, load_time=1.0, t_fault=2.0,
                       duration=3.0, fault='motor_fail', magnitude=0.0),
}
SPEC_FORMS = ('max', 'min', 'max_rel', 'min_rel')
NODES = ('plant_sim',) + LOOP_NODES    # what one run builds (core.config.registry)
TRACE_POINTS = 1500          # decimated samples per trace kept for the report

# columns a campaign summary shows beside a failed spec's value, where a run has them: the
# truth's own error (load step, whose spec is against what the sensor reports without its
# white noise) or the floor an estimator that knows the plant would leave (step, jump:
# core.sim.sensor_bound)
BESIDE = {'steady_error_m': ('steady_error_truth_m', 'steady_error_bound_m')}


@dataclass
class Scenario:
    name: str
    kind: str
    description: str = ''
    params: dict = field(default_factory=dict)
    specs: dict = field(default_factory=dict)
    path: str = ''
    overrides: dict = field(default_factory=dict)    # {'node:key': value} of the loop's nodes
    oracle: bool = False         # the estimator is given the plant parameters (core.sim.oracle)

    @property
    def duration(self) -> float:
        p = self.params
        if self.kind in ('sweep', 'stiffness'):
            return sum(segment_ticks(f, p) for f in p['freqs']) * 1e-3
        return float(p['duration'])

    def as_dict(self) -> dict:
        doc = dict(name=self.name, kind=self.kind, description=self.description,
                   params=self.params, specs=self.specs, overrides=self.overrides,
                   duration=self.duration)
        if self.oracle:
            doc['oracle'] = True
        return doc


def scenario_dir() -> str:
    return os.path.join(default_config_dir(), 'campaigns')


def available() -> list[str]:
    d = scenario_dir()
    out = []
    for f in sorted(os.listdir(d)) if os.path.isdir(d) else []:
        if f.endswith('.yaml') and not f.startswith('family'):
            out.append(f[:-5])
    return out


def load(name_or_path: str) -> Scenario:
    """A scenario by name (config/campaigns/<name>.yaml) or path; UsageError (one line) when
    it is unknown or malformed."""
    path = name_or_path
    if not (os.sep in path or path.endswith('.yaml')):
        path = os.path.join(scenario_dir(), name_or_path + '.yaml')
        if not os.path.isfile(path):
            raise UsageError(f'unknown scenario {name_or_path!r}: expected one of '
                             f'{", ".join(available())} or a path to a scenario YAML')
    try:
        with open(path) as f:
            doc = yaml.safe_load(f)
    except OSError as err:
        raise UsageError(f'scenario {path}: cannot read it: {err.strerror}')
    except yaml.YAMLError as err:
        raise UsageError(f'scenario {path}: malformed YAML: {str(err).splitlines()[0]}')
    return from_dict(doc, path)


def from_dict(doc, path: str = '<dict>') -> Scenario:
    if not isinstance(doc, dict):
        raise UsageError(f'scenario {path}: expected a mapping with name, kind, params, specs')
    unknown = set(doc) - {'name', 'kind', 'description', 'params', 'specs', 'overrides',
                          'oracle'}
    if unknown:
        raise UsageError(f'scenario {path}: unknown key(s) {", ".join(sorted(unknown))} '
                         f'(expected name, kind, description, params, specs, overrides, '
                         f'oracle)')
    if not isinstance(doc.get('oracle', False), bool):
        raise UsageError(f'scenario {path}: oracle = {doc["oracle"]!r}: expected true or false')
    kind = doc.get('kind')
    if kind not in KINDS:
        raise UsageError(f'scenario {path}: kind {kind!r}: expected one of {", ".join(KINDS)}')
    params = dict(KINDS[kind])
    given = doc.get('params') or {}
    if not isinstance(given, dict):
        raise UsageError(f'scenario {path}: params: expected a mapping, got {given!r}')
    for key, value in given.items():
        if key not in params:
            raise UsageError(f'scenario {path}: params.{key}: unknown for kind {kind} '
                             f'(expected {", ".join(params)})')
        default = params[key]
        ok = (isinstance(value, str) if isinstance(default, str) else
              isinstance(value, list) and all(_num(v) for v in value)
              if isinstance(default, list) else _num(value))
        if not ok:
            raise UsageError(f'scenario {path}: params.{key} = {value!r}: expected '
                             f'{type(default).__name__} like {default!r}')
        params[key] = value
    if 'fault' in params and params['fault'] not in FAULTS:
        raise UsageError(f'scenario {path}: params.fault = {params["fault"]!r}: expected one '
                         f'of {", ".join(FAULTS)}')
    specs = doc.get('specs') or {}
    if not isinstance(specs, dict):
        raise UsageError(f'scenario {path}: specs: expected a mapping metric: {{max: v}}')
    for metric, s in specs.items():
        _check_spec(s, f'scenario {path}: specs.{metric}')
    overrides = doc.get('overrides') or {}
    if not (isinstance(overrides, dict) and all(
            isinstance(k, str) and k.partition(':')[0] in NODES and k.partition(':')[2]
            for k in overrides)):
        raise UsageError(f'scenario {path}: overrides = {overrides!r}: expected a mapping '
                         f'node:key: value with node one of {", ".join(NODES)}')
    scn = Scenario(str(doc.get('name') or os.path.basename(path)[:-5]), kind,
                   str(doc.get('description', '')), params, specs, path, dict(overrides),
                   bool(doc.get('oracle', False)))
    _check_signals(scn, path)
    return scn


SPEC_HELP = ('{max: v}, {min: v}, {max_rel: {to: column, factor: f, offset: o}}, {min_rel: ...} '
             'or a list of such cases, each but the last with where: column')


def _check_spec(s, where: str) -> None:
    """A spec: one form (SPEC_FORMS), or a list of cases {where: column, <form>: v} of which
    the first whose column is true applies; the last case has no ``where`` (the default)."""
    cases = s if isinstance(s, list) else [s]
    if not cases or not all(isinstance(c, dict) for c in cases):
        raise UsageError(f'{where} = {s!r}: expected {SPEC_HELP}')
    for i, c in enumerate(cases):
        forms = [k for k in c if k != 'where']
        # a list's last case is the default (no where); every other case of a list has one
        where_ok = ('where' not in c if i == len(cases) - 1 else
                    isinstance(c.get('where'), str)) if isinstance(s, list) else 'where' not in c
        if not (len(forms) == 1 and forms[0] in SPEC_FORMS and where_ok):
            raise UsageError(f'{where} = {s!r}: expected {SPEC_HELP}')
        form, v = forms[0], c[forms[0]]
        if form.endswith('_rel'):
            if not (isinstance(v, dict) and isinstance(v.get('to'), str) and
                    set(v) <= {'to', 'factor', 'offset'} and
                    _num(v.get('factor', 1.0)) and _num(v.get('offset', 0.0))):
                raise UsageError(f'{where}.{form} = {v!r}: expected '
                                 f'{{to: column, factor: number, offset: number}}')
        elif not _num(v):
            raise UsageError(f'{where}.{form} = {v!r}: expected a number')


def from_saved(doc: dict, path: str = '<saved>') -> Scenario:
    """The scenario of Scenario.as_dict() (campaign.json, a task's payload)."""
    return from_dict({k: v for k, v in doc.items() if k != 'duration'}, path)


def _num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check_signals(scn: Scenario, path: str) -> None:
    p = scn.params
    if scn.kind in ('sweep', 'stiffness'):
        bad = [f for f in p['freqs'] if not 0 < f <= 50.0]
        if bad or not p['freqs']:
            raise UsageError(f'scenario {path}: params.freqs {p["freqs"]!r}: expected 0 < f <= '
                             f'50 Hz (Nyquist/10 at Ts = 1 ms)')
        if p['settle_periods'] < 1 or p['periods'] < 1:
            raise UsageError(f'scenario {path}: settle_periods and periods: expected >= 1')
    elif scn.duration <= 0 or scn.duration > 600:
        raise UsageError(f'scenario {path}: params.duration {scn.duration!r}: expected 0..600 s')
    amp = p.get('amplitude', 0.0)
    if abs(amp) > 0.05:
        raise UsageError(f'scenario {path}: params.amplitude {amp!r} m: beyond the stroke '
                         f'(+-0.06 m with margin; expected |amplitude| <= 0.05)')


# ---------------------------------------------------------------------------- signals
def segment_ticks(f: float, p: dict) -> int:
    """Ticks of one stepped-sine frequency: whole periods, settle + measured."""
    return int(round((p['settle_periods'] + p['periods']) / f * 1000.0))


def signals(scn: Scenario, Ts: float):
    """(references, loads, faults, commands) arrays/schedules of n ticks; faults/commands as
    time-sorted (t, payload) lists for core.sim.switchover.schedule."""
    p, kind = scn.params, scn.kind
    n = int(round(scn.duration / Ts))
    t = np.arange(n) * Ts
    ref, load = np.zeros(n), np.zeros(n)
    faults, commands = [], []
    if kind == 'step':
        ref[t >= p['t_step'] - 1e-9] = p['amplitude']
    elif kind == 'load_step':
        load[t >= p['t_step'] - 1e-9] = p['force']
    elif kind in ('sweep', 'stiffness'):
        sig = ref if kind == 'sweep' else load
        amp = p['amplitude'] if kind == 'sweep' else p['force']
        k = 0
        for f in p['freqs']:
            m = segment_ticks(f, p)
            sig[k:k + m] = amp * np.sin(2 * np.pi * f * np.arange(m) * Ts)
            k += m
    elif kind == 'sine':
        ref[:] = p['amplitude'] * np.sin(2 * np.pi * p['freq'] * t)
    elif kind in ('switch', 'motor_fail'):
        ref[:] = p['amplitude'] * np.sin(2 * np.pi * p['freq'] * t)
        load[t >= p['load_time'] - 1e-9] = p['load']
        if kind == 'switch':
            commands.append((p['switch_time'], (1, 'campaign: commanded switch')))
        else:
            faults.append((p['t_fault'], (p['fault'], 0, p['magnitude'], 0.0)))
    elif kind == 'sensor_fault':
        ref[:] = p['amplitude'] * np.sin(2 * np.pi * p['freq'] * t)
        load[t >= p['load_time'] - 1e-9] = p['load']
        faults.append((p['t_fault'], (p['fault'], 0, p['magnitude'], 0.0)))
    return ref, load, faults, commands


# ---------------------------------------------------------------------------- one run
def run(scn: Scenario, nominal: dict, multipliers: dict, seed: int, trace: bool = True):
    """One run; returns (figures dict, decimated traces dict or None).

    multipliers: one family row (core.sim.family.COLUMNS; other keys are ignored)."""
    from .closed_loop import (R_ACTIVE, R_EN, R_FAULT, R_GM, R_STATE, R_U, R_VALVE, R_VERDICT,
                              R_X0, R_XHAT, R_XM)
    from .batch import build_loop
    from .switchover import schedule
    from .family import plant_params
    from .oracle import estimator_params
    plant = plant_params(nominal['plant_sim'], multipliers)
    est = (estimator_params(nominal['estimator'], multipliers) if scn.oracle
           else nominal['estimator'])
    Ts = plant['plant.sim.Ts']
    ref, load, faults, commands = signals(scn, Ts)
    n = len(ref)
    loop = build_loop({**nominal, 'plant_sim': plant, 'estimator': est}, seed,
                      schedule(faults, n, Ts),
                      schedule(commands, n, Ts))
    rec = loop.run(ref, load).T
    t = np.arange(n) * Ts
    sig = dict(t=t, reference=ref, load=load, truth=rec[R_X0], estimate=rec[R_XHAT],
               measured=rec[R_XM], sensor_lf=rec[R_X0] + rec[R_GM], command=rec[R_U],
               fault=rec[R_FAULT], verdict=rec[R_VERDICT],
               active=rec[R_ACTIVE], state=rec[R_STATE], valve=rec[R_VALVE:R_VALVE + 2],
               enable=rec[R_EN:R_EN + 2] > 0.5,
               sensor_noise=(plant['plant.sensors.position_sigma'],
                             plant['plant.sensors.position_gm_sigma'],
                             plant['plant.sensors.position_gm_corner']))
    figs = FIGURES[scn.kind](sig, scn.params, Ts)
    figs['max_abs_command'] = float(np.max(np.abs(rec[R_U])))
    figs['plant_s'] = n * Ts
    tr = None
    if trace:
        step = max(1, math.ceil(n / TRACE_POINTS))
        tr = {k: np.asarray(sig[k][::step], float) for k in
              ('t', 'reference', 'truth', 'estimate', 'measured', 'command', 'load')}
    return figs, tr


def case(spec, figs: dict) -> dict:
    """The case of a spec that applies to one run: the spec itself, or of a list of cases the
    first whose ``where`` column is true in ``figs`` (the last case has none)."""
    if isinstance(spec, dict):
        return spec
    for c in spec:
        if 'where' not in c or bool(figs.get(c['where'], False)):
            return c
    return spec[-1]


def limit(spec, figs: dict) -> tuple[str, float]:
    """('max' | 'min', limit) of one spec on one run; max_rel / min_rel resolve against
    another column of the same run (factor x column + offset)."""
    form, v = next((k, x) for k, x in case(spec, figs).items() if k != 'where')
    if form.endswith('_rel'):
        return form[:3], v.get('factor', 1.0) * figs.get(v['to'], math.nan) + v.get('offset', 0.0)
    return form, float(v)


def judge(figs: dict, specs: dict) -> tuple[bool, str]:
    """(passed, failed_specs): every spec met by a finite figure."""
    failed = []
    for metric, s in specs.items():
        form, v = limit(s, figs)
        x = figs.get(metric, math.nan)
        ok = (x <= v) if form == 'max' else (x >= v)
        if not (isinstance(x, (int, float)) and math.isfinite(x) and math.isfinite(v) and ok):
            failed.append(metric)
    return not failed, ','.join(failed)


def excess(figs: dict, specs: dict) -> tuple[float, str]:
    """Largest normalised spec excess (x/limit - 1 for max, 1 - x/limit for min) and its
    metric: how far the worst spec of a run is from its limit (> 0: failed)."""
    worst, which = -math.inf, ''
    for metric, s in specs.items():
        form, v = limit(s, figs)
        x = figs.get(metric, math.nan)
        try:
            e = (x / v - 1.0) if form == 'max' else (1.0 - x / v)
        except ZeroDivisionError:
            e = math.inf if (form == 'max' and x > 0) or (form == 'min' and x < 0) else 0.0
        e = e if math.isfinite(e) else math.inf
        if e > worst:
            worst, which = e, metric
    return worst, which


# ---------------------------------------------------------------------------- figures
def _fhz(f: float) -> str:
    return f'{int(f)}' if float(f).is_integer() else f'{f:g}'.replace('.', 'p')


def step_figures(s, p, Ts):
    """Overshoot (% of the step), 2 % settling time, steady error and steady ripple (peak to
    peak over the steady window: a loop hunting at rest) of the truth; beside them the steady
    error of what the sensor reports without its white noise (truth + its Gauss-Markov
    offset: the load step's measure, issue 42) and the steady error an estimator that knows
    the plant would leave on the run's sensor noise (core.sim.sensor_bound), not specs here."""
    t, x, a = s['t'], s['truth'], p['amplitude']
    after = t >= p['t_step'] - 1e-9
    y, ta = x[after], t[after] - p['t_step']
    outside = np.nonzero(np.abs(y - a) > p['band'] * abs(a))[0]
    win = (ta >= p['steady'][0]) & (ta <= p['steady'][1])
    out = {'overshoot_pct': float(max(0.0, np.max((y - a) * np.sign(a))) / abs(a) * 100.0),
           'settling_s': float(ta[outside[-1]] + Ts) if len(outside) else 0.0,
           'steady_error_m': float(abs(np.mean(y[win]) - a)),
           'steady_ripple_m': float(np.ptp(y[win])),
           'estimate_error_m': float(abs(np.mean(s['estimate'][after][win] - y[win])))}
    if 'sensor_lf' in s:
        out['steady_error_sensor_m'] = float(abs(np.mean(s['sensor_lf'][after][win]) - a))
    if 'sensor_noise' in s:
        t0 = p['t_step']
        out['steady_error_bound_m'] = steady_error_bound(
            t, s['measured'], x, (t0 + p['steady'][0], t0 + p['steady'][1]), Ts,
            *s['sensor_noise'])
    return out


def _stepped(s, p, Ts, u_key):
    from ..sweep.analysis import sine_point
    out, k = [], 0
    for f in p['freqs']:
        m = segment_ticks(f, p)
        u = s[u_key][k:k + m]
        out.append((f, sine_point(u, s['truth'][k:k + m], f, Ts, int(p['settle_periods']))))
        k += m
    return out


def sweep_figures(s, p, Ts):
    """Gain (dB) and phase (deg) of truth vs reference per frequency (appendix B.2 DFT)."""
    out = {}
    for f, pt in _stepped(s, p, Ts, 'reference'):
        out[f'gain_db_{_fhz(f)}hz'] = pt.gain_db
        out[f'phase_deg_{_fhz(f)}hz'] = pt.phase_deg
    return out


def stiffness_figures(s, p, Ts):
    """Dynamic stiffness |F_L|/|x| per frequency in kN/mm (Fig. 4.52)."""
    from ..sweep.analysis import stiffness_kn_per_mm
    return {f'stiffness_kn_per_mm_{_fhz(f)}hz': stiffness_kn_per_mm(pt)
            for f, pt in _stepped(s, p, Ts, 'load')}


def sine_figures(s, p, Ts):
    """RMSE(estimate - truth) / RMSE(raw sensor - truth) over the window; tracking RMSE; the
    estimate error's parts (:func:`error_parts`)."""
    t = s['t']
    w = (t >= p['window'][0]) & (t <= p['window'][1])
    x = s['truth'][w]
    e_est = np.sqrt(np.mean((s['estimate'][w] - x) ** 2))
    e_raw = np.sqrt(np.mean((s['measured'][w] - x) ** 2))
    return {'rmse_ratio': float(e_est / e_raw), 'estimate_rmse_m': float(e_est),
            'tracking_rmse_m': float(np.sqrt(np.mean((x - s['reference'][w]) ** 2))),
            **error_parts(t[w], s['estimate'][w] - x, p['freq'], Ts)}


SLOW_BAND = 0.9         # error_slow_m: below this fraction of the sine's frequency


def error_parts(t, e, freq: float, Ts: float) -> dict:
    """Where an estimate error e(t) under a sine of ``freq`` comes from, each an rms [m]:
    its mean over the window (error_mean_m), its component at the sine's frequency (least
    squares on sin, cos; error_at_freq_m: a gain or phase error of the model), and what is
    left below SLOW_BAND x freq (error_slow_m: the sensor's slow Gauss-Markov wander taken
    into the estimate). RMSE^2 = mean^2 + at_freq^2 + the rest (slow, harmonics, noise)."""
    wt = 2.0 * np.pi * freq * t
    M = np.column_stack((np.ones_like(t), np.sin(wt), np.cos(wt)))
    c, *_ = np.linalg.lstsq(M, e, rcond=None)
    rest = e - M @ c
    f = np.fft.rfftfreq(len(rest), Ts)
    power = 2.0 * np.abs(np.fft.rfft(rest)) ** 2 / len(rest) ** 2   # one-sided, rms^2 per bin
    slow = power[(f > 0.0) & (f < SLOW_BAND * freq)].sum()
    return {'error_mean_m': float(abs(c[0])),
            'error_at_freq_m': float(np.hypot(c[1], c[2]) / np.sqrt(2.0)),
            'error_slow_m': float(np.sqrt(slow))}


def handover_figures(s, p, t_event: float):
    """Figures of a hand-over to couple B at t_event while tracking a sine (Table 3.4): the
    tracking figures of core.sim.switchover, the time until B drives, the final channel."""
    from .switchover import driving_time, tracking_figures
    f = tracking_figures(s['t'], s['truth'], s['reference'], t_event, 1.0 / p['freq'])
    f['drive_time_s'] = driving_time(s['t'], s['valve'], s['enable'], 1, t_event)
    f['final_channel'] = float(s['active'][-1])
    return f


def switch_figures(s, p, Ts):
    """Table 3.4: the commanded switch."""
    return handover_figures(s, p, p['switch_time'])


def motor_fail_figures(s, p, Ts):
    """A plant fault (motor failure of the active couple: the automatic switch): the
    hand-over figures and whether the switch manager went to the safe state (1) or not (0)."""
    from ..redundancy.state_machine import STATE_CODES
    f = handover_figures(s, p, p['t_fault'])
    f['safe_state'] = float(np.any(s['state'] == STATE_CODES['FAILED_SAFE']))
    return f


def sensor_fault_figures(s, p, Ts):
    """Estimator's detection time of the injected sensor fault (inf: none; a fault at or after
    the run's end is never injected: false_alarm), false alarms before it (a fault code or the
    safe state); the first report of it, a fault code or a consistency verdict other than ok
    (adapt.VERDICTS: a drift under a held load is the monitor's model_mismatch, not the
    detector's), and the ticks with such a verdict before the fault; the safe state
    (core.loop.safe_state): time from the fault to the hydraulic lock (switch manager
    FAILED_SAFE, both couples' valves closed) and the piston's drift from then to the end of
    the run."""
    from ..estimator.adapt import OK
    from ..redundancy.state_machine import STATE_CODES
    t, code = s['t'], s['fault']
    before = t < p['t_fault'] - 1e-9

    def since(cond) -> float:
        """From the fault to the first tick at or after it where cond holds (inf: none)."""
        i = np.nonzero((~before) & cond)[0]
        return float(t[i[0]] - p['t_fault'] + Ts) if len(i) else math.inf

    said = s['verdict'] != OK
    err = np.abs(s['truth'][~before] - s['reference'][~before])
    safe = s['state'] == STATE_CODES['FAILED_SAFE']
    locked = np.nonzero((~before) & safe & np.all(s['valve'] <= 0.01, axis=0))[0]
    lock = locked[0] if len(locked) else None
    return {'detection_time_s': since(code != 0),
            'false_alarm_ticks': float(np.count_nonzero((code[before] != 0) | safe[before])),
            'report_time_s': since((code != 0) | said),
            'report_ticks_before': float(np.count_nonzero(said[before])),
            'peak_deviation_m': float(np.max(err)) if len(err) else math.nan,
            'safe_state_s': float(t[lock] - p['t_fault'] + Ts) if lock is not None else math.inf,
            'lock_drift_m': float(abs(s['truth'][-1] - s['truth'][lock])) if lock is not None
            else math.nan}


FIGURES = {'step': step_figures, 'load_step': load_step_figures, 'sweep': sweep_figures,
           'stiffness': stiffness_figures, 'sine': sine_figures, 'switch': switch_figures,
           'sensor_fault': sensor_fault_figures, 'motor_fail': motor_fail_figures}


def linear_columns(scn: Scenario) -> bool:
    """Whether the scenario's report and specs use core.sim.linear predictions."""
    return scn.kind in ('sweep', 'stiffness', 'load_step')
