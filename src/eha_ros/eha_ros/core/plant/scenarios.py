"""Batch closed-loop scenarios on the nonlinear plant: Table 3.8 position PID (tests, bench).

Ordering per tick like the stack: read position(k) -> PID -> plant.step(command(k)).
"""
from __future__ import annotations

import math

import numpy as np

from ..config.params import load
from ..controller.pid import PID
from .model import EhaPlant
from .parameters import PLANT_SCHEMA, plant_file


def make_plant(overrides: dict | None = None, files=(), seed: int = 0) -> EhaPlant:
    """EhaPlant from config/plant.yaml (or the given files) plus overrides (dotted keys)."""
    return EhaPlant(load(PLANT_SCHEMA, list(files) or [plant_file()], overrides or {}),
                    seed=seed)


def closed_loop(plant: EhaPlant, duration: float, reference, load_force=None, events=None,
                use_truth: bool = True, pid: PID | None = None) -> dict:
    """Run the Table 3.8 PID around the plant for ``duration`` s.

    reference(t) and load_force(t) are callables of the tick start time; events maps a tick
    index to a callable(plant) (e.g. a channel switch). Returns arrays t, ref, x (true),
    x_meas, w (2, n), i (2, n), p_a, p_b, load.
    """
    pid = pid or PID.table_3_8(plant.Ts, plant.p.omega_max)
    n = int(round(duration / plant.Ts))
    events = events or {}
    out = {k: np.empty(n) for k in ('t', 'ref', 'x', 'x_meas', 'p_a', 'p_b', 'load', 'u')}
    out['w'] = np.empty((2, n))
    out['i'] = np.empty((2, n))
    for k in range(n):
        t = plant.t
        if k in events:
            events[k](plant)
        r = reference(t)
        y = plant.position if use_truth else plant.measure().position
        u = pid.update(r - y)
        f = load_force(t) if load_force is not None else 0.0
        plant.step(u, f)
        tr = plant.truth()
        out['t'][k] = plant.t
        out['ref'][k] = r
        out['x'][k] = tr.position
        out['x_meas'][k] = plant.measure().position
        out['p_a'][k] = tr.pressure_a
        out['p_b'][k] = tr.pressure_b
        out['load'][k] = f
        out['u'][k] = u
        out['w'][:, k] = tr.motor_speed
        out['i'][:, k] = tr.motor_current
    return out


def switch_to(channel: int):
    """Event: enable drive ``channel`` + open its valves, close the other's, disable it."""
    def act(plant: EhaPlant):
        en = (channel == 0, channel == 1)
        plant.select(channel, drive_enable=en, valve_open=en)
    return act


def table_3_4(overrides: dict | None = None, switch: bool = True, duration: float = 4.0,
              seed: int = 0) -> dict:
    """Table 3.4: 3 Hz, 3 mm sine; 10 kN load step at 1 s; channel 0 -> 1 switch at 3 s."""
    plant = make_plant(overrides, seed=seed)
    ref = lambda t: 3e-3 * math.sin(2 * math.pi * 3.0 * t)      # noqa: E731
    load_f = lambda t: 10e3 if t >= 1.0 - 1e-9 else 0.0         # noqa: E731
    events = {int(round(3.0 / plant.Ts)): switch_to(1)} if switch else {}
    return closed_loop(plant, duration, ref, load_f, events)


def switch_figures(run_switch: dict, run_ref: dict, t_switch: float = 3.0) -> dict:
    """Figures of merit of the switch: RMS tracking error in the second before the switch and
    in the last second, and the peak extra deviation caused by the switch (max |x_switch -
    x_no_switch| after t_switch) with the time it stays above 0.1 mm."""
    t = run_switch['t']
    e = run_switch['x'] - run_switch['ref']
    before = (t > t_switch - 1.0) & (t <= t_switch)
    last = t > t[-1] - 1.0
    after = t > t_switch
    diff = np.abs(run_switch['x'] - run_ref['x'])[after]
    above = np.nonzero(diff > 1e-4)[0]
    settle = (above[-1] + 1) * (t[1] - t[0]) if len(above) else 0.0
    return {
        'rms_error_before_switch_m': float(np.sqrt(np.mean(e[before] ** 2))),
        'rms_error_last_second_m': float(np.sqrt(np.mean(e[last] ** 2))),
        'peak_extra_deviation_m': float(diff.max()),
        'switch_settle_time_s': float(settle),
    }
