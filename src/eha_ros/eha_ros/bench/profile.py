"""scripts/bench profile [--duration S]: where the composed real-time loop's CPU goes (issue 46).

The composed stack runs (eha_loop hosting plant_sim, estimator, controller and switch_manager;
nothing else listening) and py-spy samples the threads of eha_loop that hold the GIL
(``--gil --nonblocking``: the loop is never paused) RATE times a second (not a multiple of the
loop's rate) for the duration (default 20 s). Each sample is charged to the innermost frame
that names a stage (STAGES, first match in order, tried from the innermost frame out), so a
message field set inside the plant side counts as message building, the estimator's kernel
called from its node as the estimator. A stage's
figure is its CPU in microseconds per tick: samples / RATE / wall s x 1e6 / ticks per s. Time in
compiled code that releases the GIL (rclpy's C, numba kernels without the GIL) is not sampled:
the total is set beside the process's CPU from /proc, the difference named.

Written: every stage's us per tick and share, the 25 costliest lines, the sampled total and the
process CPU, ticks and overruns over the window.
"""
from __future__ import annotations

import collections
import os
import re
import shutil
import sys
import subprocess
import tempfile
import time

from .stack import NODES, wait_running

RATE = 1237                     # [Hz] py-spy samples: not a multiple of the loop's 1 kHz
TICK_HZ = 1000.0                # the loop's rate
STAGES = (                      # (stage, pattern on 'function (file:line)'), innermost first
    ('DDS publish (rclpy)', r'\(rclpy/publisher\.py'),
    ('message fields (generated classes)', r'/msg/_[a-z_]+\.py'),
    ('in-process delivery (nodes/compose.py)', r'\(eha_ros/nodes/compose\.py'),
    ('diagnostics', r'\(eha_ros/nodes/diag\.py|publish_diagnostics|diagnostic_msgs'),
    ('loop statistics (core/stats.py)', r'\(eha_ros/core/stats\.py'),
    ('loop supervisor (core/loop/supervisor.py)', r'\(eha_ros/core/loop/supervisor\.py'),
    ('plant model: step', r'EhaPlant\.step |\(eha_ros/core/plant/(integrator|stepper)'),
    ('plant model: outputs (measure, truth)', r'EhaPlant\.(measure|truth|_channel|read_into) '),
    ('plant model: other', r'\(eha_ros/core/plant/'),
    ('estimator (core)', r'\(eha_ros/core/estimator/'),
    ('controller (core)', r'\(eha_ros/core/(controller|qft)/'),
    ('switch manager (core)', r'\(eha_ros/core/redundancy/'),
    ('plant side node', r'\(eha_ros/nodes/plant_side\.py'),
    ('estimator node', r'\(eha_ros/nodes/estimator\.py'),
    ('controller node', r'\(eha_ros/nodes/controller\.py'),
    ('switch manager node', r'\(eha_ros/nodes/switch_manager\.py'),
    ('other eha_ros', r'\(eha_ros/'),
    ('executor, timers (rclpy)', r'\(rclpy/'),
)
_RULES = [(name, re.compile(pat)) for name, pat in STAGES]


def stage_of(frames: list[str]) -> str:
    """The stage of one sampled stack (outermost frame first)."""
    for frame in reversed(frames):
        for name, rule in _RULES:
            if rule.search(frame):
                return name
    return 'other'


def breakdown(raw: str, wall: float, only: str | None = None) -> dict:
    """Per-stage and per-line figures from py-spy's raw output (``frames count`` lines);
    ``only``: the samples whose stack holds this text (a thread's entry function)."""
    stages, lines = collections.Counter(), collections.Counter()
    by_stage = collections.defaultdict(collections.Counter)
    total = 0
    for row in raw.splitlines():
        stack, _, n = row.rpartition(' ')
        if not stack or not n.isdigit() or (only is not None and only not in stack):
            continue
        frames, n = stack.split(';'), int(n)
        stage = stage_of(frames)
        stages[stage] += n
        lines[frames[-1]] += n
        # the stage's own frame: the innermost eha_ros one (what to change), else the leaf
        own = next((f for f in reversed(frames) if '(eha_ros/' in f), frames[-1])
        by_stage[stage][own] += n
        total += n
    us = 1e6 / RATE / wall / TICK_HZ             # one sample in us per tick
    return {'samples': total, 'sampled_us_per_tick': total * us,
            'stages_us_per_tick': {k: v * us for k, v in stages.most_common()},
            'stage_share': {k: v / total for k, v in stages.most_common()} if total else {},
            'top_lines_us_per_tick': {k: v * us for k, v in lines.most_common(25)},
            'stage_top_frames_us_per_tick': {
                k: {f: v * us for f, v in by_stage[k].most_common(6)} for k in stages}}


def py_spy() -> str:
    """py-spy's path: the venv's own first (scripts/bench runs the venv's python without the
    venv on PATH)."""
    from ..core.config.cli import UsageError
    spy = shutil.which('py-spy', path=os.path.dirname(sys.executable)) or shutil.which('py-spy')
    if spy is None:
        raise UsageError('bench: py-spy not found (pip install py-spy; it is in '
                         'requirements.txt)')
    return spy


def profile(duration: float, log=print) -> dict:
    from ..core.config.cli import UsageError
    from ..monitor import DiagMonitor
    from ..stack import Stack, cpu_seconds
    spy = py_spy()
    monitor = DiagMonitor('bench_profile')
    with tempfile.TemporaryDirectory() as tmp:
        stack = Stack(NODES, composed=True, log_dir=os.path.join(tmp, 'logs')).start()
        try:
            wait_running(stack, monitor)
            pid = stack.procs['eha_loop'].pid
            time.sleep(2.0)                      # past the start's first seconds
            d0, t0 = monitor.next_after('plant_sim: loop', time.monotonic())
            cpu0 = cpu_seconds(pid)
            out = os.path.join(tmp, 'profile.raw')
            log(f'bench profile: sampling eha_loop (pid {pid}) for {duration:g} s ...')
            r = subprocess.run([spy, 'record', '--pid', str(pid), '--duration',
                                str(int(round(duration))), '--rate', str(RATE), '--gil',
                                '--nonblocking', '--format', 'raw', '--output', out],
                               capture_output=True, text=True)
            t1, cpu1 = time.monotonic(), cpu_seconds(pid)
            d1, _ = monitor.next_after('plant_sim: loop', t1)
            if r.returncode != 0 or not os.path.exists(out):
                raise UsageError(f'bench profile: py-spy failed ({r.returncode}): '
                                 f'{(r.stderr or r.stdout).strip().splitlines()[-1:]} '
                                 f'(attaching needs ptrace: root, or '
                                 f'/proc/sys/kernel/yama/ptrace_scope 0)')
            if stack.dead():
                raise RuntimeError(f'a process exited while sampled: {stack.dead()}')
            with open(out) as fh:
                raw = fh.read()
        finally:
            stack.stop(timeout=30)
            monitor.close()
    wall = t1 - t0
    ticks = d1.get('ticks', 0) - d0.get('ticks', 0)
    result = breakdown(raw, wall)
    result.update({'duration_s': duration, 'wall_s': wall, 'rate_hz': RATE, 'ticks': ticks,
                   'overruns': d1.get('overruns', 0) - d0.get('overruns', 0),
                   'process_cpu_cores': (cpu1 - cpu0) / wall,
                   'process_cpu_us_per_tick': (cpu1 - cpu0) / wall * 1e6 / TICK_HZ})
    log(f'bench profile: {result["sampled_us_per_tick"]:.0f} us per tick sampled with the GIL, '
        f'process CPU {result["process_cpu_us_per_tick"]:.0f} us per tick')
    for name, us in result['stages_us_per_tick'].items():
        log(f'  {us:7.1f} us  {100 * result["stage_share"][name]:5.1f} %  {name}')
    return result


def run(args) -> dict:
    return profile(args.duration or 20.0)
