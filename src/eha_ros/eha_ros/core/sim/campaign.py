"""Campaigns: one scenario over a plant family, on Dask distributed (scripts/campaign).

Only the plant varies; estimator, controller and switch manager keep the nominal parameters
of config/ (as on a bench whose actuator differs from its datasheet). The client loads every
parameter file, the family and the linear predictions, and ships them with each task, so a
worker needs only the installed package, not the same config/ folder.

Engine: a ``distributed.LocalCluster`` with one single-threaded worker process per core by
default (numba kernels cached on disk, so a warm worker starts in seconds), or any running
Dask scheduler (``scheduler='tcp://host:8786'``). Tasks carry chunks of plants. A worker that
dies loses only the chunk it was running, which the scheduler gives to another worker. Each
finished chunk is written at once to DIR/parts/ (rows as Parquet, traces as npz), so an
interrupted campaign keeps what it has and ``resume=DIR`` runs only the rest.

Output in DIR: results.parquet (one row per plant and seed), traces.npz, campaign.json,
report.md with its figures (core.sim.report).
"""
from __future__ import annotations

import glob
import json
import math
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from ..config.cli import UsageError
from ..config.params import ParamError
from ..io.ports import is_free
from ..io.report import write_json
from ..qft.spec import configured_spec
from . import family as FAM
from .batch import nominal_params
from . import scenarios as SC

NODES = SC.NODES
MULT = FAM.COLUMNS
ID_COLUMNS = ('run_id',) + MULT + ('seed', 'noise_seed')
TUNING_SEEDS = tuple(range(1, 6))        # tuning (tune_estimator, gates, thresholds) reads these
RECORD_SEEDS = tuple(range(101, 106))    # figures of record: seeds no tuning has read


def seed_role(seed: int) -> str:
    """'held-out' (RECORD_SEEDS: a figure of record), 'tuning' (TUNING_SEEDS) or 'other'."""
    return 'held-out' if seed in RECORD_SEEDS else 'tuning' if seed in TUNING_SEEDS else 'other'


@dataclass
class CampaignResult:
    out_dir: str
    info: dict            # what campaign.json holds
    results: object       # pandas.DataFrame, one row per run

    @property
    def passed(self) -> int:
        return int(self.info['passed'])

    @property
    def failed(self) -> int:
        return int(self.info['failed'])


def centre(path: str, config_dir: str | None = None) -> dict:
    """{'plant_sim:key': value} of the plant.* keys a params file sets (an identified plant):
    the scenario overrides that make it the family's centre; one-line UsageError."""
    from ..hardware.sim_params import plant_file
    try:
        return {f'plant_sim:{k}': v for k, v in plant_file(path, config_dir).items()}
    except ParamError as err:
        raise UsageError(f'--plant-params: {err}') from None


def run_chunk(scn_doc: dict, nominal: dict, rows: list, trace: bool = True):
    """Worker task: the runs of one chunk. rows: dicts with ID_COLUMNS and any extra per-plant
    columns (linear predictions). Returns (row dicts with figures, traces or None)."""
    import traceback
    scn = SC.from_saved(scn_doc)
    out, traces = [], []
    for row in rows:
        t0 = time.perf_counter()
        r = dict(row)
        try:
            figs, tr = SC.run(scn, nominal, row, int(row['noise_seed']), trace=trace)
            r.update(figs)
            r['passed'], r['failed_specs'] = SC.judge(r, scn.specs)
            r['error'] = ''
        except Exception as err:        # a run that raises is a failed row, not a lost chunk
            tr = None
            r.update(passed=False, failed_specs='error',
                     error=f'{type(err).__name__}: {err} '
                           f'[{traceback.extract_tb(err.__traceback__)[-1].name}]')
        r['wall_s'] = time.perf_counter() - t0
        out.append(r)
        traces.append(tr)
    return out, traces


def noise_seed(seed: int, run_id: int) -> int:
    """The noise seed of run ``run_id`` of a campaign with seed ``seed``: one independent
    stream per run (numpy's SeedSequence with the run as its spawn key), so no two plants of a
    campaign share a noise realization and the pair (seed, run) reproduces the run."""
    seq = np.random.SeedSequence(int(seed), spawn_key=(int(run_id),))
    return int(seq.generate_state(1, np.uint64)[0] >> np.uint64(1))    # 63 bits: int64 column


def linear_columns(scn, fam: dict, nominal: dict, config_dir: str | None = None) -> dict:
    """Per-plant columns of core.sim.linear for the scenario's specs and report: ``lin_*`` of
    each plant with eq. 3.22's leakage; for a held load (load_step, stiffness) also
    ``loaded_C_eq`` (the C_eq multiplier at the operating point of the scenario's force,
    linear.operating_leakage), ``loaded_beyond_table`` (that multiplier leakier than Table
    4.5's leakiest plant, config/qft_spec.yaml) and ``lin_loaded_*`` (the linear loop of that
    plant)."""
    from . import linear
    scales = np.column_stack([fam[c] for c in FAM.NAMES])
    p = scn.params
    kw = dict(plant=nominal['plant_sim'], controller=nominal['controller'],
              load_step_n=p.get('force', 5e3))
    out = linear.predict(scales, freqs_hz=p.get('freqs', linear.FREQS_HZ),
                         stiff_freqs_hz=p.get('freqs', linear.STIFF_FREQS_HZ), **kw)
    if scn.kind in ('load_step', 'stiffness'):
        c = linear.loaded_C_eq(nominal['plant_sim'], fam, p['force'])
        hi = configured_spec(config_dir)['family.C_eq_range'][1]
        out['loaded_C_eq'] = c
        out['loaded_beyond_table'] = c > hi * (1 + 1e-9)
        scales[:, 0] = c
        loaded = linear.predict(scales, freqs_hz=(), stiff_freqs_hz=p.get('freqs', ()),
                                load_step=scn.kind == 'load_step', **kw)
        out.update({k.replace('lin_', 'lin_loaded_', 1): v for k, v in loaded.items()})
    return {k: (np.asarray(v, bool) if k == 'loaded_beyond_table' else np.asarray(v, float))
            for k, v in out.items()}


def plant_limits(scn, multipliers: dict, nominal: dict | None = None,
                 config_dir: str | None = None) -> tuple[dict, dict]:
    """The scenario's spec limits on ONE plant (multipliers of core.sim.family.COLUMNS, a
    missing one nominal), as a campaign judges that plant: ({metric: ('max' | 'min', limit)},
    its linear columns (linear_columns) the relative specs resolve against)."""
    nominal = nominal_params(config_dir) if nominal is None else nominal
    fam = {c: np.array([float(multipliers.get(c, 1.0))]) for c in MULT}
    lin = {k: v[0].item() for k, v in linear_columns(scn, fam, nominal, config_dir).items()}
    return {m: SC.limit(spec, lin) for m, spec in scn.specs.items()}, lin


# ------------------------------------------------------------------------------ engine
# A campaign worker computes: its event loop thread wakes less (statistical profiler every
# 10 ms, loop tick every 20 ms, system monitor every 0.5 s by default), each wake taking the
# GIL from the run. Measured on 1 worker, the same 30 runs in turns as a task and inside the
# worker's loop: the task took 7.5 % longer with the defaults, 0 % with these. The nannies'
# memory check and work stealing run in the client's process, which shares the cores (the
# guided chunks balance the load without stealing; a dead worker's chunk is still retried).
QUIET_WORKER = {'distributed.worker.profile.enabled': False,
                'distributed.admin.tick.interval': '1s',
                'distributed.admin.system-monitor.interval': '2s',
                'distributed.worker.memory.monitor-interval': '1s',
                'distributed.scheduler.work-stealing': False}


def one_thread_env() -> None:
    """One core per worker process: BLAS and numba single-threaded in the processes started
    from here on (they inherit the environment)."""
    for var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
                'NUMBA_NUM_THREADS'):
        os.environ.setdefault(var, '1')


def connect(workers: int | None, scheduler: str | None, quiet: bool = False):
    """(client, cluster or None): a LocalCluster of ``workers`` single-threaded processes, or
    a client of the running scheduler at ``scheduler``; UsageError when it cannot be reached."""
    import logging

    import dask
    from distributed import Client, LocalCluster
    logging.getLogger('distributed').setLevel(logging.ERROR)
    if scheduler:
        try:
            return Client(scheduler, timeout='10s'), None
        except (OSError, TimeoutError, ValueError) as err:
            raise UsageError(f'scheduler {scheduler}: cannot connect '
                             f'({str(err).splitlines()[0][:160]})')
    n = int(workers or os.cpu_count() or 1)
    if n < 1:
        raise UsageError(f'--workers {workers}: expected at least 1')
    one_thread_env()
    # Ctrl-C on a terminal reaches the whole process group: the workers (and their nannies)
    # start with SIGINT ignored, so only this process reacts (keeps the rows, closes them)
    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        with dask.config.set(QUIET_WORKER):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=':8787' if is_free(8787) else ':0',
                                   silence_logs=logging.ERROR)
    finally:
        if main:
            signal.signal(signal.SIGINT, old)
    return Client(cluster), cluster


def _silence_distributed() -> None:
    import logging
    logging.getLogger('distributed').setLevel(logging.CRITICAL)


def quiet_shutdown(client) -> None:
    """Before our own LocalCluster closes: its workers stop logging, so a heartbeat on a comm
    the closing scheduler already dropped ('... is closed', an ERROR with a Traceback from
    distributed.comm.tcp, seen after Ctrl-C) does not reach the CLI's stderr. Runs' errors are
    rows (run_chunk) and a dead worker raises in the client, so nothing else is lost."""
    try:
        client.run(_silence_distributed, wait=True)
    except Exception:             # a worker already gone: nothing of it left to silence
        pass


def disconnect(client, cluster) -> None:
    """Close what :func:`connect` opened: the client, and a LocalCluster of our own quietly
    (:func:`quiet_shutdown`)."""
    if cluster is not None:
        quiet_shutdown(client)
    client.close()
    if cluster is not None:
        cluster.close()


def chunks(ids: list, n_workers: int, size: int | None = None) -> list:
    """Split run ids into chunks, largest first (guided scheduling): each about a quarter of
    the remaining runs per worker, at most 8 (a lost worker costs little) and down to 1 at
    the end, so no worker idles long while another finishes a big last chunk."""
    out, i = [], 0
    while i < len(ids):
        k = size or max(1, min(8, math.ceil((len(ids) - i) / max(1, 4 * n_workers))))
        out.append(ids[i:i + k])
        i += k
    return out


class Progress:
    """Runs done, failures so far and ETA: a tqdm bar on a terminal, a line every 10 % or
    15 s otherwise (logs, CI)."""

    def __init__(self, total: int, done: int, label: str, enabled: bool = True):
        self.total, self.done, self.failed = total, done, 0
        self.t0, self.last = time.monotonic(), 0.0
        self.label, self.enabled = label, enabled
        self.bar = None
        self.start_done = done
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, initial=done, desc=label, unit='run',
                            file=sys.stderr, dynamic_ncols=True)

    def update(self, n: int, failed: int):
        self.done += n
        self.failed += failed
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(n)
            self.bar.set_postfix(failed=self.failed)
            return
        now = time.monotonic() - self.t0
        step = max(1, self.total // 10)
        if (self.done // step != (self.done - n) // step or now - self.last >= 15.0
                or self.done == self.total):
            self.last = now
            rate = (self.done - self.start_done) / now if now > 0 else 0.0
            eta = (self.total - self.done) / rate if rate > 0 else math.inf
            tail = f', ETA {eta:.0f} s' if math.isfinite(eta) else ''
            print(f'{self.label}: {self.done}/{self.total} runs, {self.failed} failed, '
                  f'{now:.0f} s{tail}', file=sys.stderr, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()


# ------------------------------------------------------------------------------ output
def _write_part(parts: str, rows: list, traces: list) -> None:
    """One finished chunk: parts/chunk-<first run id>.parquet (+ .npz of its traces); written
    under a temporary name and renamed, so a part is whole or absent."""
    import pandas as pd
    index = int(rows[0]['run_id'])
    tmp = os.path.join(parts, f'.chunk-{index:06d}.tmp')
    pd.DataFrame(rows).to_parquet(tmp + '.parquet', index=False)
    good = [(r['run_id'], tr) for r, tr in zip(rows, traces) if tr is not None]
    if good:
        np.savez(tmp + '.npz', run_id=np.array([g[0] for g in good]),
                 **{k: np.array([g[1][k] for g in good], dtype=object)
                    for k in good[0][1]})
        os.replace(tmp + '.npz', os.path.join(parts, f'chunk-{index:06d}.npz'))
    os.replace(tmp + '.parquet', os.path.join(parts, f'chunk-{index:06d}.parquet'))


def read_parts(out_dir: str, with_traces: bool = True):
    """(rows DataFrame, [(run_id, trace dict)]) of every finished chunk in DIR/parts."""
    import pandas as pd
    files = sorted(glob.glob(os.path.join(out_dir, 'parts', 'chunk-*.parquet')))
    df = by_run([pd.read_parquet(f) for f in files])
    pairs = []
    for f in sorted(glob.glob(os.path.join(out_dir, 'parts', 'chunk-*.npz'))) \
            if with_traces else ():
        with np.load(f, allow_pickle=True) as z:
            keys = [k for k in z.files if k != 'run_id']
            cols = {k: z[k] for k in keys}
            for i, rid in enumerate(z['run_id']):
                pairs.append((int(rid), {k: cols[k][i] for k in keys}))
    return df, pairs


def by_run(frames: list):
    """One row table of row frames: each run once (the latest), sorted by run id."""
    import pandas as pd
    frames = [f for f in frames if len(f)]
    if not frames:
        return pd.DataFrame()
    df = pd.concat(frames, ignore_index=True).drop_duplicates('run_id', keep='last')
    return df.sort_values('run_id').reset_index(drop=True)


def merge_traces(pairs: list):
    """One {'t', 'run_id', signal: (N, M)} of (run_id, trace) pairs, sorted by run id, cut to
    the shortest trace (runs of one scenario have the same length)."""
    pairs = sorted({rid: tr for rid, tr in pairs if tr is not None}.items())
    if not pairs:
        return None
    m = min(len(tr['t']) for _, tr in pairs)
    out = {'t': np.asarray(pairs[0][1]['t'][:m], float),
           'run_id': np.array([rid for rid, _ in pairs])}
    for k in pairs[0][1]:
        if k != 't':
            out[k] = np.array([np.asarray(tr[k][:m], float) for _, tr in pairs])
    return out


def default_out(scenario: str, family: str) -> str:
    stamp = time.strftime('%Y%m%d-%H%M%S')
    fam = family if not os.path.exists(family) else os.path.splitext(os.path.basename(family))[0]
    return os.path.join('out', 'campaign', f'{scenario}-{fam.replace(":", "")}-{stamp}')


# ------------------------------------------------------------------------------ API
def run_campaign(scenario: str | None = None, family: str | dict = 'thesis', seed: int = 1,
                 workers: int | None = None, scheduler: str | None = None,
                 out: str | None = None, resume: str | None = None, client=None,
                 config_dir: str | None = None, progress: bool = True, report: bool = True,
                 chunk_size: int | None = None, trace: bool = True,
                 log=print, plant_params: str | None = None,
                 oracle: bool = False) -> CampaignResult:
    """Run ``scenario`` (name in config/campaigns/ or a YAML path) on ``family`` ('thesis',
    'random:N' or a CSV/Parquet of multipliers) with campaign seed ``seed``: each run draws
    its own noise from (seed, run id) (:func:`noise_seed`); random:N is drawn with it.

    workers/scheduler choose the engine (a LocalCluster of ``workers`` processes, default one
    per core; or the Dask scheduler at ``scheduler``); ``client`` reuses an existing
    distributed.Client. ``resume=DIR`` finishes an interrupted campaign in DIR (scenario,
    family and seed are read from it). ``plant_params``: a params file whose plant.* keys (an
    identified plant, core.hardware.sim_params.plant_file) are the family's centre, the plant the
    multipliers scale; kept in the scenario's overrides, so a resume keeps it. ``oracle``: the
    runs' estimator is given the plant parameters (core.sim.oracle; kept in the scenario, as
    is a scenario's own ``oracle: true``). Every user mistake is a UsageError with one line,
    raised before anything is written."""
    import pandas as pd
    t_start = time.monotonic()
    if int(seed) < 0:
        raise UsageError(f'seed {seed}: expected a non-negative integer')
    if resume and plant_params:
        raise UsageError(f'--resume {resume}: the campaign keeps the plant it started with: '
                         f'drop --plant-params')
    if resume and oracle:
        raise UsageError(f'--resume {resume}: the campaign keeps the estimator it started '
                         f'with: drop --oracle')
    if resume:
        info0, fam, scn, seed = _resume_inputs(resume, scenario)
        out, family = resume, info0['family']
    else:
        if not scenario:
            raise UsageError('no scenario given: expected one of '
                             f'{", ".join(SC.available())} or a YAML path')
        scn = SC.load(scenario)
        if plant_params:
            scn.overrides = {**centre(plant_params, config_dir), **scn.overrides}
        scn.oracle = scn.oracle or oracle
        if isinstance(family, dict):           # API: {column: array} of multipliers
            fam = {c: np.asarray(family.get(c, np.ones(len(family['C_eq']))), float)
                   for c in MULT}
            family = 'custom'
        else:
            fam = FAM.resolve(family, seed)
        out = out or default_out(scn.name, family)
        if os.path.exists(os.path.join(out, 'campaign.json')):
            raise UsageError(f'{out} already holds a campaign: use --resume {out} to finish it, '
                             f'or another --out')
    try:
        nominal = nominal_params(config_dir, scn.overrides)
    except ParamError as err:
        raise UsageError(f'scenario {scn.path or scn.name}: overrides: {err}') from None
    n = len(fam['C_eq'])
    table = pd.DataFrame({'run_id': np.arange(n), **{c: fam[c] for c in MULT},
                          'seed': np.full(n, int(seed)),
                          'noise_seed': [noise_seed(seed, i) for i in range(n)]})
    if SC.linear_columns(scn):
        for k, v in linear_columns(scn, fam, nominal, config_dir).items():
            table[k] = v
    # the engine last: a bad scheduler address fails before anything is written
    own = client is None
    cluster = None
    if own:
        client, cluster = connect(workers, scheduler)
    try:
        n_workers = max(1, len(client.scheduler_info(n_workers=-1).get('workers', {})))
        if not own:
            scheduler = scheduler or client.scheduler.address
        parts = os.path.join(out, 'parts')
        os.makedirs(parts, exist_ok=True)
        if not resume:
            table.to_parquet(os.path.join(out, 'family.parquet'), index=False)
        done_df, done_traces = read_parts(out, with_traces=bool(resume))
        done = set(int(i) for i in done_df['run_id']) if len(done_df) else set()
        todo = [i for i in range(n) if i not in done]
        info = dict(scenario=scn.as_dict(), family=family, seed=int(seed),
                    seed_role=seed_role(int(seed)), count=n,
                    workers=n_workers, scheduler=scheduler or 'LocalCluster',
                    dashboard=getattr(client, 'dashboard_link', ''), complete=False)
        write_json(os.path.join(out, 'campaign.json'), dict(info, passed=0, failed=0), True)
        label = f'campaign {scn.name}'
        log(f'{label}: {len(todo)} of {n} runs ({family}, seed {seed}) on {n_workers} '
            f'worker(s), {scheduler or "LocalCluster"}; dashboard {info["dashboard"]}; '
            f'writing {out}')
        bar = Progress(n, n - len(todo), label, progress)
        if len(done_df):
            bar.failed = int((~done_df['passed'].astype(bool)).sum())
        first_row = None
        interrupted = False
        new_rows, new_traces = [], []
        t_run = time.monotonic()
        groups = chunks(todo, n_workers, chunk_size)
        if groups:
            from distributed import as_completed
            scn_f, nom_f = scn.as_dict(), nominal     # small: sent with each task
            recs = table.to_dict('records')
            futures = [client.submit(run_chunk, scn_f, nom_f, [recs[i] for i in g], trace,
                                     pure=False, retries=1,
                                     key=f'campaign-{scn.name}-{os.getpid()}-{g[0]}-'
                                         f'{time.monotonic_ns()}') for g in groups]
            seen, restore = _noted_interrupts()
            try:
                for f in as_completed(futures):
                    if seen:        # a Ctrl-C that Python swallowed (raised in a gc callback)
                        raise KeyboardInterrupt
                    rows, traces = f.result()
                    _write_part(parts, rows, traces)
                    new_rows.extend(rows)
                    new_traces.extend((r['run_id'], tr) for r, tr in zip(rows, traces))
                    if first_row is None:
                        first_row = time.monotonic() - t_start
                    bar.update(len(rows), sum(not r['passed'] for r in rows))
                if seen:
                    raise KeyboardInterrupt
            except KeyboardInterrupt:
                interrupted = True
                client.cancel(futures)
            finally:
                restore()
        bar.close()
        wall = time.monotonic() - t_start
        if interrupted:          # the parts on disk are the truth (a chunk may be half-noted)
            df, pairs = read_parts(out)
        else:
            df, pairs = by_run([done_df, pd.DataFrame(new_rows)]), done_traces + new_traces
        traces = merge_traces(pairs)
        passed = int(df['passed'].astype(bool).sum()) if len(df) else 0
        plant_s = float(df['plant_s'].sum()) if 'plant_s' in df else 0.0
        ran = df[df['run_id'].isin(todo)] if len(df) else df
        run_wall = time.monotonic() - t_run
        info.update(passed=passed, failed=int(len(df) - passed), rows=int(len(df)),
                    complete=bool(len(df) == n), wall_s=round(wall, 3),
                    first_row_s=None if first_row is None else round(first_row, 3),
                    plant_s=round(plant_s, 3),
                    plant_s_per_wall_s=round(float(ran['plant_s'].sum()) / run_wall, 3)
                    if len(ran) and 'plant_s' in ran else 0.0,
                    errors=int((df['error'] != '').sum()) if 'error' in df else 0)
        df.to_parquet(os.path.join(out, 'results.parquet'), index=False)
        if traces is not None:
            np.savez(os.path.join(out, 'traces.npz'), **traces)
        write_json(os.path.join(out, 'campaign.json'), info, True)
        if report and len(df):
            from .report import write_report
            write_report(out, info, df, traces)
        if interrupted:
            log(f'{label}: interrupted: {len(df)} of {n} runs kept in {out}; finish with '
                f'--resume {out}')
            raise KeyboardInterrupt
        return CampaignResult(out, info, df)
    finally:
        if own:
            disconnect(client, cluster)


def _noted_interrupts():
    """SIGINT raises KeyboardInterrupt as before and is also noted in ``seen``: Python ignores
    an exception raised where it cannot propagate (CI: Ctrl-C landed in distributed's gc
    callback, "Exception ignored", and the campaign ran to its end with exit 0), so the loop
    checks ``seen`` too. Main thread only; ``restore()`` puts the previous handler back."""
    seen = []
    prev = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(prev):
        return seen, lambda: None

    def handler(signum, frame):
        seen.append(signum)
        prev(signum, frame)          # the default handler raises KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    return seen, lambda: signal.signal(signal.SIGINT, prev)


def _resume_inputs(out: str, scenario: str | None):
    """(info, family table, scenario, seed) of the campaign in DIR, to finish it."""
    import pandas as pd
    path = os.path.join(out, 'campaign.json')
    try:
        with open(path) as f:
            info = json.load(f)
        fam_df = pd.read_parquet(os.path.join(out, 'family.parquet'))
    except (OSError, ValueError) as err:
        raise UsageError(f'--resume {out}: not a campaign folder ({err.__class__.__name__}: '
                         f'{str(err).splitlines()[0][:120]})')
    scn = SC.from_saved(info['scenario'], path)
    if scenario and scenario not in (scn.name, scn.path) and \
            os.path.splitext(os.path.basename(scenario))[0] != scn.name:
        raise UsageError(f'--resume {out}: that campaign ran scenario {scn.name!r}, not '
                         f'{scenario!r}')
    fam = {c: fam_df[c].to_numpy(float) for c in MULT}
    return info, fam, scn, int(info['seed'])
