"""Campaign benchmark (issue 16): the same runs of one scenario on 2 Dask workers
(core.sim.campaign on a LocalCluster) and in this one process (core.sim.campaign.run_chunk,
the batch loop), warm numba cache; speedup = the ratio of their plant-seconds per wall-second,
measured in the same run.

Both are measured ``repeats`` times in turns (the whole campaign, then every third of its
plants in one process started for it, as a plain ``python``), because on a shared machine one stretch can be 20 % slower than the
next; the rates are the medians over the repeats.

Keys: campaign_plant_s_per_wall_s, single_process_plant_s_per_wall_s, speedup (ratio of the
medians), speedup_each (each repeat's pair), runs, plant_s (simulated seconds of one campaign),
cluster_start_s (LocalCluster up, workers running), worker_warmup_s (a new worker's first run:
imports and the numba kernels from the disk cache), first_row_s (from the call to the first
finished chunk), campaign_wall_s, single_wall_s_per_run.
The timed campaign runs on an already started and warmed-up cluster, as a long campaign
sees it; the cold-start keys say what a fresh cluster adds once.

``run(args)``: args may carry ``duration`` (ignored), ``runs`` (default 270: the thesis
family), ``workers`` (2), ``scenario`` ('sine': 30 s runs of the 1 Hz sine), ``repeats`` (3).
"""
from __future__ import annotations

import tempfile
import time

import numpy as np

from . import arg as _arg

SUBSET = 3          # the single process runs every third plant of the campaign each repeat


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

    reps = int(_arg(args, 'repeats', 3))
    # the single process is a process of its own, as a worker is: in this one the client's
    # scheduler and nannies would take the GIL from it (what QUIET_WORKER measures)
    import multiprocessing as mp
    C.one_thread_env()
    conn, child = mp.get_context('spawn').Pipe()
    proc = mp.get_context('spawn').Process(target=_single_process,
                                           args=(child, scn.as_dict(), nominal), daemon=True)
    proc.start()
    conn.send(rows[:1])
    conn.recv()                                              # imports and kernels loaded
    t0 = time.perf_counter()
    client, cluster = C.connect(workers, None)
    start = time.perf_counter() - t0
    camp, single, first = [], [], []
    try:
        t0 = time.perf_counter()
        client.run(lambda: C.run_chunk(scn.as_dict(), nominal, rows[:1]))   # warm each worker
        warm = time.perf_counter() - t0
        for rep in range(reps):
            # in turns, so a slower stretch of a shared machine hits both sides alike
            with tempfile.TemporaryDirectory() as d:
                t0 = time.perf_counter()
                res = C.run_campaign(name, fam, out=f'{d}/c', client=client, progress=False,
                                     report=False, log=lambda s: None)
                wall = time.perf_counter() - t0
            camp.append((float(res.results['plant_s'].sum()), wall))
            first.append(res.info['first_row_s'])
            conn.send(rows[rep % SUBSET::SUBSET])
            single.append(conn.recv())
            print(f'bench campaign: repeat {rep + 1}/{reps}: campaign '
                  f'{camp[-1][0] / camp[-1][1]:.1f}, single process '
                  f'{single[-1][0] / single[-1][1]:.1f} plant-s per wall-s', flush=True)
    finally:
        conn.send(None)
        proc.join(10)
        client.close()
        cluster.close()
    camp_rate = float(np.median([p / w for p, w in camp]))
    single_rate = float(np.median([p / w for p, w in single]))
    return {'scenario': name, 'runs': n, 'workers': workers, 'repeats': reps,
            'plant_s': camp[0][0],
            'campaign_plant_s_per_wall_s': round(camp_rate, 2),
            'single_process_plant_s_per_wall_s': round(single_rate, 2),
            'speedup': round(camp_rate / single_rate, 3),
            'speedup_each': [round((pc / wc) / (ps / ws), 3)
                             for (pc, wc), (ps, ws) in zip(camp, single)],
            'campaign_wall_s': round(float(np.median([w for _, w in camp])), 3),
            'single_wall_s_per_run': round(float(np.median([w for _, w in single])) /
                                           len(rows[::SUBSET]), 4),
            'first_row_s': round(float(np.median(first)), 3),
            'cluster_start_s': round(start, 3),
            'worker_warmup_s': round(warm, 3), 'failed_runs': res.info['failed']}


def _single_process(conn, scn_doc: dict, nominal: dict) -> None:
    """The single-process side: run the chunks it is sent, answer (plant_s, wall_s)."""
    from ..core.sim import campaign as C
    while True:
        rows = conn.recv()
        if rows is None:
            return
        t0 = time.perf_counter()
        out, _ = C.run_chunk(scn_doc, nominal, rows)
        conn.send((sum(r['plant_s'] for r in out), time.perf_counter() - t0))
