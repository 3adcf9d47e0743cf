"""Benchmark of the nonlinear EHA plant alone in batch (no ROS): simulated s per wall s.

``run(args)`` returns flat keys in SI units. args may be None or carry ``duration`` (s of
simulated time per repeat, default 5), ``repeats`` (default 5) and ``substeps`` (default 16).
Scenario: 300 rad/s 2 Hz sine speed reference and a 5 kN 0.5 Hz sine load (Stribeck friction,
reversals), then the same with the Table 3.8 PID closed on the measured position.
"""
from __future__ import annotations

import math
import os
import time


def _get(args, name, default):
    if args is None:
        return default
    if isinstance(args, dict):
        return args.get(name, default)
    value = getattr(args, name, None)
    return default if value is None else value


def run(args=None) -> dict:
    from ..core.pid import PID
    from ..core.plant import EhaPlant
    from ..core.plant.parameters import nominal_plant
    from ..core.plant import layout as L

    duration = float(_get(args, 'duration', 5.0))
    repeats = int(_get(args, 'repeats', 5))
    substeps = int(_get(args, 'substeps', 16))
    params = nominal_plant({'plant.sim.substeps': substeps})
    plant = EhaPlant(params, seed=1)
    n = int(round(duration / plant.Ts))
    w = [300.0 * math.sin(2 * math.pi * 2.0 * k * plant.Ts) for k in range(n)]
    load_f = [5e3 * math.sin(2 * math.pi * 0.5 * k * plant.Ts) for k in range(n)]

    # JIT warm-up (compiled kernels are cached on disk; first call loads or compiles them)
    t0 = time.perf_counter()
    plant.step(0.0)
    warmup = time.perf_counter() - t0
    plant.reset()

    # 1) open loop: step() only; best of `repeats` (the machine is shared: the minimum is
    #    the cost of the code, the median shows the interference)
    walls = []
    for _ in range(repeats):
        plant.reset()
        t0 = time.perf_counter()
        for k in range(n):
            plant.step(w[k], load_f[k])
        walls.append(time.perf_counter() - t0)
    open_wall = min(walls)
    median_wall = sorted(walls)[len(walls) // 2]
    newton = plant.S[L.S_NIT] / (n * substeps)

    # 2) closed loop with the Table 3.8 PID on the measured position + measure() every tick
    plant.reset()
    pid = PID.table_3_8(plant.Ts)
    t0 = time.perf_counter()
    for k in range(n):
        ref = 3e-3 * math.sin(2 * math.pi * 3.0 * k * plant.Ts)
        u = pid.update(ref - plant.measure().position)
        plant.step(u, load_f[k])
    closed_wall = time.perf_counter() - t0

    return {
        'plant_substeps': substeps,
        'plant_substep_s': plant.Ts / substeps,
        'plant_simulated_s': duration,
        'plant_jit_warmup_s': warmup,
        'plant_step_only_sim_s_per_wall_s': duration / open_wall,
        'plant_step_only_us_per_tick': open_wall / n * 1e6,
        'plant_step_only_median_sim_s_per_wall_s': duration / median_wall,
        'plant_newton_iterations_per_substep': newton,
        'plant_closed_loop_sim_s_per_wall_s': duration / closed_wall,
        'plant_closed_loop_us_per_tick': closed_wall / n * 1e6,
        'cpu_count': os.cpu_count(),
    }


if __name__ == '__main__':
    import json
    print(json.dumps(run(None), indent=1))
