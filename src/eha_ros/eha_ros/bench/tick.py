"""scripts/bench tick: the composed loop's tick run back to back (issue 46): what one tick of
the node layer costs without the millisecond's sleep between ticks, and where it goes.

A child process builds eha_loop's nodes exactly as eha_loop does (plant_sim, estimator,
controller, switch_manager as in bench stack; the executor spins beside them), but the plant
side's loop thread runs its ticks back to back: WARMUP ticks, then TICKS in BLOCKS blocks,
each tick under the process lock as in real time. Written: us per tick (the best and the
median block; wall time and the loop thread's CPU). A second child runs PROFILE_TICKS under
py-spy (every sample of the loop thread, with or without the GIL; the child paused for each
sample, so the stacks are whole), charged to bench.profile's stages (us per tick = the stage's
share x the best block of the first child). bench stack's execution time in
real time adds what waking up once a millisecond costs (cold caches); bench profile samples
that running loop.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

from .profile import RATE, breakdown, py_spy
from .stack import NODES

WARMUP, TICKS, BLOCKS, PROFILE_TICKS = 2000, 20000, 10, 60000
# fewest samples of the loop thread that make a per-stage breakdown (60,000 ticks gave 3047
# beside a campaign; py-spy falls further behind on a busier machine and keeps a few dozen)
MIN_SAMPLES = 1000
LOOP_THREAD = 'PlantSide.loop '    # py-spy's frame text of the loop thread's samples


def _child(ticks: int, out: str) -> int:
    """eha_loop with the plant side's real-time loop replaced by ``ticks`` back-to-back ticks;
    writes the figures as JSON to the file ``out`` (not stdout, which py-spy shares: its
    "behind in sampling" lines broke the line the figures were printed on)."""
    from ..nodes import eha_loop, plant_side
    from ..stack import composed_command
    result = {}

    def loop(self):
        while self.running and not self.start_gate.poll():
            time.sleep(0.02)
        time.sleep(1.0)                       # past the start: the other nodes settle
        for _ in range(WARMUP):
            with self.callback_lock:
                self.tick(self.Ts)
        blocks, n = [], ticks // BLOCKS
        c0 = time.thread_time()
        for _ in range(BLOCKS):
            t0 = time.perf_counter()
            for _ in range(n):
                with self.callback_lock:
                    self.tick(self.Ts)
            blocks.append((time.perf_counter() - t0) / n)
        cpu = (time.thread_time() - c0) / (n * BLOCKS)
        blocks.sort()
        result.update(us_per_tick_best=blocks[0] * 1e6,
                      us_per_tick_median=blocks[BLOCKS // 2] * 1e6, cpu_us_per_tick=cpu * 1e6,
                      ticks=n * BLOCKS)
        self.done = True                      # common.spin ends

    plant_side.PlantSide.realtime_loop = loop
    rc = eha_loop.main(['eha_loop'] + composed_command(NODES)[1:])
    if result:
        with open(out, 'w') as fh:
            json.dump(result, fh)
    return rc


def _run_child(ticks: int, spy: str | None = None, raw: str | None = None) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, 'tick.json')
        cmd = [sys.executable, '-m', __name__, str(ticks), out]
        if spy:
            # blocking (py-spy pauses the child per sample): a stack read while a 50 us tick
            # runs on (--nonblocking) mixes frames of different calls
            cmd = [spy, 'record', '--rate', str(RATE), '--threads', '--format', 'raw',
                   '--output', raw, '--'] + cmd
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if r.returncode != 0 or not os.path.exists(out):
            tail = (r.stderr or r.stdout).strip().splitlines()[-3:]
            raise RuntimeError(f'bench tick: the child failed ({r.returncode}): {tail}')
        with open(out) as fh:
            return json.load(fh)


def run(args) -> dict:
    result = _run_child(TICKS)
    print(f'bench tick: {result["us_per_tick_best"]:.1f} us per tick (best block), '
          f'{result["us_per_tick_median"]:.1f} (median)', file=sys.stderr, flush=True)
    spy = py_spy()
    with tempfile.TemporaryDirectory() as tmp:
        raw = os.path.join(tmp, 'tick.raw')
        prof = _run_child(PROFILE_TICKS, spy, raw)
        with open(raw) as fh:
            text = fh.read()
    # the loop thread's samples only; each stage as its share of the best block's tick
    shares = breakdown(text, 1.0, only=LOOP_THREAD)
    result['profile_samples'] = shares['samples']
    result['profiled_us_per_tick_median'] = prof['us_per_tick_median']
    if shares['samples'] < MIN_SAMPLES:
        print(f'bench tick: py-spy kept {shares["samples"]} samples of the loop thread (at '
              f'least {MIN_SAMPLES} make a breakdown; it falls behind on a busy machine): no '
              f'per-stage figures written, the tick figures above stand', file=sys.stderr)
        return result
    tick_us, total = result['us_per_tick_best'], shares['sampled_us_per_tick']
    result['stage_share'] = shares['stage_share']
    result['stages_us_per_tick'] = {k: v * tick_us for k, v in shares['stage_share'].items()}
    result['stage_top_frames_us_per_tick'] = {
        k: {f: v / total * tick_us for f, v in frames.items()}
        for k, frames in shares['stage_top_frames_us_per_tick'].items()}
    for name, us in result['stages_us_per_tick'].items():
        print(f'  {us:6.1f} us  {100 * result["stage_share"][name]:5.1f} %  {name}',
              file=sys.stderr)
    return result


if __name__ == '__main__':
    sys.exit(_child(int(sys.argv[1]), sys.argv[2]))
