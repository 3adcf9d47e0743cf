"""scripts/bench controller: cost per controller tick (issue 6 goal: at most 50 us).

core_*: PositionController.update (reference shaping, F, G, clamp, anti-windup) in a tight
loop on a 1 Hz, 5 mm sine; node_*: the controller node's whole estimate callback (message in,
command out) as it runs in the composed real-time loop (eha_loop), from its /diagnostics.
"""
from __future__ import annotations

import math
import time

import numpy as np


def core_cost(n: int = 20000) -> dict:
    from ..core.sim.batch import node_params
    from ..core.controller.params import SCHEMA
    from ..core.controller.position import PositionController
    ctl = PositionController.from_params(node_params('controller', SCHEMA))
    ctl.start(0.0)
    cost = np.empty(n)
    x = w = 0.0
    for k in range(n):
        ctl.request(5e-3 * math.sin(2 * math.pi * k * 1e-3))
        t0 = time.perf_counter()
        out = ctl.update(x, w)
        cost[k] = time.perf_counter() - t0
        w = out.speed_ref                              # a motor that follows at once
        x += 2.6e-4 * w * 1e-3                         # a pump-driven piston (D_p/A_p)
    cost = cost[1000:]
    return {'core_mean_s': float(cost.mean()), 'core_p50_s': float(np.percentile(cost, 50)),
            'core_p99_s': float(np.percentile(cost, 99)), 'core_max_s': float(cost.max()),
            'core_ticks': int(cost.size)}


def run(args) -> dict:
    from .stack import measure_stack
    out = core_cost()
    loop = measure_stack(args.duration or 10.0, composed=True)
    out.update({'node_exec_mean_s': loop.get('controller_exec_mean_s'),
                'node_exec_p99_s': loop.get('controller_exec_p99_s'),
                'node_ticks': loop['ticks']})
    out['goal_core_mean_met'] = out['core_mean_s'] <= 50e-6
    return out
