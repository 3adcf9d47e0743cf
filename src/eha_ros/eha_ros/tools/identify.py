"""scripts/identify: system identification of the actuator (thesis section 3.6, issue 43).

  scripts/identify --plant sim --out DIR [-p plant_sim:plant.KEY:=VALUE ...]
  scripts/identify --plant bridge --activate --out DIR
  scripts/identify --recordings PATH... --out DIR

--plant sim|bridge runs the experiments below one after the other, each a run of
scripts/run_stack --record --experiment KIND (the experiment node; the drive experiment with
--no-controller), recorded to DIR/recordings/<experiment>.mcap (run folders with logs under
DIR/runs/), then fits the recordings (eha_ros.core.ident.pipeline.fit_recordings) into DIR:
identified.yaml (plant_sim takes it as one more --params-file; run_stack, campaign and
design_qft as --plant-params), identification.json and report.md. --recordings fits
recordings made elsewhere (a bench) and runs nothing. Everything it prints is also in
DIR/identify.log.

sim: plant_sim with the -p plant_sim:plant.* overrides (the plant under test); the estimator
and controller keep config/'s nominal values, as on a bench, so -p for any other node is
refused. Lock-step by default (deterministic), --mode realtime on the wall clock.
bridge: hardware_bridge to the PLC at ads.host:ads.tcp_port of config/hardware_bridge.yaml
(a bench, or scripts/ads_peer started beside it), in real time (lock-step with the test peer
run as scripts/ads_peer --lockstep: a PLC keeps its own clock). The PLC must answer and the
drive must be armed: identify arms it (activates hardware_bridge once the arming conditions
hold) only with --activate, the operator's explicit choice; without it, it refuses.

Bad input (an unknown -p key, an unreachable or unarmed drive, DIR already holding an
identification, a missing recording, an experiment beyond the actuator's limits) is one line
and exit 2, with nothing written but DIR/identify.log. A failed experiment (the safe state, a
node that died) ends the run with exit 1 and run_stack's reason; its recording is kept.
"""
from __future__ import annotations

import argparse
import datetime
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import yaml

from ..core.config.cli import UsageError, guarded, interrupt_on_signals, stopping
from ..core.config.params import ParamError, default_config_dir
from ..core.ident.experiments import KINDS

PROG = 'identify'
FITTED = ('identification.json', 'identified.yaml', 'report.md')   # a DIR holding a fit
PLANT_KEYS = ('plant.', 'sim_node.seed')   # what -p may set on plant_sim
FIT = 'eha_ros.core.ident.pipeline'
PROGRESS_S = 5.0                           # s between progress lines
HUNG = '(stopped or hung)'                 # run_stack's stop reason for a node fallen silent
HUNG_RETRIES = 2
FINISHED = 'experiment finished'           # run_stack's stop reason: the plan ran to its end


def experiments_text(config_dir: str) -> str:
    """One line per experiment with its plant time, from the config folder's files."""
    try:
        plans = build_plans(config_dir, KINDS)
    except (UsageError, ParamError) as err:
        return f'experiments: cannot read them from {config_dir}: {err}'
    lines = textwrap.wrap('experiments (config/experiment.yaml), each with its plant time; '
                          'lock-step takes about 2-3x that in wall time on 2 cores, plus about '
                          '15 s to start each stack:', 100)
    for kind, plan in plans.items():
        lines += textwrap.wrap(plan.summary, 100, initial_indent=f'  {kind:10s} '
                               f'{plan.duration_s:5.1f} s  ', subsequent_indent=' ' * 22)
    total = sum(p.duration_s for p in plans.values())
    lines.append(f'  {"all":10s} {total:5.1f} s')
    return '\n'.join(lines)


def parse(argv):
    config = default_config_dir()
    for i, a in enumerate(argv[:-1]):          # --help shows the experiments of --config
        if a == '--config':
            config = argv[i + 1]
    ap = argparse.ArgumentParser(prog='scripts/identify', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=experiments_text(config))
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument('--plant', choices=('sim', 'bridge'),
                     help='run the experiments on plant_sim or through hardware_bridge')
    src.add_argument('--recordings', nargs='+', metavar='PATH',
                     help='fit these recordings (MCAP, one per experiment); run nothing')
    ap.add_argument('--out', default=None,
                    help='output folder (default out/identify/<time>); must not hold an '
                         'identification')
    ap.add_argument('--mode', choices=('lockstep', 'realtime'), default=None,
                    help='--plant sim: lockstep (default) or realtime; --plant bridge: realtime '
                         '(default), lockstep only with the ADS test peer run with --lockstep')
    ap.add_argument('-p', dest='params', action='append', default=[],
                    metavar='plant_sim:KEY:=VALUE',
                    help='--plant sim: a parameter of the simulated plant (plant.*, or '
                         'sim_node.seed), repeatable')
    ap.add_argument('--activate', action='store_true',
                    help='--plant bridge: arm the drive (activate hardware_bridge) once the '
                         'arming conditions hold; without it identify refuses an unarmed drive')
    ap.add_argument('--experiments', default=','.join(KINDS), metavar='LIST',
                    help=f'comma list, in this order (default: {",".join(KINDS)})')
    ap.add_argument('--no-fit', action='store_true',
                    help='run and record the experiments only (fit later with --recordings)')
    ap.add_argument('--config', default=config, help='config folder (default config/)')
    ap.add_argument('--domain-id', type=int, default=None, metavar='N',
                    help='ROS domain of the stacks (run_stack --domain-id)')
    ap.add_argument('--start-timeout', type=float, default=120.0,
                    help='each stack must run (the drive armed) within this many seconds')
    return ap.parse_args(argv)


# ------------------------------------------------------------------ checks (nothing written)
def build_plans(config_dir: str, kinds) -> dict:
    """{kind: Plan} from the config folder, as the experiment node builds them."""
    from ..core.ident.experiments import build
    from ..core.ident.params import SCHEMA
    from ..core.sim.batch import node_params
    p = node_params('experiment', SCHEMA, config_dir)
    return {k: build(p, k) for k in kinds}


def plant_overrides(items, config_dir: str) -> list[str]:
    """The -p items, checked: plant_sim's plant.* (or sim_node.seed), values in range."""
    from ..core.hardware.sim_params import SCHEMA
    from ..core.sim.batch import node_params
    over = {}
    for item in items:
        node, sep, rest = item.partition(':')
        key, sep2, text = rest.partition(':=')
        if not (sep and sep2):
            raise UsageError(f'-p {item!r}: expected plant_sim:KEY:=VALUE')
        if node != 'plant_sim':
            raise UsageError(f'-p {item!r}: identify changes the simulated plant only '
                             f'(plant_sim): the estimator and controller keep config/\'s '
                             f'nominal values, as on a bench')
        if not key.startswith(PLANT_KEYS):
            raise UsageError(f'-p {item!r}: {key} is not a plant parameter: expected plant.* '
                             f'(or sim_node.seed, the noise seed)')
        try:
            over[f'plant_sim:{key}'] = yaml.safe_load(text) if text else ''
        except yaml.YAMLError:
            over[f'plant_sim:{key}'] = text
    node_params('plant_sim', SCHEMA, config_dir, over)      # unknown key, range: ParamError
    return [x for item in items for x in ('-p', item)]


def check_out(out: str, runs: bool) -> None:
    """DIR holds no identification: no fit's output, and when experiments are to run, no
    recordings (--recordings may fit DIR/recordings/ of a --no-fit run into DIR)."""
    held = [f for f in FITTED + (('recordings',) if runs else ())
            if os.path.exists(os.path.join(out, f))]
    if held:
        raise UsageError(f'--out {out} already holds an identification ({held[0]}): give '
                         f'another folder')
    if os.path.exists(out) and not os.path.isdir(out):
        raise UsageError(f'--out {out}: not a folder')


def fit_function():
    """fit_recordings, or a one-line UsageError when the fitting is not in this tree."""
    try:
        from importlib import import_module
        return import_module(FIT).fit_recordings
    except (ImportError, AttributeError) as err:
        raise UsageError(f'the fitting ({FIT}.fit_recordings) is not available here ({err}): '
                         f'run the experiments with --no-fit and fit their recordings later '
                         f'with --recordings') from None


def probe_drive(config_dir: str) -> str:
    """The PLC of config/hardware_bridge.yaml answers with a matching symbol table and its
    drive reports no fault on the active couple; what it said, or a UsageError."""
    from ..core.hardware.bridge_params import SCHEMA
    from ..core.hardware.ads import AdsHardware
    from ..core.hardware.interface import HardwareError
    from ..core.stats import Counters
    from ..core.sim.batch import node_params
    p = node_params('hardware_bridge', SCHEMA, config_dir)
    if p['bridge.backend'] != 'ads':
        raise UsageError(f'--plant bridge: bridge.backend is {p["bridge.backend"]!r} in '
                         f'{config_dir}/hardware_bridge.yaml: expected ads (a drive to identify)')
    hw = AdsHardware(p, Counters(), p['bridge.stale_limit'])
    hw.link.log_level = 4                   # AdsLib silent: the refusal is our one line
    try:
        hw.configure()
        r = hw.read(time.monotonic())
    except HardwareError as err:
        raise UsageError(f'--plant bridge: the drive is not reachable: {err} (a bench: check '
                         f'ads.host/ads.tcp_port in {config_dir}/hardware_bridge.yaml; the '
                         f'test peer: start scripts/ads_peer)') from None
    finally:
        hw.link.close()
    couple = 'AB'[r.active_channel]
    if r.active_fault:
        raise UsageError(f'--plant bridge: the drive of couple {couple} reports a fault: it '
                         f'cannot be armed (clear it at the drive)')
    return f'PLC {hw.link.address} answers; couple {couple} active, no drive fault'


class Job:
    """What to run, all checked: raises UsageError/ParamError before anything is written."""

    def __init__(self, args):
        self.args = args
        self.out = args.out
        self.config = os.path.abspath(args.config)
        check_out(self.out, runs=not args.recordings)
        self.fit = None
        self.recordings = []
        self.plans, self.params, self.drive = {}, [], ''
        if args.recordings:
            for opt, given in (('--plant', args.plant), ('-p', args.params),
                               ('--activate', args.activate), ('--mode', args.mode)):
                if given:
                    raise UsageError(f'--recordings fits recordings made elsewhere: {opt} '
                                     f'does not apply (nothing runs)')
            if args.no_fit:
                raise UsageError('--recordings with --no-fit would do nothing')
            missing = [r for r in args.recordings if not os.path.isfile(r)]
            if missing:
                raise UsageError(f'--recordings: {missing[0]}: no such file')
            self.recordings = list(args.recordings)
            self.fit = fit_function()
            return
        kinds = [k.strip() for k in args.experiments.split(',') if k.strip()]
        bad = [k for k in kinds if k not in KINDS]
        if bad or not kinds or len(set(kinds)) != len(kinds):
            raise UsageError(f'--experiments {args.experiments!r}: expected distinct names '
                             f'among {",".join(KINDS)}')
        self.kinds = [k for k in KINDS if k in kinds]
        self.plans = build_plans(self.config, self.kinds)
        self.mode = args.mode or ('lockstep' if args.plant == 'sim' else 'realtime')
        if not 0 < args.start_timeout < 1e6:
            raise UsageError(f'--start-timeout {args.start_timeout:g}: expected > 0 s')
        if args.plant == 'sim':
            if args.activate:
                raise UsageError('--activate arms a drive: it applies to --plant bridge')
            self.params = plant_overrides(args.params, self.config)
            self.fit = None if args.no_fit else fit_function()
            return
        if args.params:
            raise UsageError('-p changes the simulated plant: --plant bridge runs the drive as '
                             'it is')
        self.drive = probe_drive(self.config)
        if not args.activate:
            raise UsageError('--plant bridge: the drive is not armed, and identify arms it only '
                             'when told: add --activate (the experiments move the piston and '
                             'apply loads; hardware_bridge arms once its arming conditions hold)')
        self.fit = None if args.no_fit else fit_function()


# ------------------------------------------------------------------ running
class Log:
    """identify's lines: printed and appended to DIR/identify.log."""

    def __init__(self, out: str):
        self.path = os.path.join(out, 'identify.log')
        self.fh = None

    def open(self):
        os.makedirs(os.path.dirname(self.path), exist_ok=True)
        self.fh = open(self.path, 'a', encoding='utf-8')

    def __call__(self, line: str, show: bool = True):
        if show:
            print(line, flush=True)
        if self.fh is not None:
            self.fh.write(line + '\n')
            self.fh.flush()

    def file_only(self, line: str):
        """The refusal's line, when DIR can be written (nothing else is)."""
        try:
            if self.fh is None:
                self.open()
            self(line, show=False)
        except OSError:
            pass


def run_experiment(job: Job, kind: str, log: Log) -> str:
    """One experiment through run_stack; the path of its recording under DIR/recordings/.
    Without a real drive (plant_sim, or the ADS test peer in lock-step), a run stopped because a
    node fell silent (a hung process, not the actuator: see docs/identification.md) is run
    again, at most HUNG_RETRIES times; nothing else is."""
    plan = job.plans[kind]
    log(f'{PROG}: {kind}: {plan.summary}; {plan.duration_s:.1f} s of plant time')
    for attempt in range(HUNG_RETRIES + 1):
        name = kind if attempt == 0 else f'{kind}-retry{attempt}'
        folder, reason, t0 = run_stack(job, kind, name, log)
        if not reason:
            break
        simulated = job.args.plant == 'sim' or job.mode == 'lockstep'
        if not simulated or HUNG not in reason or attempt == HUNG_RETRIES:
            raise ExperimentFailed(f'experiment {kind} failed: {reason} (logs: {folder}/logs/)')
        log(f'{PROG}: {kind}: run_stack stopped ({reason}): a hung node, not the actuator; '
            f'running it again ({attempt + 2} of {HUNG_RETRIES + 1})')
    path = os.path.join(job.out, 'recordings', f'{kind}.mcap')
    os.makedirs(os.path.dirname(path), exist_ok=True)
    os.replace(os.path.join(folder, 'recording.mcap'), path)
    log(f'{PROG}: {kind}: recorded {path} ({os.path.getsize(path) / 1e6:.1f} MB) in '
        f'{time.monotonic() - t0:.0f} s')
    return path


def run_stack(job: Job, kind: str, name: str, log: Log) -> tuple[str, str, float]:
    """scripts/run_stack --record --experiment KIND into DIR/runs/NAME, its lines logged (its
    progress as a share of the plan); (folder, '' or why it failed, start time). A refusal
    (exit 2, or a drive that could not be armed) is a UsageError, its folder removed."""
    from ..stack import spawn
    args, plan = job.args, job.plans[kind]
    runs = os.path.join(job.out, 'runs')
    cmd = [sys.executable, '-m', 'eha_ros.tools.run_stack', '--mode', job.mode, '--record',
           '--experiment', kind, '--out', runs, '--name', name, '--progress', f'{PROGRESS_S:g}',
           '--config', job.config, '--start-timeout', f'{args.start_timeout:g}']
    if kind == 'drive':
        cmd.append('--no-controller')
    if args.plant == 'bridge':
        cmd += ['--plant', 'bridge', '--no-peer'] + (['--activate'] if args.activate else [])
    if args.domain_id is not None:
        cmd += ['--domain-id', str(args.domain_id)]
    cmd += job.params
    n = plan.n_ticks + int(round(1.0 / plan.Ts))          # + about the node's start delay
    log(f'{PROG}: {kind}: {" ".join(cmd[1:])}', show=False)
    t0 = time.monotonic()
    proc = spawn(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    last = ''
    try:
        for line in proc.stdout:
            line = last = line.rstrip()
            m = re.match(r'run_stack: +([\d.]+) s: ticks (\d+)', line)
            if m:
                log(line, show=False)
                log(f'{PROG}: {kind}: {min(99, 100 * int(m.group(2)) // n):3d} % (tick '
                    f'{m.group(2)} of ~{n}), {time.monotonic() - t0:.0f} s')
            else:
                log(f'  {line}')
        rc = proc.wait()
    except KeyboardInterrupt:
        stopping()
        os.killpg(proc.pid, signal.SIGINT)      # its own session: it stops its stack cleanly
        proc.wait()
        log(f'{PROG}: interrupted during {kind}; its run folder: {os.path.join(runs, name)}')
        raise
    folder = os.path.join(runs, name)
    reason, errors = stack_summary(folder)
    if reason == FINISHED and errors:      # the plan ran to its end; another node's alarm
        log(f'{PROG}: {kind}: finished; ERROR on /diagnostics from {", ".join(sorted(errors))} '
            f'during the run (an alarm, not the safe state: that stops the experiment): '
            f'{folder}/stack.json')
    if rc == 2 or (args.plant == 'bridge' and reason.startswith('lifecycle: hardware_bridge')):
        shutil.rmtree(folder, ignore_errors=True)       # refused: nothing ran
        why = reason or last.split('error: ', 1)[-1]
        raise UsageError(f'{kind}: run_stack refused: {why}')
    ok = rc == 0 or reason == FINISHED
    return folder, '' if ok else reason or f'run_stack exit code {rc}', t0


def stack_summary(folder: str) -> tuple[str, dict]:
    """(stop reason, ERRORs on /diagnostics) of a run_stack run folder's stack.json."""
    import json
    try:
        with open(os.path.join(folder, 'stack.json')) as fh:
            doc = json.load(fh)
        return doc.get('stop_reason', ''), doc.get('errors') or {}
    except (OSError, ValueError):
        return '', {}


class ExperimentFailed(Exception):
    """An experiment that ran and failed (exit 1): its reason, one line."""


def run(args, log: Log) -> int:
    job = Job(args)
    log.open()
    log(f'{PROG}: {" ".join(sys.argv[1:]) if sys.argv[1:] else ""}'.rstrip(), show=False)
    paths = job.recordings
    if not paths:
        if job.drive:
            log(f'{PROG}: bridge: {job.drive}')
        total = sum(p.duration_s for p in job.plans.values())
        log(f'{PROG}: {len(job.kinds)} experiments on {args.plant} ({job.mode}), '
            f'{total:.1f} s of plant time, into {job.out}/')
        try:
            paths = [run_experiment(job, k, log) for k in job.kinds]
        except ExperimentFailed as err:
            log(f'{PROG}: FAILED: {err}')
            return 1
    if job.fit is None:
        log(f'{PROG}: recordings in {job.out}/recordings/; not fitted (--no-fit)')
        return 0
    log(f'{PROG}: fitting {len(paths)} recordings into {job.out}/')
    t0 = time.monotonic()
    job.fit(paths, job.out, config_dir=job.config, log=log)
    log(f'{PROG}: fitted in {time.monotonic() - t0:.0f} s: {job.out}/identified.yaml, '
        f'identification.json, report.md')
    return 0


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    interrupt_on_signals()
    args.out = args.out or os.path.join(
        'out', 'identify', datetime.datetime.now().strftime('%Y%m%d-%H%M%S'))
    log = Log(args.out)

    def body():
        try:
            return run(args, log)
        except (UsageError, ParamError) as err:
            log.file_only(f'{PROG}: error: {err}')
            raise
    return guarded(PROG, body)


if __name__ == '__main__':
    sys.exit(main())
