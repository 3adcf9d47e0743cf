"""Batch closed loop with the switch manager (DESIGN.md "three ways", 3): nonlinear plant,
estimator (if available), QFT controller of config/controller.yaml and SwitchManager composed
in one process, in the order of the stack: state(k) -> estimate(k) -> command(k) and channel
select(k) -> applied by the plant at k+1. Table 3.4 scenario helpers and the switch figures."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..params import default_config_dir, load
from ..plant import EhaPlant
from .health import ChannelSample
from .params import SCHEMA, check
from .state_machine import SwitchManager

STATE_CODES = {'ACTIVE_A': 0, 'ACTIVE_B': 1, 'SWITCHING': 2, 'DEGRADED': 3, 'FAILED_SAFE': 4}


def config(name: str) -> str:
    return os.path.join(default_config_dir(), name)


def switch_params(overrides: dict | None = None) -> dict:
    """switch_manager parameters from config/plant.yaml + config/switch_manager.yaml."""
    named = {k if ':' in k else f'switch_manager:{k}': v for k, v in (overrides or {}).items()}
    p = load(SCHEMA, [config('plant.yaml'), config('switch_manager.yaml')], named,
             node='switch_manager')
    check(p)
    return p


def make_controller(Ts: float):
    """The controller node's PositionController from the YAML it loads (not hardcoded)."""
    from ..controller.params import SCHEMA as CSCHEMA
    from ..controller.position import PositionController
    p = load(CSCHEMA, [config('plant.yaml'), config('controller.yaml'),
                       config('controller_node.yaml')], node='controller')
    ctl = PositionController.from_params(p)
    return ctl, int(round(p['control.switch_hold'] / Ts))


def make_estimator():
    """The estimator core from config/estimator.yaml, or None when it cannot be built."""
    try:
        from ..estimator.estimator import Estimator
        from ..estimator.params import SCHEMA as ESCHEMA
        return Estimator(load(ESCHEMA, [config('plant.yaml'), config('estimator.yaml')],
                              node='estimator'))
    except Exception:                       # estimator still being built: loop on measurement
        return None


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


def run(scn: Scenario, overrides: dict | None = None, plant_overrides: dict | None = None,
        use_estimator: bool = True, switch_hold: float | None = None) -> dict:
    """Closed loop with the switch manager; returns arrays (t, ref, x, x_meas, w[2], w_ref,
    valve[2], enable[2], bypass, active, state codes) plus the manager and the responses.

    switch_hold: the controller's integrator hold on a switch (control.switch_hold, s);
    None = as config/controller_node.yaml says. Like the controller node, the hold starts
    when /eha/redundancy reports SWITCHING or a new active channel."""
    from ..plant.parameters import PLANT_SCHEMA
    plant = EhaPlant(load(PLANT_SCHEMA, [config('plant.yaml')], plant_overrides or {}),
                     seed=scn.seed)
    Ts = plant.Ts
    mgr = SwitchManager(switch_params(overrides))
    ctl, hold_ticks = make_controller(Ts)
    if switch_hold is not None:
        hold_ticks = int(round(switch_hold / Ts))
    est = make_estimator() if use_estimator else None
    n = int(round(scn.duration / Ts))
    cols = {k: np.zeros(n) for k in ('t', 'ref', 'x', 'x_meas', 'w_ref', 'bypass', 'nis', 'innov')}
    cols.update({k: np.zeros((2, n)) for k in ('w', 'w_meas', 'valve', 'i')})
    cols['enable'] = np.zeros((2, n), bool)
    cols['active'] = np.zeros(n, int)
    cols['state'] = np.zeros(n, int)
    commands = sorted(scn.commands)
    faults = sorted(scn.faults)
    responses = []
    u = 0.0
    applied = None
    last_status = (mgr.active, mgr.state)
    for k in range(n):
        t = k * Ts
        while faults and faults[0][0] <= t + 1e-9:
            _, name, ch, mag, dur = faults.pop(0)
            responses.append((k, 'fault', plant.inject_fault(name, ch, mag, dur)))
        m = plant.measure()
        if est is not None:
            r = est.update(m.position, m.motor_speed, m.pressure_a, m.pressure_b,
                           m.active_channel)
            x_hat, nis, est_ok = r.position, r.nis, (r.nis_dim > 0 and not r.sensor_fault)
            innov = r.innovation
        else:
            x_hat, nis, est_ok, innov = m.position, float('nan'), False, float('nan')
        ctl.request(scn.reference(t))
        while commands and commands[0][0] <= t + 1e-9:
            _, ch, why = commands.pop(0)
            responses.append((k, 'command', mgr.request(ch, why)))
        s = ChannelSample(t, u, tuple(m.motor_speed), tuple(m.motor_current), m.pressure_a,
                          m.pressure_b, tuple(m.drive_enabled), tuple(m.drive_fault),
                          m.valid, innov, est_ok)
        mgr.update(s, k)
        if mgr.select != applied:              # also after a request() earlier in this tick
            applied = sel = mgr.select
            plant.select(sel.channel, sel.drive_enable, sel.valve_open, sel.bypass_open)
        status = (mgr.active, mgr.state)
        if status != last_status and (status[0] != last_status[0] or mgr.state == 'SWITCHING'):
            ctl.hold_integrator(hold_ticks)      # as the controller node does on /eha/redundancy
        last_status = status
        u = ctl.update(x_hat).speed_ref
        f = scn.load if t >= scn.load_time - 1e-9 else 0.0
        plant.step(u, f)
        tr = plant.truth()
        cols['t'][k] = plant.t
        cols['ref'][k] = scn.reference(plant.t)
        cols['x'][k] = tr.position
        cols['x_meas'][k] = m.position
        cols['w_ref'][k] = u
        cols['w'][:, k] = tr.motor_speed
        cols['w_meas'][:, k] = m.motor_speed
        cols['i'][:, k] = tr.motor_current
        cols['valve'][:, k] = tr.valve_fraction
        cols['bypass'][k] = tr.bypass_fraction
        cols['enable'][:, k] = plant.measure().drive_enabled
        cols['active'][k] = mgr.active
        cols['state'][k] = STATE_CODES[mgr.name]
        cols['nis'][k] = nis
        cols['innov'][k] = innov
    cols.update(manager=mgr, responses=responses, estimator=est is not None)
    return cols


def tracking_figures(t, x, ref, t_event: float, period: float, window: float = 0.5,
                     band_window: float = 1.0) -> dict:
    """Figures of a disturbance at t_event on a periodic tracking run, from one run only (so
    they can be measured over DDS as well):

    - band: peak |x - ref| in the band_window before t_event (pre-event tracking band);
    - peak_error: peak |x - ref| in [t_event, t_event + window];
    - extra_deviation: peak over the window of |e(t) - e(t - period)|, the error change
      against the same phase one reference period earlier (what the event added);
    - recovery_time: time after t_event of the last sample with |e| above the band.
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
    above = np.nonzero(np.abs(e[after]) > band)[0]
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
