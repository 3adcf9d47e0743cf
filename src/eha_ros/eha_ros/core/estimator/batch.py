"""Batch closed loop in one process (DESIGN.md "three ways", 3): nonlinear plant, estimator,
and the Table 3.8 position PID (core.controller.pid) closing the loop on the estimate, as the
controller does on the bench. Used by the tests and the benchmark."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..controller.pid import PID
from ..plant import EhaPlant
from .estimator import Estimator


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


def closed_loop(params: dict, reference, duration: float, seed: int = 1,
                faults=(), estimator: Estimator | None = None) -> Run:
    """Run ``duration`` s. ``reference(t)`` (m) or an array per tick; ``faults`` are
    (time_s, name, magnitude) injected into the plant's sensors at that time."""
    plant = EhaPlant(params, seed=seed)
    est = estimator or Estimator(params)
    pid = PID.table_3_8(plant.Ts)
    n = int(round(duration / plant.Ts))
    t = np.arange(n) * plant.Ts
    ref = np.asarray(reference(t), float) if callable(reference) else np.asarray(reference)
    cols = {k: np.zeros(n) for k in ('truth', 'measured', 'estimate', 'velocity',
                                      'velocity_est', 'innovation', 'nis')}
    nis_dim = np.zeros(n, int)
    fault = np.zeros(n, int)
    skipped = np.zeros(n, bool)
    verdict = np.zeros(n, int)
    pending = sorted(faults)
    u = 0.0
    for k in range(n):
        while pending and pending[0][0] <= t[k]:
            _, name, mag = pending.pop(0)
            plant.inject_fault(name, 0, mag, 0.0)
        plant.step(u)
        m = plant.measure()
        r = est.update(m.position, m.motor_speed, m.pressure_a, m.pressure_b,
                       m.active_channel)
        u = pid.update(ref[k] - r.position)
        cols['truth'][k] = plant.position
        cols['measured'][k] = m.position
        cols['estimate'][k] = r.position
        cols['velocity'][k] = plant.S[plant_v_index()]
        cols['velocity_est'][k] = r.velocity
        cols['innovation'][k] = r.innovation
        cols['nis'][k] = r.nis
        nis_dim[k] = r.nis_dim
        fault[k] = r.sensor_fault
        skipped[k] = r.update_skipped
        verdict[k] = r.consistency
    return Run(t, ref, nis_dim=nis_dim, fault=fault, skipped=skipped, consistency=verdict, **cols)


def plant_v_index() -> int:
    from ..plant import layout
    return layout.S_V


def sine(amplitude: float, freq: float):
    return lambda t: amplitude * np.sin(2.0 * np.pi * freq * t)


def phase_deg(signal: np.ndarray, ref: np.ndarray, freq: float, t: np.ndarray) -> float:
    """Phase of ``signal`` relative to ``ref`` at ``freq`` (single-bin DFT, whole periods)."""
    e = np.exp(-2j * np.pi * freq * t)
    return float(np.degrees(np.angle(np.sum(signal * e) / np.sum(ref * e))))
