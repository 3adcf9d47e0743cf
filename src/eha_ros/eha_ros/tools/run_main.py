"""The main job (scripts/run): a stepped-sine sweep of the simulated actuator with a report.

Today the stack runs in batch (plant core + position controller in one process). The
position loop is the thesis' interim PID of Table 3.8 on the measured position until the
estimator and the QFT controller nodes exist; the report says which controller was used.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from ..core.cli import UsageError, guarded
from ..core.params import default_config_dir, load
from ..core.report import bode_png, run_dir, write_csv, write_json
from ..core.sweep.analysis import sine_point, summarize, unwrap_deg
from ..core.sweep.signals import SteppedSine, check_sweep

MODES = ('batch', 'realtime', 'lockstep')


def parse(argv):
    ap = argparse.ArgumentParser(
        prog='scripts/run',
        description='Run the simulated EHA with a stepped-sine sweep (thesis Fig. 4.51) and '
                    'write a report (summary.json, data.csv, bode.png) under out/<run>/.')
    ap.add_argument('--amplitude-mm', type=float, default=1.0, help='sine amplitude [mm] (1)')
    ap.add_argument('--offset-mm', type=float, default=0.0, help='position offset [mm] (0)')
    ap.add_argument('--start-hz', type=float, default=1.0, help='first frequency [Hz] (1)')
    ap.add_argument('--step-hz', type=float, default=1.0, help='frequency increment [Hz] (1)')
    ap.add_argument('--max-hz', type=float, default=15.0, help='last frequency [Hz] (15)')
    ap.add_argument('--periods', type=int, default=8, help='periods per frequency (8)')
    ap.add_argument('--relax-s', type=float, default=0.3, help='rest between frequencies [s]')
    ap.add_argument('--mode', choices=MODES, default='batch',
                    help='batch: one process, no DDS (available now); realtime/lockstep: the '
                         'node stack over DDS (needs the estimator, controller and sweep nodes)')
    ap.add_argument('--config', default=default_config_dir(), help='config folder (config/)')
    ap.add_argument('--out', default='out', help='output base folder (out/)')
    ap.add_argument('--seed', type=int, default=1, help='noise seed (1)')
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    return guarded('run', lambda: run(args))


def run(args) -> int:
    from ..core.pid import PID
    from ..core.plant import EhaPlant
    from ..core.plant.parameters import PLANT_SCHEMA
    from ..core.plant import linear

    if args.mode != 'batch':
        raise UsageError(f'mode {args.mode!r} needs the estimator, controller and sweep nodes, '
                         f'which are not built yet (issues 4, 6, 8): use --mode batch')
    plant_file = os.path.join(args.config, 'plant.yaml')
    params = load(PLANT_SCHEMA, [plant_file])
    Ts = params['plant.sim.Ts']
    amp, off = args.amplitude_mm * 1e-3, args.offset_mm * 1e-3
    check_sweep(args.start_hz, args.step_hz, args.max_hz, args.periods, args.relax_s, amp, off,
                params['plant.cylinder.stroke'], Ts)
    sweep = SteppedSine(args.start_hz, args.step_hz, args.max_hz, args.periods, args.relax_s,
                        amp, off, Ts)
    out = run_dir(args.out)
    print(f'run: batch stepped sine {args.start_hz:g}-{args.max_hz:g} Hz step {args.step_hz:g} Hz, '
          f'{args.amplitude_mm:g} mm, {args.periods} periods; plant {plant_file}; '
          f'controller: thesis PID (Table 3.8, interim) on the measured position', flush=True)

    plant = EhaPlant(params, seed=args.seed)
    plant.reset(position=off)
    pid = PID.table_3_8(Ts, omega_max=params['plant.drive.omega_max'])
    n = sweep.n_ticks
    rec = {k: np.zeros(n) for k in ('t', 'reference', 'measured', 'truth', 'command',
                                    'motor_speed_0', 'motor_speed_1')}
    ref = sweep.array()
    t0 = time.perf_counter()
    done_segments = 0
    for k in range(n):
        m = plant.measure()
        u = pid.update(ref[k] - m.position)
        plant.step(u, 0.0)
        tr = plant.truth()
        rec['t'][k] = (k + 1) * Ts
        rec['reference'][k], rec['measured'][k], rec['truth'][k] = ref[k], m.position, tr.position
        rec['command'][k] = u
        rec['motor_speed_0'][k], rec['motor_speed_1'][k] = m.motor_speed
        seg = sweep.segment_at(k)
        if seg is not None and k == sweep.segments[seg].stop - 1:
            done_segments += 1
            print(f'  {sweep.segments[seg].freq_hz:5.1f} Hz done ({done_segments}/'
                  f'{len(sweep.segments)})', flush=True)
    wall = time.perf_counter() - t0

    points = []
    for seg in sweep.segments:
        sl = slice(seg.start, seg.stop)
        points.append(sine_point(rec['reference'][sl], rec['truth'][sl], seg.freq_hz, Ts))
    summary = summarize(points)
    summary.update({'complete': True, 'mode': 'batch', 'output': 'true position',
                    'controller': 'thesis PID, Table 3.8 (interim until the QFT controller)',
                    'amplitude_m': amp, 'offset_m': off, 'simulated_s': n * Ts,
                    'wall_s': wall, 'plant_config': plant_file})
    write_csv(os.path.join(out, 'data.csv'), rec)
    write_json(os.path.join(out, 'summary.json'), summary)

    # linear-model overlay: PID (continuous equivalent, with the one-tick delay) around eq. 3.41
    f = np.logspace(np.log10(args.start_hz * 0.8), np.log10(args.max_hz * 1.2), 200)
    w = 2 * np.pi * f
    P = linear.freqresp(linear.velocity_abcd(params), w)
    s = 1j * w
    C = pid.kp + pid.ki / s + pid.kd * s / (pid.tau_d * s + 1)
    L = C * P * np.exp(-s * Ts)
    T = L / (1 + L)
    bode_png(os.path.join(out, 'bode.png'), summary['points'],
             (f, 20 * np.log10(np.abs(T)), unwrap_deg(np.degrees(np.angle(T)))),
             'closed loop x/x_ref: batch plant + Table 3.8 PID')

    print(f'\n{"freq [Hz]":>10} {"gain [dB]":>10} {"phase [deg]":>12} {"coherence":>10}')
    for p in summary['points']:
        print(f'{p["freq_hz"]:10.2f} {p["gain_db"]:10.2f} {p["phase_deg"]:12.1f} '
              f'{p["coherence"]:10.4f}')
    bw = summary['bandwidth_hz']
    ph7 = summary['phase_at_7hz_deg']
    print(f'\nbandwidth (-3 dB): {"> %g Hz (not reached)" % args.max_hz if bw is None else "%.2f Hz" % bw}'
          f'; phase at 7 Hz: {"n/a" if ph7 is None else "%.1f deg" % ph7}'
          f'; {n * Ts:.1f} s simulated in {wall:.1f} s wall ({n * Ts / wall:.1f}x real time)')
    print(f'report: {out}/ (summary.json, data.csv, bode.png)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
