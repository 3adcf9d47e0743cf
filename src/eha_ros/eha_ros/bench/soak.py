"""scripts/bench soak --duration S: a long run of the composed real-time stack with the recorder
(what `run_stack --record` starts: eha_loop hosting plant_sim, estimator, controller,
switch_manager and the recorder), measured (issue 45).

Reported: resident memory (RSS) of every process after the loop started and at the end, and its
growth per hour; ticks, lost ticks (a state whose command missed the next tick) and overruns
over the run; the recording's size and bytes per hour; every topic's message count in the MCAP
against the states recorded, and gaps in the recorded state seq. A progress line a minute.
Default duration 300 s; the figure of record is 1800 s (docs/measurements.md).
"""
from __future__ import annotations

import os
import tempfile
import time

from .stack import NODES, wait_running
from ..core import topics as T

PROGRESS_S = 60.0


def rss_bytes(pid: int) -> int:
    """Resident set size of a process (VmRSS of /proc/<pid>/status), 0 once it is gone."""
    try:
        with open(f'/proc/{pid}/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _loop(monitor) -> dict:
    return monitor.find('plant_sim: loop')


def _progress(elapsed: float, d0: dict, d: dict, pids: dict, cores: dict) -> str:
    ticks = d.get('ticks', 0) - d0.get('ticks', 0)
    lost = d.get('commands_not_for_previous_tick', 0) - d0.get('commands_not_for_previous_tick', 0)
    over = d.get('overruns', 0) - d0.get('overruns', 0)
    rss = ', '.join(f'{n} {rss_bytes(p) / 2**20:.0f} MB' for n, p in pids.items())
    cpu = ', '.join(f'{n} {c:.2f}' for n, c in cores.items())
    return (f'bench soak: {elapsed:6.0f} s: ticks {ticks}, lost {lost}, overruns {over}; '
            f'RSS {rss}; cores over the last interval {cpu}')


def _recording_figures(path: str, wall: float) -> dict:
    from ..core.io import recording
    summ = recording.summary(path)
    size = os.path.getsize(path)
    states, gaps = recording.seq_coverage(path, T.STATE.path)
    out = {'recording_bytes': size, 'recording_bytes_per_hour': size * 3600.0 / wall,
           'recorded_states': states, 'recorded_state_seq_gaps': gaps}
    for topic, v in sorted(summ.items()):
        name = topic.replace('/', '_').strip('_')
        out[f'count_{name}'] = v['count']
        out[f'count_{name}_per_state'] = v['count'] / states if states else None
    return out


def soak(duration: float, log=print) -> dict:
    from ..monitor import DiagMonitor
    from ..stack import Stack, cpu_seconds
    monitor = DiagMonitor('bench_soak')
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, 'soak.mcap')
        stack = Stack(NODES, composed=True, record=path, log_dir=os.path.join(tmp, 'logs')).start()
        try:
            wait_running(stack, monitor)
            pids = {n: p.pid for n, p in stack.procs.items()}
            rss0 = {n: rss_bytes(p) for n, p in pids.items()}
            cpu0 = {n: cpu_seconds(p) for n, p in pids.items()}
            d0, t0 = monitor.next_after('plant_sim: loop', time.monotonic())
            log(f'bench soak: loop running; {duration:g} s from now ({", ".join(pids)})')
            next_line, last = t0 + PROGRESS_S, (t0, cpu0)
            while time.monotonic() < t0 + duration:
                if stack.dead():
                    raise RuntimeError(f'a process exited during the soak: {stack.dead()}')
                time.sleep(min(1.0, max(0.0, t0 + duration - time.monotonic())))
                if time.monotonic() >= next_line:
                    now, cpu = time.monotonic(), {n: cpu_seconds(p) for n, p in pids.items()}
                    cores = {n: (cpu[n] - last[1][n]) / (now - last[0]) for n in pids}
                    log(_progress(now - t0, d0, _loop(monitor), pids, cores))
                    next_line, last = next_line + PROGRESS_S, (now, cpu)
            d1, t1 = monitor.next_after('plant_sim: loop', t0 + duration - 0.5)
            rss1 = {n: rss_bytes(p) for n, p in pids.items()}
            cpu1 = {n: cpu_seconds(p) for n, p in pids.items()}
        finally:
            stack.stop(timeout=30)
            monitor.close()
        wall = t1 - t0
        log(f'bench soak: reading the recording ({os.path.getsize(path) / 2**20:.0f} MB) ...')
        rec = _recording_figures(path, wall)
    ticks = d1.get('ticks', 0) - d0.get('ticks', 0)
    lost = d1.get('commands_not_for_previous_tick', 0) - d0.get('commands_not_for_previous_tick', 0)
    over = d1.get('overruns', 0) - d0.get('overruns', 0)
    out = {'duration_s': duration, 'wall_s': wall, 'ticks': ticks, 'lost_ticks': lost,
           'lost_fraction': lost / ticks if ticks else None, 'overruns': over,
           'overrun_fraction': over / ticks if ticks else None,
           'latency_p99_s': d1.get('latency_p99_s'), 'latency_max_s': d1.get('latency_max_s')}
    for n in pids:
        out[f'rss_{n}_start_bytes'] = rss0[n]
        out[f'rss_{n}_end_bytes'] = rss1[n]
        out[f'rss_{n}_growth_bytes_per_hour'] = (rss1[n] - rss0[n]) * 3600.0 / wall
        out[f'cpu_{n}_cores'] = (cpu1[n] - cpu0[n]) / wall
    out.update(rec)
    return out


def run(args) -> dict:
    return soak(args.duration or 300.0)
