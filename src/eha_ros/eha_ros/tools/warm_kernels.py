"""Compile every numba kernel of the stack into its on-disk cache (issue 45: no compile on the
first run). scripts/setup runs it once per change of the code, so the first scripts/run,
run_stack, campaign or identify after set-up loads machine code instead of compiling it.

Each kernel is compiled by running the code path that uses it, for a few ticks, with the
types the stack passes: the closed loop tick by tick (what each node's core object runs) and
in compiled segments (campaigns, batch), with the switch manager, a commanded switch and a
motor fault; the estimator's real-time branches (lost and stale states); the switch manager
node's per-state kernel; the identification's replays. It prints how many kernels numba
compiled (0 when the cache already held them all).

usage: python -m eha_ros.tools.warm_kernels [--quiet]
"""
from __future__ import annotations

import argparse
import sys
import time


def _closed_loop() -> None:
    """Plant, estimator, controller, switch manager: tick by tick, then compiled segments."""
    from ..bench.batch import build, scenario
    loop, refs, loads = build(scenario(0.2))
    loop.run(refs, loads, fast=False)
    loop, refs, loads = build(scenario(0.2))
    loop.run(refs, loads, fast=True)


def _realtime() -> None:
    """The estimator's branches only the wall clock takes: lost states (ticks > 1), a stale
    tick predicted over, an invalid sample, a rejected (NaN) position."""
    from ..core.estimator.estimator import Estimator
    from ..core.estimator.params import SCHEMA
    from ..core.sim.batch import node_params
    est = Estimator(node_params('estimator', SCHEMA))
    for _ in range(20):
        est.update(0.0, (0.0, 0.0), 5e5, 5e5, 0)
    est.update(0.0, (0.0, 0.0), 5e5, 5e5, 0, ticks=3)
    est.predict_only()
    est.update(0.0, (0.0, 0.0), 5e5, 5e5, 0, valid=False)
    est.update(float('nan'), (0.0, 0.0), 5e5, 5e5, 0)


def _switch_manager_node() -> None:
    """The switch_manager node's per-state kernel (ManagerTick), with a message's types."""
    import numpy as np
    from ..core.redundancy import SwitchManager
    from ..core.redundancy.params import SCHEMA
    from ..core.redundancy.stepper import ManagerTick
    from ..core.sim.batch import node_params
    tick = ManagerTick(SwitchManager(node_params('switch_manager', SCHEMA)), 50)
    for k in range(5):
        tick.command(k, 0.0)
        tick.update(k * 1e-3, k, 0.0, True, np.zeros(2), np.zeros(2), 1e6, 1e6,
                    [True, False], [False, False], 0.0, True)


def _identification() -> None:
    """The drive replay (Kp_w, Ki_w, delay, k_T fits) and the friction curve of eq. 3.33."""
    import numpy as np
    from ..core.ident import drive, friction
    from ..core.ident.dataset import Recording
    from ..core.ident.pipeline import nominal_plant
    p, _ = nominal_plant(None)
    n = 400
    z, z2 = np.zeros(n), np.zeros((n, 2))
    rec = Recording('warm', 'drive', 'sim', {}, p.Ts, np.arange(n), z, z, z2, z2, z, z,
                    np.zeros(n, dtype=int), np.ones(n, dtype=bool), command=np.ones(n))
    drive.simulate(p, rec, 1)
    friction.curve(np.linspace(-0.1, 0.1, n), 450.0, 800.0, 0.01, 1000.0)


PATHS = (('closed loop', _closed_loop), ('real-time branches', _realtime),
         ('switch manager node', _switch_manager_node), ('identification', _identification))


def compiled(fn) -> int:
    """Run fn; the number of kernels numba compiled meanwhile (0: all came from the cache)."""
    from numba.core.event import install_recorder
    with install_recorder('numba:compile') as rec:
        fn()
    return sum(1 for _, e in rec.buffer if e.is_start)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='warm_kernels', description=__doc__.split('\n\n')[0])
    ap.add_argument('--quiet', action='store_true', help='print only the final line')
    args = ap.parse_args(argv)
    t0, total = time.perf_counter(), 0
    for what, fn in PATHS:
        t = time.perf_counter()
        n = compiled(fn)
        total += n
        if not args.quiet:
            print(f'warm_kernels: {what}: {n} compiled in {time.perf_counter() - t:.1f} s')
    print(f'warm_kernels: {total} kernels compiled into the cache in '
          f'{time.perf_counter() - t0:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
