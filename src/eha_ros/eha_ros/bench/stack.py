"""scripts/bench stack: the whole loop under load, measured (issue 10 goals in the JSON).

realtime_<structure>_*: plant_sim, estimator, controller, switch_manager at 1 kHz on the
wall clock for --duration s (default 30), composed (eha_loop, the default structure) and as
separate processes: ticks, lost ticks (state seq without its command before the next tick),
state-to-command latency p50/p99/max, plant period p99, overruns, CPU per process, each loop
node's execution time per input (the plant side's: its whole tick with the in-process
deliveries it triggers). realtime_composed_record_*: composed, with the recorder listening.
lockstep_*: the same nodes as processes in lock-step: simulated s per wall s.
batch_*: the closed loop in one process, no DDS (bench batch) when available.
"""
from __future__ import annotations

import importlib
import os
import tempfile
import time

from ..core import topics as T
from ..core.io.ports import free_port

NODES = ['plant_sim', 'estimator', 'controller', 'switch_manager']
GOALS = {'answered_fraction': 0.999, 'latency_p99_s': 1e-3, 'cpu_total_cores': 1.0,
         'batch_sim_per_wall': 50.0}
# issue 46 (the loop close to its compute): goal46_<key>_met in the JSON
GOALS_46 = {'cpu_eha_loop_cores': 0.15, 'record_cpu_eha_loop_cores': 0.25,
            'plant_sim_exec_mean_s': 60e-6, 'plant_sim_exec_p99_s': 200e-6,
            'answered_fraction': 0.999, 'latency_p99_s': 0.5e-3, 'batch_sim_per_wall': 150.0}


def measure_stack(duration: float, lockstep: bool = False, composed: bool = False,
                  warmup: float = 3.0, log_dir=None, live: bool = False,
                  record: bool = False) -> dict:
    """Start the stack, wait for the loop to run, measure over ``duration`` s. ``live``: with
    the live node, first ``duration`` s without a viewer (cpu_*_cores_no_viewer), then with
    one WebSocket client subscribed to every channel (bench live). ``record``: with the
    recorder (every /eha topic and /diagnostics into a temporary MCAP file; composed: a guest
    of eha_loop): recorded_states, recorded_state_gaps of the whole run."""
    from ..monitor import CpuMeter, DiagMonitor
    from ..stack import Stack
    monitor = DiagMonitor('bench_stack')
    port = free_port() if live else None
    tmp = tempfile.TemporaryDirectory() if record else None
    stack = Stack(NODES, lockstep=lockstep, composed=composed, log_dir=log_dir,
                  live=port, record=os.path.join(tmp.name, 'bench.mcap') if tmp else None
                  ).start()
    viewer = None
    try:
        wait_running(stack, monitor)
        idle = {}
        if live:
            time.sleep(warmup)
            idle = CpuMeter(stack.procs).over(duration)
            viewer = _Viewer(port)
        time.sleep(warmup)
        d0, t0 = monitor.next_after('plant_sim: loop', time.monotonic())
        seen0 = viewer.total() if viewer else 0
        share = CpuMeter(stack.procs).over(duration)
        d1, t1 = monitor.next_after('plant_sim: loop', t0 + duration - 0.5)
        wall = t1 - t0                   # between the two diagnostics the figures come from
        snap = monitor.snapshot()
        if viewer:
            seen1 = viewer.total()
    finally:
        if viewer:
            viewer.close()
        stack.stop()
        monitor.close()
        recorded = _recorded(stack.record) if tmp else {}
        if tmp:
            tmp.cleanup()
    ticks = d1.get('ticks', 0) - d0.get('ticks', 0)
    key = 'commands_not_for_previous_tick'
    lost = d1.get(key, 0) - d0.get(key, 0)
    out = {'wall_s': wall, 'ticks': ticks, 'lost_ticks': lost,
           'answered_fraction': 1.0 - lost / ticks if ticks else 0.0,
           'ticks_per_wall_s': ticks / wall,
           'latency_p50_s': d1.get('latency_p50_s'), 'latency_p99_s': d1.get('latency_p99_s'),
           'latency_max_s': d1.get('latency_max_s'),
           'plant_period_p99_s': d1.get('period_p99_s'),
           'plant_period_max_s': d1.get('period_max_s'),
           'overruns': d1.get('overruns', 0) - d0.get('overruns', 0),
           'cpu_total_cores': sum(share.values())}
    out.update({f'cpu_{n}_cores': c for n, c in share.items()})
    out.update(recorded)
    out.update({f'cpu_{n}_cores_no_viewer': c for n, c in idle.items()})
    if viewer:
        out['viewer_channels'] = len(viewer.client.subs)
        out['viewer_messages_per_s'] = (seen1 - seen0) / wall
    for name, values in snap.items():
        node = name.split(':')[0]
        for key in ('exec_mean_s', 'exec_p99_s'):
            if key in values:
                out[f'{node}_{key}'] = values[key]
    return out


def _recorded(path: str) -> dict:
    """The whole run's recording: states in it and seq values missing between its first and
    last (the recorder keeps up: none)."""
    from ..core.io.recording import RecordingError, seq_coverage
    try:
        n, gaps = seq_coverage(path, T.STATE.path)
    except RecordingError:
        return {'recorded_states': 0, 'recorded_state_gaps': -1}
    return {'recorded_states': n, 'recorded_state_gaps': gaps}


def wait_running(stack, monitor, timeout: float = 90.0) -> None:
    """Block until the plant side has reported 100 ticks on /diagnostics; RuntimeError when
    it does not within ``timeout`` s or a process of the stack exits."""
    end = time.monotonic() + timeout
    while monitor.find('plant_sim: loop').get('ticks', 0) < 100:
        if time.monotonic() > end or stack.dead():
            raise RuntimeError(f'the loop did not start within {timeout:g} s '
                               f'(exited: {stack.dead()})')
        time.sleep(0.1)


class _Viewer:
    """One WebSocket client subscribed to every advertised channel at full rate, reading in a
    thread (counts only)."""

    def __init__(self, port: int):
        import threading
        from ..tools.ws_client import FoxgloveClient
        self.client = c = FoxgloveClient(f'ws://127.0.0.1:{port}', timeout=60)
        c.keep = False
        c.wait_for(lambda: {T.STATE.path, T.ESTIMATE.path, T.COMMAND.path} <= set(c.channels),
                   60, 'the loop topics advertised')
        c.poll(1.0)                      # the rest of the topics
        c.subscribe(sorted(c.channels))
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop.is_set():
            self.client.poll(0.2)

    def total(self) -> int:
        return sum(self.client.counts.values())

    def close(self):
        self.stop.set()
        self.thread.join(timeout=5)
        self.client.close()


def run(args) -> dict:
    duration = args.duration or 30.0
    result = {'duration_s': duration}
    for label, kw in (('realtime_composed', {'composed': True}),
                      ('realtime_composed_record', {'composed': True, 'record': True}),
                      ('realtime_processes', {}), ('lockstep', {'lockstep': True})):
        seconds = duration if label != 'lockstep' else min(duration, 15.0)
        print(f'bench stack: {label} for {seconds:g} s ...', flush=True)
        r = measure_stack(seconds, **kw)
        result.update({f'{label}_{k}': v for k, v in r.items()})
    result['lockstep_sim_s_per_wall_s'] = result['lockstep_ticks_per_wall_s'] * 1e-3
    try:
        batch = importlib.import_module(f'{__package__}.batch')
    except ImportError:
        batch = None
    if batch is not None:
        print('bench stack: batch closed loop ...', flush=True)
        result.update({k if k.startswith('batch_') else f'batch_{k}': v
                       for k, v in batch.run(args).items()})
    rt = 'realtime_composed_'
    result['goal_answered_met'] = result[rt + 'answered_fraction'] >= GOALS['answered_fraction']
    result['goal_latency_met'] = (result[rt + 'latency_p99_s'] or 1.0) <= GOALS['latency_p99_s']
    result['goal_cpu_met'] = result[rt + 'cpu_total_cores'] <= GOALS['cpu_total_cores']
    key = 'batch_closed_loop_sim_s_per_wall_s_median'
    if key in result:
        result['goal_batch_met'] = result[key] >= GOALS['batch_sim_per_wall']
        result['goal46_batch_sim_per_wall_met'] = result[key] >= GOALS_46['batch_sim_per_wall']
    for name, limit in GOALS_46.items():      # record_x: realtime_composed_record_x
        value = result.get(rt + name)
        if value is not None:
            result[f'goal46_{name}_met'] = value >= limit if name == 'answered_fraction' \
                else value <= limit
    return result
