"""The main job (scripts/run): the simulated EHA stack with a stepped-sine sweep and a report.

lockstep (default): plant_sim, estimator, controller and switch_manager as separate processes
over DDS, the plant stepping when command(k) has arrived, the sweep node driving them;
realtime: on the wall clock at 1 kHz, the loop nodes composed in one eha_loop process (as
scripts/run_stack runs them; docs/nodes/eha_loop.md); batch: the same core objects in one
process.
Every mode writes out/<run>/summary.json, data.csv, bode.png (and logs/ for the node modes).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time

from ..core.config.cli import UsageError, guarded, interrupt_on_signals, require_seconds, stopping
from ..core.config.params import default_config_dir
from ..core.io.report import run_dir

MODES = ('realtime', 'lockstep', 'batch')


def parse(argv):
    ap = argparse.ArgumentParser(
        prog='scripts/run',
        description='Run the simulated EHA stack with a stepped-sine sweep (thesis Fig. 4.51) '
                    'and write a report (summary.json, data.csv, bode.png) under out/<run>/. '
                    'Sweep defaults come from config/sweep.yaml (1 mm from 1 Hz in 1 Hz steps, '
                    'until the first frequency below -3 dB, at most Nyquist/10 = 50 Hz); the '
                    'closed-loop bandwidth is interpolated between the last two points. '
                    '--stiffness measures the dynamic stiffness instead (thesis Fig. 4.52).')
    ap.add_argument('--mode', choices=MODES, default='lockstep',
                    help='lockstep (default): nodes over DDS, the plant waits for each command; '
                         'realtime: wall clock at 1 kHz, loop nodes composed in one process '
                         '(eha_loop), the sweep over DDS; batch: core objects in one process, '
                         'no DDS')
    ap.add_argument('--stiffness', action='store_true',
                    help='dynamic stiffness: a stepped sine of the external load force '
                         '(sweep.load_amplitude, 5 kN, at sweep.stiffness_freqs, 1/4/7 Hz) with '
                         'the reference held at the offset; reports |F_L|/|x| against the '
                         'eq. 4.60 bound (>= 49 kN/mm up to 7 Hz); stiffness.png')
    ap.add_argument('--no-stop', action='store_true',
                    help='sweep every frequency up to --max-hz, also beyond the -3 dB point')
    ap.add_argument('--amplitude-mm', type=float, help='sine amplitude [mm]')
    ap.add_argument('--offset-mm', type=float, help='centre position [mm]')
    ap.add_argument('--start-hz', type=float, help='first frequency [Hz]')
    ap.add_argument('--step-hz', type=float, help='frequency increment [Hz]')
    ap.add_argument('--max-hz', type=float, help='last frequency [Hz]')
    ap.add_argument('--periods', type=int, help='whole periods per frequency')
    ap.add_argument('--config', default=default_config_dir(), help='config folder (config/)')
    ap.add_argument('--out', default='out', help='output base folder (out/)')
    ap.add_argument('--name', default=None, help='run folder name (default: timestamp)')
    ap.add_argument('--timeout', type=float, default=600.0,
                    help='give up (and keep what was measured) after this many seconds')
    return ap.parse_args(argv)


def sweep_overrides(args) -> dict:
    """Command-line options as sweep.* parameter values."""
    pairs = {'sweep.amplitude': None if args.amplitude_mm is None else args.amplitude_mm * 1e-3,
             'sweep.offset': None if args.offset_mm is None else args.offset_mm * 1e-3,
             'sweep.start_hz': args.start_hz, 'sweep.increment_hz': args.step_hz,
             'sweep.max_hz': args.max_hz, 'sweep.periods': args.periods,
             'sweep.mode': 'stiffness' if args.stiffness else None,
             'sweep.stop_at_bandwidth': False if args.no_stop else None}
    return {k: v for k, v in pairs.items() if v is not None}


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    interrupt_on_signals()
    return guarded('run', lambda: run(args))


def run(args) -> int:
    from ..core.sim.batch import node_params
    from ..core.sweep.params import SCHEMA, build_plan
    require_seconds('--timeout', args.timeout)
    over = sweep_overrides(args)
    # validate the sweep here, so a bad option is one line before anything starts
    sweep_p = node_params('sweep', SCHEMA, args.config, {f'sweep:{k}': v for k, v in over.items()})
    plan = build_plan(sweep_p)
    if args.mode != 'batch':
        from ..monitor import DiagMonitor, refuse_second_stack
        monitor = DiagMonitor('run_check')
        try:
            refuse_second_stack(monitor, 'ROS_DOMAIN_ID=N scripts/run ...')
        finally:
            monitor.close()
    out = run_dir(args.out, args.name)
    if args.stiffness:
        what = (f'load {sweep_p["sweep.load_amplitude"] / 1e3:g} kN at '
                f'{", ".join("%g" % f for f in sweep_p["sweep.stiffness_freqs"])} Hz, '
                f'reference held at {sweep_p["sweep.offset"] * 1e3:g} mm')
    else:
        what = (f'stepped sine {sweep_p["sweep.start_hz"]:g}-{sweep_p["sweep.max_hz"]:g} Hz every '
                f'{sweep_p["sweep.increment_hz"]:g} Hz'
                f'{" (stops below -3 dB)" if sweep_p["sweep.stop_at_bandwidth"] else ""}, '
                f'{sweep_p["sweep.amplitude"] * 1e3:g} mm')
    print(f'run: {args.mode}, {what}, {sweep_p["sweep.periods"]} periods '
          f'({plan.n_ticks * plan.Ts:.0f} s planned); config {args.config}; report {out}/',
          flush=True)
    if args.mode == 'batch':
        summary = run_batch(args, sweep_p, plan, out)
    else:
        summary = run_nodes(args, over, out)
    from ..core.sweep.session import print_table
    print()
    print_table(summary)
    print(f'report: {out}/ (summary.json, data.csv, {"stiffness" if args.stiffness else "bode"}.png'
          f'{", logs/" if args.mode != "batch" else ""})')
    return 0 if summary.get('complete') else 1


def run_batch(args, p, plan, out) -> dict:
    """Batch: the same core objects in one process (BatchStack.run: compiled segments that
    give the numbers of tick-by-tick stepping)."""
    import numpy as np

    from ..core.sim.batch import BatchStack
    from ..core.sweep.session import COLUMNS, from_params
    from ..nodes.sweep import model_overlay
    stack = BatchStack(args.config)
    model, ctl_file = model_overlay(p)
    meta = {'mode': p['sweep.mode'], 'amplitude_m': p['sweep.amplitude'],
            'offset_m': p['sweep.offset'],
            'source': 'batch (plant, estimator, controller cores in one process)',
            'controller_file': ctl_file}
    session = from_params(p, plan, out, meta, model, background_writes=False)
    warmup = int(round(0.5 / stack.Ts))
    stack.run(np.full(warmup, session.position))  # let the estimator settle at the offset
    session.start(stack.k)
    chunk = int(round(0.5 / stack.Ts))           # ticks per BatchStack.run (compiled segments)
    t0 = time.perf_counter()
    try:
        while stack.k - session.seq0 < session.n_run:
            k0 = stack.k
            m = min(chunk, session.n_run - (k0 - session.seq0))
            ks = range(k0, k0 + m)
            r = stack.run([session.reference_for(k) for k in ks], [session.load_for(k) for k in ks])
            done = m
            for i, x_hat in enumerate(r['estimate']):   # same tick of abort as tick by tick
                if session.check_error(k0 + i, float(x_hat)):
                    done = i + 1
                    break
            for col in COLUMNS:
                session.record_many(col, k0, r[col][:done])
            if done < m:
                break
            for pt in session.progress(k0 + m - 1):
                print('  ' + session.describe(pt), flush=True)
    except KeyboardInterrupt:
        return session.finish(reason='interrupted')
    wall = time.perf_counter() - t0
    session.meta['wall_s'] = wall
    session.meta['simulated_s'] = sim_s = session.n_run * plan.Ts
    print(f'  {sim_s:.1f} s simulated in {wall:.1f} s ({sim_s / wall:.1f}x real time)')
    return session.finish()


def run_nodes(args, over: dict, out: str) -> dict:
    """Lock-step: every node its own process; real time: the loop nodes composed (eha_loop);
    the sweep node (its own process) drives the run."""
    from ..stack import Stack, node_command, spawn
    nodes = ['plant_sim', 'estimator', 'controller']
    if os.path.exists(os.path.join(args.config, 'switch_manager.yaml')):
        nodes.append('switch_manager')
    logs = os.path.join(out, 'logs')
    stack = Stack(nodes, args.config, log_dir=logs, lockstep=args.mode == 'lockstep',
                  composed=args.mode == 'realtime').start()
    print(f'run: started {", ".join(nodes)} as {", ".join(stack.procs)} (logs in {logs}/)',
          flush=True)
    sweep_args = ['-p', 'use_sim_time:=true'] if args.mode == 'lockstep' else []
    sweep_args += ['-p', f'sweep:sweep.out_dir:={os.path.dirname(out) or "."}',
                  '-p', f'sweep:sweep.run_name:={os.path.basename(out)}']
    for k, v in over.items():
        sweep_args += ['-p', f'sweep:{k}:={v}']
    sweep = spawn(node_command('sweep', args.config, sweep_args), env=stack.env,
                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []

    def reader():                      # the sweep's output, echoed as it measures
        for line in sweep.stdout:
            lines.append(line)
            text = line.split(']: ', 1)[-1].rstrip()
            if 'Hz:' in text or 'started' in text or 'aborted' in text:
                print('  ' + text, flush=True)
    threading.Thread(target=reader, daemon=True).start()
    try:
        deadline = time.monotonic() + args.timeout
        while sweep.poll() is None:
            time.sleep(0.5)
            dead = stack.dead()
            if dead:
                os.killpg(sweep.pid, signal.SIGINT)
                sweep.wait(timeout=60)
                stopped = stack.stop()
                tails = {n: stopped[n][1].strip().splitlines()[-1:] for n in dead}
                raise UsageError(f'node(s) died during the run: {dead} {tails}; see {logs}/')
            if time.monotonic() > deadline:
                print(f'run: timeout after {args.timeout:.0f} s: stopping the sweep', flush=True)
                os.killpg(sweep.pid, signal.SIGINT)
                sweep.wait(timeout=60)
    except KeyboardInterrupt:
        print('run: interrupted: keeping every finished frequency', flush=True)
        os.killpg(sweep.pid, signal.SIGINT)
        sweep.wait(timeout=60)
    finally:
        stopping()
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
        with open(os.path.join(logs, 'sweep.log'), 'w') as fh:
            fh.writelines(lines)
        stack.stop()
    path = os.path.join(out, 'summary.json')
    if not os.path.exists(path):
        raise UsageError(f'the sweep wrote no summary; see {logs}/sweep.log: '
                         f'{"".join(lines[-3:]).strip()[-300:]}')
    with open(path) as fh:
        return json.load(fh)


if __name__ == '__main__':
    sys.exit(main())
