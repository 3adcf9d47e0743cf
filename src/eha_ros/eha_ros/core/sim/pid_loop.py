"""The thesis' Table 3.8 position PID (core.controller.pid) in the one closed-loop harness
(BatchLoop, DESIGN.md "three ways", 3): around the plant alone on the true position, for the
plant's checks of ch. 3 (Tables 3.4, 3.8), and on the estimate, as the controller does on the
bench, for the estimator's figures of ch. 4. Used by the tests and the benchmark."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.params import load
from ..controller.pid import PID, PIDLoop
from ..estimator.estimator import Estimator
from ..plant import EhaPlant
from ..plant.parameters import PLANT_SCHEMA, plant_file
from .batch import BatchLoop
from .closed_loop import (R_FAULT, R_I, R_INNOV, R_NIS, R_NISDIM, R_P, R_SKIP, R_T, R_U, R_V0,
                          R_VERDICT, R_VHAT, R_W, R_X, R_X0, R_XHAT, R_XM)


def make_plant(overrides: dict | None = None, files=(), seed: int = 0) -> EhaPlant:
    """EhaPlant from config/plant.yaml (or the given files) plus overrides (dotted keys)."""
    return EhaPlant(load(PLANT_SCHEMA, list(files) or [plant_file()], overrides or {}),
                    seed=seed)


def plant_loop(plant: EhaPlant, duration: float, reference, load_force=None, events=None,
               use_truth: bool = True, pid: PID | None = None) -> dict:
    """Run the Table 3.8 PID around the plant for ``duration`` s (BatchLoop without
    estimator: on the true position, or on the measured one).

    reference(t) and load_force(t) are callables of the tick start time; events maps a tick
    index to a callable(plant) (e.g. a channel switch). Returns arrays t, ref, x (true), w
    (2, n), i (2, n), p_a, p_b (true, after each tick), load, u.
    """
    pid = pid or PID.table_3_8(plant.Ts, plant.p.omega_max)
    n = int(round(duration / plant.Ts))
    # the plant's clock at each tick start (it adds Ts per tick)
    t = np.add.accumulate(np.concatenate(([plant.t], np.full(n - 1, plant.Ts))))
    ref = np.array([reference(tk) for tk in t])
    load = np.array([load_force(tk) if load_force is not None else 0.0 for tk in t])
    loop = BatchLoop(plant, None, PIDLoop(pid), on_truth=use_truth,
                     events={k: [e] for k, e in (events or {}).items()})
    rec = loop.run(ref, load, fast=False).T
    return {'t': rec[R_T].copy(), 'ref': ref, 'x': rec[R_X].copy(), 'p_a': rec[R_P].copy(),
            'p_b': rec[R_P + 1].copy(), 'load': load, 'u': rec[R_U].copy(),
            'w': rec[R_W:R_W + 2].copy(), 'i': rec[R_I:R_I + 2].copy()}


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
    return plant_loop(plant, duration, ref, load_f, events)


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


@dataclass
class Run:
    t: np.ndarray            # s
    reference: np.ndarray    # m
    truth: np.ndarray        # m
    measured: np.ndarray     # m
    estimate: np.ndarray     # m
    velocity: np.ndarray     # m/s (truth)
    velocity_est: np.ndarray
    innovation: np.ndarray   # m
    nis: np.ndarray
    nis_dim: np.ndarray
    fault: np.ndarray        # sensor_fault codes
    skipped: np.ndarray      # bool
    consistency: np.ndarray  # adapt verdicts (OK, MODEL, DISAGREE, SENSOR)


def estimator_loop(params: dict, reference, duration: float, seed: int = 1,
                   faults=(), estimator: Estimator | None = None) -> Run:
    """The Table 3.8 PID on the estimate (BatchLoop with the estimator) for ``duration`` s,
    sample k taken after the plant's k-th tick (the first with zero command);
    ``reference(t)`` (m) or an array per tick; ``faults`` are (time_s, name, magnitude)
    injected into the plant's sensors at that time (they show from the next sample). A
    consistency verdict that calls for the safe state (core.loop.safe_state) holds the command
    at zero, as the stack's controller does."""
    plant = EhaPlant(params, seed=seed)
    est = estimator or Estimator(params)
    n = int(round(duration / plant.Ts))
    t = np.arange(n) * plant.Ts
    ref = np.asarray(reference(t), float) if callable(reference) else np.asarray(reference)
    # a fault due at sample k is injected before the tick that leads to it: BatchLoop tick k-1
    ticks = {}
    for time_s, name, magnitude in sorted(faults):
        k = int(np.searchsorted(t, time_s, side='left'))
        ticks.setdefault(k - 1, []).append((name, 0, magnitude, 0.0))
    for f in ticks.pop(-1, ()):
        plant.inject_fault(*f)
    plant.step(0.0)
    loop = BatchLoop(plant, est, PIDLoop(PID.table_3_8(plant.Ts)), faults=ticks)
    rec = loop.run(ref, fast=False).T
    return Run(t, ref, truth=rec[R_X0].copy(), measured=rec[R_XM].copy(),
               estimate=rec[R_XHAT].copy(), velocity=rec[R_V0].copy(),
               velocity_est=rec[R_VHAT].copy(), innovation=rec[R_INNOV].copy(),
               nis=rec[R_NIS].copy(), nis_dim=rec[R_NISDIM].astype(int),
               fault=rec[R_FAULT].astype(int), skipped=rec[R_SKIP].astype(bool),
               consistency=rec[R_VERDICT].astype(int))


def sine(amplitude: float, freq: float):
    return lambda t: amplitude * np.sin(2.0 * np.pi * freq * t)


def phase_deg(signal: np.ndarray, ref: np.ndarray, freq: float, t: np.ndarray) -> float:
    """Phase of ``signal`` relative to ``ref`` at ``freq`` (single-bin DFT, whole periods)."""
    e = np.exp(-2j * np.pi * freq * t)
    return float(np.degrees(np.angle(np.sum(signal * e) / np.sum(ref * e))))
