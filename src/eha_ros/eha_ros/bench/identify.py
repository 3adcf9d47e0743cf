"""Identification benchmark (issue 43): wall time of the fits alone (drive, friction, leakage),
and of reading, validating and reporting, on one set of recordings of the four experiments.

``run(args)``: args may carry ``recordings`` (paths of the four recordings; scripts/bench
identify --recordings ...); without them the set is simulated first (a plant with C_eq x5,
F_c x1.5, 2 ms drive delay, k_T x0.9, Kp_w x1.2, Ki_w x0.8, default sensor noise) by the
experiments' simulation (tests/ident_experiments.py until core/ident/experiments.py holds it).
Goal: fits under 60 s on the 2-core machine.
"""
from __future__ import annotations

import importlib.util
import os
import tempfile
import time

from . import arg as _arg

CHANGED = {'plant.pump.C_p': 7.5e-12, 'plant.pump.C_r': 1.8e-11, 'plant.cylinder.C_c': 2.5e-12,
           'plant.friction.F_c': 675.0, 'plant.drive.delay': 0.002, 'plant.motor.k_T': 0.657,
           'plant.drive.Kp_w': 1.2 * 0.5855590712981736,
           'plant.drive.Ki_w': 0.8 * 46.228402116038275}


def _experiments():
    """The module that simulates and records the experiments (the repository's tests/)."""
    from ..core.config.cli import UsageError
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(
        os.path.dirname(os.path.abspath(__file__))))))
    path = os.path.join(root, 'tests', 'ident_experiments.py')
    if not os.path.isfile(path):
        raise UsageError(f'{path} not found: give the recordings with --recordings')
    spec = importlib.util.spec_from_file_location('ident_experiments', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(args=None) -> dict:
    from ..core.ident.pipeline import fit_recordings
    paths = _arg(args, 'recordings', None)
    out = {}
    with tempfile.TemporaryDirectory(prefix='bench-identify-') as tmp:
        if not paths:
            t0 = time.perf_counter()
            paths = _experiments().record_set(tmp, CHANGED, seed=3)
            out['simulate_recordings_s'] = time.perf_counter() - t0
        result = fit_recordings(list(paths), os.path.join(tmp, 'out'), log=lambda line: None)
    wall = result['wall_time']
    out.update({f'{key[:-2]}_wall_s': value for key, value in wall.items()})
    out['recordings'] = len(paths)
    out['recorded_s'] = sum(r['duration_s'] for r in result['recordings'].values())
    out['fits_goal_s'] = 60.0
    out['drive_best_fit_evaluations'] = result['fits']['drive']['evaluations']
    return out
