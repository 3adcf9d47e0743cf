"""Recorder cost: the simulated stack (plant_sim, estimator, controller, switch_manager) with
the recorder, in lock-step and in real time (1 kHz wall clock): CPU of the recorder over a
window of --duration s (default 10) after a warm-up, messages per second, CPU per message,
file size per simulated second. Message counts come from the recording (log times)."""
from __future__ import annotations

import os
import tempfile
import time

from ..core.io import recording
from ..stack import Stack, cpu_seconds
from ..core import topics as T

NODES = ['plant_sim', 'estimator', 'controller', 'switch_manager']
WARMUP_S = 10.0


def measure(mode: str, duration: float) -> dict:
    """One stack run; figures of the window [warm-up, warm-up + duration]."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, 'rec.mcap')
        # a DDS domain of its own: another stack on the machine must not feed this one
        domain = os.environ.get('ROS_DOMAIN_ID') or str(101 + os.getpid() % 100)
        st = Stack(NODES, lockstep=mode == 'lockstep', record=path,
                   env={'ROS_DOMAIN_ID': domain}).start()
        try:
            time.sleep(WARMUP_S)
            pids = {n: p.pid for n, p in st.procs.items()}
            c0 = {n: cpu_seconds(p) for n, p in pids.items()}
            t0 = time.time_ns()
            time.sleep(duration)
            c1 = {n: cpu_seconds(p) for n, p in pids.items()}
            t1 = time.time_ns()
        finally:
            st.stop(timeout=20)
        summ = recording.summary(path)
        size = os.path.getsize(path)
        recs = recording.read_records(path)
    wall = (t1 - t0) * 1e-9
    in_window = {t: sum(t0 <= r.log_time < t1 for r in rs) for t, rs in recs.items()}
    n = sum(in_window.values())
    ticks = in_window.get(T.STATE.path, 0)
    states = summ.get(T.STATE.path, {}).get('count', 0)
    cpu = c1['recorder'] - c0['recorder']
    seqs = {r.msg.seq for r in recs.get(T.STATE.path, [])}
    gaps = (max(seqs) - min(seqs) + 1 - len(seqs)) if seqs else None
    out = {'window_s': wall, 'recorder_cpu_fraction': cpu / wall,
           'messages_per_s': n / wall, 'state_rate_hz': ticks / wall,
           'recorder_cpu_per_message_s': cpu / n if n else None,
           'file_bytes': size, 'recorded_states': states, 'state_seq_gaps': gaps,
           'bytes_per_sim_s': size / (states * 1e-3) if states else None,
           'messages_total': sum(v['count'] for v in summ.values())}
    out.update({f'cpu_fraction_{name}': (c1[name] - c0[name]) / wall for name in c0
                if name != 'recorder'})
    out.update({f'count{t.replace("/", "_")}': v['count'] for t, v in summ.items()})
    return {f'{mode}_{k}': v for k, v in out.items()}


def run(args) -> dict:
    duration = args.duration or 10.0
    result = {'duration_s': duration, 'warmup_s': WARMUP_S}
    for mode in ('lockstep', 'realtime'):
        result.update(measure(mode, duration))
    return result
