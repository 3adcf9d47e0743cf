"""Batch closed-loop benchmark (issue 10: at least 50 simulated s per wall s): nonlinear plant,
estimator, QFT controller and switch manager in one process (core.sim.batch.BatchLoop, compiled
segments between events), on a Table 3.4-like scenario: 3 Hz 3 mm sine, 10 kN load step at
1 s, commanded switch A -> B at 30 % of the run, motor_fail on B at 60 % (automatic switch
back to A): at the default 10 s, 3 s and 6 s.

Reported (flat keys, SI units): simulated s per wall s and per CPU s of this process (min /
median / max over repeats; the machine is shared, see load_avg_*), us per tick, the
compile time (cold: a fresh process with an empty numba cache, wall and CPU; warm: loading
the cache), the set-up time (configuration, objects, reference arrays), the
tick-by-tick Python reference path for comparison, and per-component us/tick of the
compiled steppers replaying the recorded run (plant, estimator, controller, switch manager).

``run(args)``: args may carry ``duration`` (simulated s per repeat, default 10), ``repeats``
(default 5), ``cold_compile`` (default True).
"""
from __future__ import annotations

import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from numba import njit

from ..core.controller import stepper as CS
from ..core.estimator import stepper as ES
from ..core.plant import stepper as PS
from ..core.jit_cache import drop_stale
from ..core.redundancy import stepper as RS
from . import arg as _arg

drop_stale(__file__, '../core/sim', '../core/plant', '../core/estimator', '../core/controller',
           '../core/redundancy', '../core/loop')


def scenario(duration: float):
    from ..core.sim.switchover import Scenario
    return Scenario(duration=duration, commands=[(0.3 * duration, 1, 'bench')],
                    faults=[(0.6 * duration, 'motor_fail', 1, 0.0, 0.0)])


def build(scn):
    """(BatchLoop, references, loads) as core.sim.switchover.run builds them."""
    from ..core.sim.switchover import build as build_scenario
    return build_scenario(scn)


def timed(fn):
    """(result, wall s, CPU s of this process)."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def spread(prefix: str, values) -> dict:
    v = sorted(values)
    return {f'{prefix}_min': v[0], f'{prefix}_median': statistics.median(v),
            f'{prefix}_max': v[-1]}


def cold_compile_s() -> tuple:
    """(wall s, CPU s) of the first closed-loop run in a fresh process with an empty numba
    cache: import, set-up and compiling every kernel."""
    code = ('import time; t0 = time.perf_counter(); '
            'from eha_ros.bench.batch import build, scenario; '
            'loop, r, f = build(scenario(0.05)); loop.run(r, f); '
            'print(time.perf_counter() - t0)')
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=tmp)
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                             text=True, timeout=1800)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise RuntimeError(f'cold compile run failed: {out.stderr.strip()[-300:]}')
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return float(out.stdout.strip().splitlines()[-1]), cpu


def run(args=None) -> dict:
    duration = float(_arg(args, 'duration', 10.0))
    repeats = int(_arg(args, 'repeats', 5))
    res = {'batch_simulated_s': duration, 'batch_repeats': repeats,
           'load_avg_1min_before': os.getloadavg()[0]}
    if _arg(args, 'cold_compile', True):
        res['batch_jit_cold_compile_s'], res['batch_jit_cold_compile_cpu_s'] = cold_compile_s()
    # warm: load the cached kernels (first call per signature), not counted below
    loop, refs, loads = build(scenario(0.05))
    _, res['batch_jit_warm_load_s'], _ = timed(lambda: loop.run(refs, loads))
    walls, cpus, fractions, setups, rec = [], [], [], [], None
    for _ in range(repeats):
        (loop, refs, loads), setup, _ = timed(lambda: build(scenario(duration)))
        setups.append(setup)
        time.sleep(0.2)               # BLAS threads of the set-up (scipy) go idle
        rec, wall, cpu = timed(lambda: loop.run(refs, loads))
        walls.append(wall)
        cpus.append(cpu)
        fractions.append(loop.fast_ticks / len(refs))
        if duration >= 2.0 and [e.kind for e in loop.mgr.events] != ['switch_start',
                                                                     'switch_done'] * 2:
            raise RuntimeError(f'unexpected switch events {[e.kind for e in loop.mgr.events]}')
    n = len(refs)
    res.update(spread('batch_closed_loop_sim_s_per_wall_s', [duration / w for w in walls]))
    res.update(spread('batch_closed_loop_sim_s_per_cpu_s', [duration / c for c in cpus]))
    res.update(spread('batch_closed_loop_us_per_tick', [w / n * 1e6 for w in walls]))
    res['batch_setup_s_median'] = statistics.median(setups)   # config, objects, references
    res['batch_compiled_tick_fraction'] = min(fractions)
    res['batch_python_ticks'] = int(round((1 - min(fractions)) * n))
    # end to end: core.sim.switchover.run (config, objects, references, loop, columns)
    from ..core.sim.switchover import run as run_scenario
    _, wall, cpu = timed(lambda: run_scenario(scenario(duration)))
    res['batch_end_to_end_sim_s_per_wall_s'] = duration / wall
    res['batch_end_to_end_sim_s_per_cpu_s'] = duration / cpu
    # the tick-by-tick Python reference path (shorter)
    short = min(duration, 2.0)
    loop, r, f = build(scenario(short))
    _, wall, cpu = timed(lambda: loop.run(r, f, fast=False))
    res['batch_reference_path_sim_s_per_wall_s'] = short / wall
    res['batch_reference_path_us_per_tick'] = wall / len(r) * 1e6
    res.update(components(rec, refs, loads))
    res['load_avg_1min_after'] = os.getloadavg()[0]
    return res


# ---------------------------------------------------------------------- per component
@njit(cache=True)
def _plant(a, nsub, u, f):
    for k in range(u.shape[0]):
        if PS.noise_exhausted(a):
            a.aux[PS.A_NOISE_K] = 0          # timing only: reuse the block
        PS.step(a, nsub, u[k], f[k])


def components(rec, refs, loads, repeats: int = 3) -> dict:
    """us/tick of each compiled stepper replaying the recorded run (best of ``repeats``)."""
    from ..core.sim.closed_loop import R_CHANNEL, R_IM, R_PM, R_U, R_WM, R_XHAT, R_XM
    loop, _, _ = build(scenario(0.01))
    loop.run(np.zeros(2), np.zeros(2))                     # start estimator and controller
    rc = np.ascontiguousarray(rec.T)
    n = rc.shape[1]
    w_act = np.where(rc[R_CHANNEL] > 0.5, rc[R_WM + 1], rc[R_WM])
    plant = loop.plant
    ek, ee, ea = loop.est.kernel
    ck, cc, ca = CS.pack(loop.ctl)
    mgr = RS.pack(loop.mgr)
    jobs = {
        'plant': lambda: _plant(plant.arrays, plant._nsub, rc[R_U], np.ascontiguousarray(loads)),
        'estimator': lambda: _estimator(ek, ee, ea, rc[R_XM], w_act, rc[R_PM], rc[R_PM + 1]),
        'controller': lambda: _controller(ck, cc, ca, np.ascontiguousarray(refs), rc[R_XHAT],
                                          w_act),
        'switch_manager': lambda: _manager(mgr, rc[R_U], rc[R_WM:R_WM + 2].copy(),
                                           rc[R_IM:R_IM + 2].copy(), rc[R_PM], rc[R_PM + 1]),
    }
    out = {}
    for name, job in jobs.items():
        job()                                              # compile / load
        best = min(timed(job)[1] for _ in range(repeats))
        out[f'batch_component_{name}_us_per_tick'] = best / n * 1e6
    return out


@njit(cache=True)
def _estimator(ek, ee, ea, x, w, pa, pb):
    s = 0.0
    for k in range(x.shape[0]):
        r = ES.estimate(ek, ee, ea, x[k], w[k], math.nan, pa[k], pb[k])
        s += r[0]
    return s


@njit(cache=True)
def _controller(ck, cc, ca, refs, x_hat, w):
    s = 0.0
    for k in range(refs.shape[0]):
        CS.request(ck, cc, refs[k])
        s += CS.control(ck, cc, ca, x_hat[k], w[k], math.nan)
    return s


@njit(cache=True)
def _manager(a, u, w, i, pa, pb):
    wk, ik = np.zeros(2), np.zeros(2)
    reported, fault = np.zeros(2, np.bool_), np.zeros(2, np.bool_)
    steady, cmd, age = np.zeros(2, np.bool_), np.zeros(2, np.bool_), np.zeros(2)
    reported[0] = True
    c = 0
    for k in range(u.shape[0]):
        wk[0], wk[1], ik[0], ik[1] = w[0, k], w[1, k], i[0, k], i[1, k]
        c += RS.supervise(a, k * 1e-3, k, u[k], u[k], True, wk, ik, pa[k], pb[k], reported,
                          fault, 1e-5, True, steady, age, cmd)
    return c


if __name__ == '__main__':
    import json
    print(json.dumps(run({'cold_compile': False}), indent=1))
