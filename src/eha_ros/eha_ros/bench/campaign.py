"""Campaign benchmark (issue 16): the same runs of one scenario on 2 Dask workers
(core.sim.campaign on a LocalCluster) and in this one process (core.sim.campaign.run_chunk,
the batch loop), warm numba cache; speedup = the ratio of their plant-seconds per wall-second,
measured in the same run.

Keys: campaign_plant_s_per_wall_s, single_process_plant_s_per_wall_s, speedup, runs,
plant_s (simulated seconds in all), cluster_start_s (LocalCluster up, workers running),
worker_warmup_s (a new worker's first run: imports and the numba kernels from the disk cache),
first_row_s (from the call to the first finished chunk), campaign_wall_s, single_wall_s.
The timed campaign runs on an already started and warmed-up cluster, as a long campaign
sees it; the cold-start keys say what a fresh cluster adds once.

``run(args)``: args may carry ``duration`` (ignored), ``runs`` (default 270: the thesis family), ``workers`` (2),
``scenario`` ('sine': 30 s runs of the 1 Hz sine).
"""
from __future__ import annotations

import tempfile
import time

import numpy as np

from . import arg as _arg


def run(args) -> dict:
    from ..core.sim import campaign as C
    from ..core.sim import family as F
    from ..core.sim import scenarios as SC
    n, workers = int(_arg(args, 'runs', 270)), int(_arg(args, 'workers', 2))
    name = _arg(args, 'scenario', 'sine')
    scn = SC.load(name)
    fam_all = F.thesis()
    idx = np.linspace(0, len(fam_all['C_eq']) - 1, n).round().astype(int)
    fam = {c: v[idx] for c, v in fam_all.items()}
    nominal = C.nominal_params()
    rows = [dict(run_id=i, seed=1, **{c: float(fam[c][i]) for c in F.COLUMNS})
            for i in range(n)]
    C.run_chunk(scn.as_dict(), nominal, rows[:1])          # compile / load the cache here

    t0 = time.perf_counter()
    client, cluster = C.connect(workers, None)
    start = time.perf_counter() - t0
    try:
        t0 = time.perf_counter()
        client.run(lambda: C.run_chunk(scn.as_dict(), nominal, rows[:1]))   # warm each worker
        warm = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            res = C.run_campaign(name, fam, out=f'{d}/c', client=client, progress=False,
                                 report=False, log=lambda s: None)
            camp_wall = time.perf_counter() - t0
    finally:
        client.close()
        cluster.close()
    plant_s = float(res.results['plant_s'].sum())

    t0 = time.perf_counter()
    out, _ = C.run_chunk(scn.as_dict(), nominal, rows)
    single_wall = time.perf_counter() - t0
    single_plant_s = sum(r['plant_s'] for r in out)
    camp_rate = plant_s / camp_wall
    single_rate = single_plant_s / single_wall
    return {'scenario': name, 'runs': n, 'workers': workers, 'plant_s': plant_s,
            'campaign_plant_s_per_wall_s': round(camp_rate, 2),
            'single_process_plant_s_per_wall_s': round(single_rate, 2),
            'speedup': round(camp_rate / single_rate, 3),
            'campaign_wall_s': round(camp_wall, 3), 'single_wall_s': round(single_wall, 3),
            'first_row_s': res.info['first_row_s'], 'cluster_start_s': round(start, 3),
            'worker_warmup_s': round(warm, 3), 'failed_runs': res.info['failed']}
