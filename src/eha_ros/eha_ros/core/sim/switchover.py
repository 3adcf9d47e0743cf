"""Batch closed loop with the switch manager (DESIGN.md "three ways", 3): nonlinear plant,
estimator (if available), QFT controller of config/controller.yaml and SwitchManager composed
in one process, in the order of the stack: state(k) -> estimate(k) -> command(k) and channel
select(k) -> applied by the plant at k+1. Table 3.4 scenario helpers and the switch figures."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..redundancy.params import SCHEMA
from ..redundancy.state_machine import STATE_CODES  # noqa: F401 (callers)
from .batch import node_params


def for_node(node: str, overrides: dict | None) -> dict:
    """-p assignments addressed to ``node`` (``key`` -> ``node:key``)."""
    return {k if ':' in k else f'{node}:{k}': v for k, v in (overrides or {}).items()}


def switch_params(overrides: dict | None = None) -> dict:
    """switch_manager parameters from its files in config/ (the node registry's)."""
    return node_params('switch_manager', SCHEMA, overrides=for_node('switch_manager', overrides))


@dataclass
class Scenario:
    """Table 3.4 by default: 3 Hz, 3 mm sine; 10 kN load step at 1 s."""

    duration: float = 4.0
    amplitude: float = 3e-3
    freq: float = 3.0
    load: float = 10e3
    load_time: float = 1.0
    commands: list = field(default_factory=list)   # (t, channel, reason)
    faults: list = field(default_factory=list)     # (t, name, channel, magnitude, duration)
    seed: int = 0

    def reference(self, t: float) -> float:
        return self.amplitude * math.sin(2.0 * math.pi * self.freq * t)


def build(scn: Scenario, overrides: dict | None = None, plant_overrides: dict | None = None,
          use_estimator: bool = True, switch_hold: float | None = None):
    """(BatchLoop, references, loads) of scenario ``scn`` (:func:`run`'s arguments): the loop of
    core.sim.batch.build_loop on config/'s nodes."""
    from .batch import build_loop, nominal_params
    params = nominal_params(overrides={**for_node('plant_sim', plant_overrides),
                                       **for_node('switch_manager', overrides)})
    Ts = params['plant_sim']['plant.sim.Ts']
    n = int(round(scn.duration / Ts))
    refs = np.array([scn.reference(k * Ts) for k in range(n)])
    loads = np.array([scn.load if k * Ts >= scn.load_time - 1e-9 else 0.0 for k in range(n)])
    faults = schedule([(f[0], f[1:]) for f in sorted(scn.faults)], n, Ts)
    commands = schedule([(c[0], c[1:]) for c in sorted(scn.commands)], n, Ts)
    loop = build_loop(params, scn.seed, faults, commands, estimator=use_estimator,
                      switch_hold=switch_hold)
    return loop, refs, loads


def run(scn: Scenario, overrides: dict | None = None, plant_overrides: dict | None = None,
        use_estimator: bool = True, switch_hold: float | None = None, fast: bool = True) -> dict:
    """Closed loop with the switch manager; returns arrays (t, ref, x, x_meas, w[2], w_ref,
    valve[2], enable[2], bypass, active, state codes) plus the manager and the responses.

    switch_hold: the controller's integrator hold on a switch (control.switch_hold, s);
    None = as config/controller_node.yaml says. Like the controller node, the hold starts
    when /eha/redundancy reports SWITCHING or a new active channel.
    fast: compiled segments between events (core.sim.batch.BatchLoop, same numbers); False: every
    tick through the Python objects."""
    from .closed_loop import (R_ACTIVE, R_BYPASS, R_EN, R_I, R_INNOV, R_NIS, R_STATE, R_T,
                              R_U, R_VALVE, R_W, R_WM, R_X, R_XM)
    loop, refs, loads = build(scn, overrides, plant_overrides, use_estimator, switch_hold)
    rec = loop.run(refs, loads, fast=fast).T
    cols = {'t': rec[R_T].copy(), 'x': rec[R_X].copy(), 'x_meas': rec[R_XM].copy(),
            'w_ref': rec[R_U].copy(), 'bypass': rec[R_BYPASS].copy(),
            'nis': rec[R_NIS].copy(), 'innov': rec[R_INNOV].copy(),
            'w': rec[R_W:R_W + 2].copy(), 'w_meas': rec[R_WM:R_WM + 2].copy(),
            'valve': rec[R_VALVE:R_VALVE + 2].copy(), 'i': rec[R_I:R_I + 2].copy(),
            'enable': rec[R_EN:R_EN + 2] > 0.5, 'active': rec[R_ACTIVE].astype(int),
            'state': rec[R_STATE].astype(int)}
    cols['ref'] = np.array([scn.reference(t) for t in cols['t']])
    cols.update(manager=loop.mgr, responses=loop.responses, estimator=loop.est is not None,
                fast_ticks=loop.fast_ticks)
    return cols


def schedule(items, n: int, Ts: float) -> dict:
    """{tick: [payload, ...]} of time-sorted (t, payload) items: each at the first tick k < n
    with t <= k Ts + 1e-9 (what a per-tick loop popping due items does)."""
    out = {}
    for t, payload in items:
        k = max(0, math.ceil((t - 1e-9) / Ts))
        while k > 0 and t <= (k - 1) * Ts + 1e-9:
            k -= 1
        while not t <= k * Ts + 1e-9:
            k += 1
        if k < n:
            out.setdefault(k, []).append(payload)
    return out


def tracking_figures(t, x, ref, t_event: float, period: float, window: float = 0.5,
                     band_window: float = 1.0, band_tolerance: float = 0.05) -> dict:
    """Figures of a disturbance at t_event on a periodic tracking run, from one run only (so
    they can be measured over DDS as well):

    - band: peak |x - ref| in the band_window before t_event (pre-event tracking band);
    - peak_error: peak |x - ref| in [t_event, t_event + window];
    - extra_deviation: peak over the window of |e(t) - e(t - period)|, the error change
      against the same phase one reference period earlier (what the event added);
    - recovery_time: time after t_event of the last sample with |e| above the band widened
      by band_tolerance (5 %: the band is itself a peak of noisy samples; a later peak a few
      um higher is noise, not the event -- measured: 8 um over a 0.67 mm band).
    """
    t, x, ref = (np.asarray(a, float) for a in (t, x, ref))
    e = x - ref
    Ts = float(np.median(np.diff(t)))
    before = (t >= t_event - band_window) & (t < t_event)
    after = (t >= t_event) & (t <= t_event + window)
    band = float(np.max(np.abs(e[before])))
    lag = int(round(period / Ts))
    idx = np.nonzero(after)[0]
    idx = idx[idx >= lag]
    # match by time (seq), not index: tolerate gaps in a DDS recording
    prev = np.interp(t[idx] - period, t, e)
    extra = float(np.max(np.abs(e[idx] - prev))) if len(idx) else float('nan')
    above = np.nonzero(np.abs(e[after]) > band * (1.0 + band_tolerance))[0]
    rec = float(t[after][above[-1]] - t_event + Ts) if len(above) else 0.0
    return {'band_m': band, 'peak_error_m': float(np.max(np.abs(e[after]))),
            'extra_deviation_m': extra, 'recovery_time_s': rec}


def driving_time(t, valve, enable, channel: int, t_event: float) -> float:
    """Time from t_event until couple ``channel`` drives: its drive enabled and its valves at
    least half open (the flow hand-over midpoint)."""
    t = np.asarray(t, float)
    ok = (t >= t_event) & (np.asarray(valve[channel]) >= 0.5) & np.asarray(enable[channel], bool)
    idx = np.nonzero(ok)[0]
    return float(t[idx[0]] - t_event) if len(idx) else float('inf')
