"""Start the EHA stack (parameters from config/), watch it, stop it cleanly.

Real time (default): the 1 kHz loop nodes (plant_sim or hardware_bridge, estimator,
controller, switch_manager) run composed in one eha_loop process (in-process topics; see
docs/nodes/eha_loop.md for the measurements behind this), every other node in its own
process. --structure processes runs each loop node as its own process as well. Lock-step:
every node its own process, the plant steps when command(k) has arrived.
One folder per run: out/stack/<run>/ with logs/<process>.log and stack.json (commands, exit
codes, CPU per process, the nodes' last /diagnostics).
Lifecycle: run_stack is the lifecycle manager (eha_ros.lifecycle_manager). The managed nodes
(the plant side and the controller) start unconfigured; run_stack configures them, activates
the controller and then activates a simulated plant side (sim, mock). A real drive
(--plant bridge, with or without the ADS test peer) is left inactive, configured and
disarmed, until the operator activates it (/hardware_bridge/change_state activate or
/eha/bridge/arm) or --activate says so. Every state change is printed and on /diagnostics
('run_stack: lifecycle'); a transition that cannot be carried out fails the run with its
reason.
Identification (docs/identification.md): --experiment KIND adds the experiment node, which
runs one experiment of thesis section 3.6 and ends the run; KIND drive sends the motor-speed
command itself, so it runs with --no-controller (the estimator and switch manager stay: the
safe state needs them). --plant-params FILE gives plant_sim an identified plant (the plant.*
keys of FILE; estimator and controller keep config/'s nominal values).
One stack per ROS domain: run_stack refuses to start (exit 2) while another plant publishes
/eha/state on its domain; --domain-id N runs a second stack beside it. Ctrl-C, SIGTERM and
SIGHUP stop the run cleanly (stack.json and recording written); the nodes die with run_stack
whatever ends it, SIGKILL included.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import time

from ..core.config.cli import UsageError, guarded, interrupt_on_signals, require_seconds, stopping
from ..core.config.registry import LOOP_NODES as LOOP, LOOP_PREFIX
from ..core.config.params import default_config_dir, override_arg, parse_ros_args
from ..core.ident.experiments import KINDS
from ..core.io.report import reserve_json, run_dir, write_json

# an ERROR from these ends the run: the loop supervisor has put the actuator in its safe state
# (switch_manager: supervisor), the recording is failing (recorder: mcap)
STOP_ON_ERROR = {'switch_manager: supervisor': 'loop supervisor', 'recorder: mcap': 'recording'}
# [s] of wall time without any /diagnostics from a node that published before: it is stopped
# (SIGSTOP) or hung. Every node publishes at least once a second (of sim time in lock-step,
# which may run slower than the wall clock on a loaded machine)
SILENT_AFTER = {'realtime': 5.0, 'lockstep': 20.0}
PLANT_NODE = {'sim': 'plant_sim', 'bridge': 'hardware_bridge', 'mock': 'hardware_bridge'}
FINISHING = ('sweep', 'experiment')        # tool nodes whose clean exit ends the run
AUTOSTART_KEY = dict({node: f'{pre}.autostart' for node, pre in LOOP_PREFIX.items()},
                     controller='control.autostart')


def parse(argv):
    ap = argparse.ArgumentParser(prog='scripts/run_stack', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog='Node parameters: -p node:key:=value (repeatable), '
                                        'e.g. -p plant_sim:sim_node.seed:=3')
    ap.add_argument('--mode', choices=('realtime', 'lockstep'), default='realtime',
                    help='realtime (default): wall clock at 1 kHz; lockstep: the plant waits for '
                         'each command, nodes follow /clock (deterministic)')
    ap.add_argument('--plant', choices=sorted(PLANT_NODE), default='sim',
                    help='sim (default): plant_sim; bridge: hardware_bridge to the drive (left '
                         'inactive until activated); mock: hardware_bridge on its mock backend '
                         '(commands echoed into states, no physics, no PLC; activated at start)')
    ap.add_argument('--structure', choices=('auto', 'composed', 'processes'), default='auto',
                    help='auto (default): composed in real time, processes in lock-step')
    ap.add_argument('--duration', type=float, default=None,
                    help='stop after this many seconds of running loop, counted from the '
                         'first plant tick (default: run until Ctrl-C)')
    ap.add_argument('--start-timeout', type=float, default=120.0,
                    help='give up when the loop has not started after this many seconds '
                         '(the lifecycle bring-up included: a refused plant-side transition is '
                         'retried every second until then)')
    ap.add_argument('--sweep', action='store_true',
                    help='also run the sweep node (config/sweep.yaml); stop when it finishes')
    ap.add_argument('--experiment', choices=KINDS, default=None, metavar='KIND',
                    help='also run the experiment node (config/experiment.yaml) with this '
                         'identification experiment, one of ' + ', '.join(KINDS) + '; stop when '
                         'it finishes (drive: with --no-controller, it commands the drive itself)')
    ap.add_argument('--no-controller', action='store_true',
                    help='leave the controller out: another node answers /eha/state with '
                         '/eha/command (--experiment drive); the plant side alone is managed')
    ap.add_argument('--plant-params', default=None, metavar='FILE',
                    help='--plant sim: plant_sim\'s plant.* parameters from FILE too (an '
                         'identified plant, scripts/identify\'s identified.yaml), as -p '
                         'plant_sim:... overrides; the other nodes keep config/\'s values'),
    ap.add_argument('--record', action='store_true',
                    help='record every /eha topic to out/stack/<run>/recording.mcap')
    ap.add_argument('--live', action='store_true',
                    help='serve every /eha topic and /diagnostics over the Foxglove WebSocket '
                         'protocol (live node, config/live.yaml): open ws://localhost:PORT in '
                         'Foxglove or Lichtblick, layout config/foxglove/eha_layout.json')
    ap.add_argument('--live-port', type=int, default=None, metavar='PORT',
                    help='port of --live (default 8765, from config/live.yaml); implies --live. '
                         'The live node takes -p live:KEY:=VALUE like every node, e.g. -p '
                         'live:live.host:=0.0.0.0 (beyond loopback read-only unless '
                         'live.services_allow names the services a viewer may call)')
    ap.add_argument('--no-peer', action='store_true',
                    help='--plant bridge: do not start the ADS test peer (a real PLC answers at '
                         'ads.host/ads.tcp_port)')
    ap.add_argument('--activate', action='store_true',
                    help='--plant bridge: activate (arm) the drive as soon as the arming '
                         'conditions hold (explicit operator choice; default: it stays inactive '
                         'until /hardware_bridge/change_state activate or /eha/bridge/arm)')
    ap.add_argument('--no-switch-manager', action='store_true',
                    help='leave the switch manager out (channel A drives throughout)')
    ap.add_argument('-p', dest='params', action='append', default=[], metavar='NODE:KEY:=VALUE',
                    help='parameter override for one node')
    ap.add_argument('--domain-id', type=int, default=None, metavar='N',
                    help='ROS domain of this stack\'s nodes (default: ROS_DOMAIN_ID or 0); a '
                         'second stack beside a running one needs its own (0..101, 215..232)')
    ap.add_argument('--config', default=default_config_dir(), help='config folder (config/)')
    ap.add_argument('--out', default=os.path.join('out', 'stack'),
                    help='base folder of the run folders (out/stack)')
    ap.add_argument('--name', default=None, help='run folder name (default: timestamp)')
    ap.add_argument('--progress', type=float, default=5.0,
                    help='seconds between progress lines (0: none)')
    return ap.parse_args(argv)


def plan(args) -> dict:
    """What to start: nodes, structure, per-node extra arguments. Raises UsageError."""
    if args.duration is not None:
        require_seconds('--duration', args.duration)
    require_seconds('--start-timeout', args.start_timeout, 1e-3, strict=False)
    require_seconds('--progress', args.progress, 0.0, strict=False)
    if args.domain_id is not None and not (0 <= args.domain_id <= 101
                                           or 215 <= args.domain_id <= 232):
        raise UsageError(f'--domain-id {args.domain_id}: expected 0..101 or 215..232 (the ROS 2 '
                         f'domains whose ports are valid on Linux)')
    structure = args.structure
    if structure == 'auto':
        structure = 'processes' if args.mode == 'lockstep' else 'composed'
    if structure == 'composed' and args.mode == 'lockstep':
        raise UsageError('--structure composed is real time only: lock-step runs every node '
                         'as its own process')
    plant = PLANT_NODE[args.plant]
    nodes = [plant] + [n for n in LOOP
                       if not (n == 'switch_manager' and args.no_switch_manager)]
    if args.no_controller:
        nodes.remove('controller')
    if args.sweep and args.experiment:
        raise UsageError('--sweep and --experiment both drive the reference: give one')
    if args.experiment == 'drive' and not args.no_controller:
        raise UsageError('--experiment drive answers /eha/state with /eha/command itself: add '
                         '--no-controller (the controller would answer too)')
    if args.no_controller and (args.sweep or args.experiment not in (None, 'drive')):
        tool = '--sweep' if args.sweep else f'--experiment {args.experiment}'
        raise UsageError(f'--no-controller: {tool} needs the controller (it sends positions)')
    if args.sweep:
        nodes.append('sweep')
    if args.experiment:
        nodes.append('experiment')
    extra = node_overrides(args.params, nodes, live=args.live or args.live_port is not None)
    if args.experiment:
        extra.setdefault('experiment', [])[:0] = [
            '-p', f'experiment:experiment.kind:={args.experiment}', '-p',
            f'experiment:experiment.plant_side:={"sim" if args.plant == "sim" else "bridge"}']
    if args.plant_params is not None:
        if args.plant != 'sim':
            raise UsageError('--plant-params sets the simulated plant (plant_sim): expected '
                             '--plant sim')
        extra.setdefault(plant, [])[:0] = plant_overrides(args.plant_params, args.config)
    if args.live_port is not None and not 0 <= args.live_port <= 65535:
        raise UsageError(f'--live-port {args.live_port}: expected 0..65535')
    live = live_params(args, extra.get('live', ()))
    if args.no_peer and args.plant != 'bridge':
        raise UsageError('--no-peer only applies to --plant bridge')
    peer = args.plant == 'bridge' and not args.no_peer
    if args.plant == 'mock':
        extra.setdefault(plant, [])[:0] = ['-p', 'hardware_bridge:bridge.backend:=mock']
    if args.activate and args.plant != 'bridge':
        raise UsageError('--activate only applies to --plant bridge (a simulated plant side is '
                         'activated at start)')
    activate = args.plant != 'bridge' or args.activate
    if args.mode == 'lockstep' and not activate:    # an inactive drive's states all the same
        extra.setdefault(plant, []).extend(
            ['-p', f'{plant}:{LOOP_PREFIX[plant]}.lockstep_from_activation:=false'])
    return {'peer': peer, 'nodes': nodes, 'structure': structure, 'extra': extra, 'plant': plant,
            'managed': [n for n in (plant, 'controller') if n in nodes], 'activate': activate,
            'live': live['live.port'] if live else None, 'live_params': live}


def node_overrides(params, nodes, live: bool) -> dict:
    """-p node:key:=value items -> {node: ['-p', item, ...]}; the live node's only with
    ``live`` (--live or --live-port). Raises UsageError (one line)."""
    extra: dict = {}
    for item in params:
        node, sep, rest = item.partition(':')
        if not sep or ':=' not in rest:
            raise UsageError(f'-p {item!r}: expected node:key:=value')
        if node == 'live' and not live:
            raise UsageError(f'-p {item!r}: the live node is not started: add --live')
        if node not in nodes and node != 'live':
            raise UsageError(f'-p {item!r}: node {node!r} is not in this stack '
                             f'({", ".join(nodes + ["live"] if live else nodes)})')
        extra.setdefault(node, []).extend(['-p', item])
    return extra


def plant_overrides(path: str, config_dir: str) -> list[str]:
    """-p plant_sim:KEY:=VALUE of every plant.* key the params file ``path`` sets for plant_sim
    (core.hardware.sim_params.plant_file): node-targeted, so they reach plant_sim alone, also
    composed in eha_loop with the estimator and controller."""
    from ..core.hardware.sim_params import plant_file
    out = []
    for key, value in plant_file(path, config_dir).items():
        out += ['-p', f'plant_sim:{key}:={override_arg(value)}']
    return out


def build_stack(args, p: dict, out: str | None = None, managed: bool = False):
    """The Stack run_stack starts (and the launch file mirrors) for parsed options.
    ``managed``: the managed nodes start unconfigured (run_stack brings them up); otherwise
    they reach their state by themselves (autostart), as the plan says."""
    from ..stack import Stack
    extra = {k: list(v) for k, v in p['extra'].items()}
    for node in p['managed']:
        state = 'unconfigured' if managed else \
            'active' if node == 'controller' or p['activate'] else 'inactive'
        extra.setdefault(node, [])[:0] = ['-p', f'{node}:{AUTOSTART_KEY[node]}:={state}']
    if args.sweep and out:
        extra.setdefault('sweep', []).extend(
            ['-p', f'sweep:sweep.out_dir:={out}', '-p', 'sweep:sweep.run_name:=sweep'])
    return Stack(p['nodes'], args.config, extra=extra,
                 log_dir=os.path.join(out, 'logs') if out else None,
                 lockstep=args.mode == 'lockstep', composed=p['structure'] == 'composed',
                 record=os.path.join(out, 'recording.mcap') if args.record and out else None,
                 ads_peer=p['peer'], live=p['live'])


def live_params(args, live_args=()) -> dict | None:
    """--live / --live-port -> the live node's parameters (None: no live node), from
    config/live.yaml and ``live_args`` (its -p items), live.port from --live-port if given.
    Checked here: a bad one is one line before anything starts."""
    if args.live_port is None and not args.live:
        return None
    from ..core.sim.batch import node_params
    from ..core.io.live_params import SCHEMA
    _, overrides, _, _ = parse_ros_args(['--ros-args', *live_args])
    p = node_params('live', SCHEMA, args.config, overrides)
    if args.live_port is not None:
        p['live.port'] = args.live_port
    return p


def live_lines(p: dict) -> list[str]:
    """What run_stack prints about the live view: where, and beyond loopback what anyone
    who connects gets (the live node's WARN line, also in its process's log)."""
    from ..core.io.live_params import exposure, is_loopback
    host, port = p['live.host'], p['live.port']
    where = 'localhost' if is_loopback(host) or host in ('0.0.0.0', '::') else host
    where = f'[{where}]' if ':' in where else where
    lines = [f'run_stack: live view on ws://{where}:{port} (Foxglove/Lichtblick: open '
             f'connection, Foxglove WebSocket; layout config/foxglove/eha_layout.json)']
    if not is_loopback(host):
        lines.append('run_stack: WARN: ' + exposure(p, f'ws://{host}:{port}'))
    return lines


def launch_entries(argv) -> list[tuple[str, str, list[str]]]:
    """For launch/eha_stack.launch.py: (kind, executable, arguments) of every process
    run_stack would start with these options; kind 'node' (package eha_ros) or 'python'
    (a module run with the interpreter, e.g. the ADS test peer)."""
    args = parse(argv)
    entries = []
    for name, cmd in build_stack(args, plan(args)).commands().items():
        if cmd[1:2] == ['-m']:
            entries.append(('python', cmd[2], cmd[3:]))
        else:
            entries.append(('node', os.path.basename(cmd[0]), cmd[1:]))
    return entries


def wait_for_loop(stack, monitor, plant: str, timeout: float) -> str:
    """Until the plant's diagnostics count ticks: 'duration' (running) or why not."""
    end = time.monotonic() + timeout
    while loop_status(monitor, plant).get('ticks', 0) <= 0:
        dead = stack.dead()
        if dead:
            return 'node exited: ' + ', '.join(f'{n} ({c})' for n, c in dead.items())
        if time.monotonic() > end:
            return f'loop not started within {timeout:g} s'
        time.sleep(0.2)
    return 'duration'


def bring_up(manager, stack, p: dict, deadline: float, monitor=None, out: str = '') -> str:
    """The managed nodes up: '' when done, else the run's stop reason. While a transition is
    retried, another stack's node of the same name (discovery had not shown its plant before
    the start) is refused as before the start (its node may be the one answering)."""
    plant = p['plant']
    steps = [(plant, 'configure', True)]
    if 'controller' in p['managed']:
        steps += [('controller', 'configure', False), ('controller', 'activate', False)]
    if p['activate']:
        steps.append((plant, 'activate', True))

    def dead():
        gone = stack.dead()
        if not gone and monitor is not None:
            _refuse_late(stack, monitor, out, nodes=tuple(p['managed']))
        return gone
    why = manager.bring_up(steps, deadline, dead)
    if why:
        return why if why.startswith('node exited') else f'lifecycle: {why}'
    if not p['activate']:
        print(f'run_stack: lifecycle: {plant} left inactive (a real drive: configured, '
              f'disarmed); activate it with /{plant}/change_state activate or /eha/bridge/arm',
              flush=True)
    return ''


def loop_status(monitor, plant: str) -> dict:
    return monitor.find(f'{plant}: ')


def progress_line(elapsed: float, loop: dict, cpu: dict) -> str:
    ticks = loop.get('ticks', 0)
    lost = loop.get('commands_not_for_previous_tick', 0)
    share = 100.0 * lost / ticks if ticks else 0.0
    cpu_text = ', '.join(f'{n} {100 * c:.0f} %' for n, c in cpu.items())
    return (f'run_stack: {elapsed:6.1f} s: ticks {ticks}, lost {lost} ({share:.2f} %), '
            f'latency p99 {1e3 * loop.get("latency_p99_s", 0.0):.2f} ms, '
            f'overruns {loop.get("overruns", 0)}; CPU {cpu_text}')


def _refuse_late(stack, monitor, out: str, nodes=()) -> None:
    """Our loop runs (or our nodes are being brought up: ``nodes`` seen twice): a second
    plant on the domain now is another stack that discovery had not shown before the start
    (a loaded machine): stop ours, drop its run folder (nothing ran), and refuse as before
    the start."""
    from ..monitor import refuse_second_stack
    try:
        refuse_second_stack(monitor, 'scripts/run_stack --domain-id N', wait=0.0, own=1,
                            nodes=nodes)
    except UsageError:
        stopping()
        stack.stop()
        monitor.close()
        shutil.rmtree(out, ignore_errors=True)
        raise


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)
    fired = interrupt_on_signals()
    return guarded('run_stack', lambda: run(args, fired))


def run(args, signals=()) -> int:
    """``signals``: where interrupt_on_signals puts the signal that stopped the run."""
    from ..lifecycle_manager import LifecycleManager
    from ..monitor import CpuMeter, DiagMonitor, refuse_second_stack
    p = plan(args)
    if args.domain_id is not None:      # the monitor (rclpy.init) and every node read it
        os.environ['ROS_DOMAIN_ID'] = str(args.domain_id)
    monitor = DiagMonitor('run_stack')
    try:
        refuse_second_stack(monitor, 'scripts/run_stack --domain-id N')
        out = run_dir(args.out, args.name)
        try:                    # its room on the disk now: written at the end, disk full or not
            reserve_json(os.path.join(out, 'stack.json'), {'stop_reason': 'running'})
        except OSError as err:
            raise UsageError(f'{out}: cannot write the run\'s stack.json: '
                             f'{err.strerror or err}') from None
    except BaseException:
        monitor.close()
        raise
    logs = os.path.join(out, 'logs')
    stack = build_stack(args, p, out, managed=True)
    manager = LifecycleManager(monitor, p['managed'], say=lambda text: print(text, flush=True))
    stack.start()
    print(f'run_stack: {args.mode}, {p["structure"]}: started '
          f'{", ".join(stack.procs)} (logs in {logs}/)', flush=True)
    for line in live_lines(p['live_params']) if p['live_params'] else ():
        print(line, flush=True)
    cpu = CpuMeter(stack.procs)
    t_start = time.monotonic()
    reason = 'duration'
    try:
        reason = bring_up(manager, stack, p, t_start + args.start_timeout, monitor, out)
        if not reason:
            reason = wait_for_loop(stack, monitor, p['plant'], args.start_timeout)
        if reason == 'duration':
            _refuse_late(stack, monitor, out)
            print(f'run_stack: loop running after {time.monotonic() - t_start:.1f} s',
                  flush=True)
    except KeyboardInterrupt:
        reason = 'interrupted during start-up' + _signal_name(signals)
    cpu.start()
    t0 = time.monotonic()
    last_print = t0
    seen: set = set()
    try:
        while reason == 'duration':
            time.sleep(0.2)
            now = time.monotonic()
            for name, t, message in monitor.new_errors(seen):
                print(f'run_stack: {max(0.0, t - t0):6.1f} s: ERROR {name}: {message}',
                      flush=True)
                if name in STOP_ON_ERROR and reason == 'duration':
                    reason = f'{STOP_ON_ERROR[name]}: {message}'
            if reason != 'duration':
                break
            dead = stack.dead()
            done = [n for n in FINISHING if dead.get(stack.process_of(n), 1) == 0]
            if done and len(dead) == 1:
                reason = f'{done[0]} finished'
                break
            if dead:
                reason = 'node exited: ' + ', '.join(f'{n} ({c})' for n, c in dead.items())
                break
            silent = monitor.silent(SILENT_AFTER[args.mode])
            if silent:
                reason = 'no /diagnostics from ' + ', '.join(
                    f'{n} for {s:.0f} s' for n, s in silent.items()) + ' (stopped or hung)'
                break
            if args.duration is not None and now - t0 >= args.duration:
                break
            if args.progress and now - last_print >= args.progress:
                last_print = now
                print(progress_line(now - t0, loop_status(monitor, p['plant']), cpu.read()),
                      flush=True)
    except KeyboardInterrupt:
        reason = 'interrupted' + _signal_name(signals)
    stopping()
    elapsed = time.monotonic() - t0
    cpu_share = cpu.read()
    diagnostics = monitor.snapshot()
    errors = {n: {'t_s': round(t - t0, 3), 'message': m} for n, (t, m) in
              dict(monitor.errors).items()}      # before the stop: shutdown is not a fault
    results = stack.stop()
    monitor.close()
    if stack.recovered is not None:
        print(f'run_stack: the recorder did not finish {stack.record}: ' + (
            stack.recovered['error'] if 'error' in stack.recovered else
            f'recovered {stack.recovered["messages"]} messages on '
            f'{stack.recovered["topics"]} topics into a finished file'), flush=True)
    codes = {n: rc for n, (rc, _) in results.items()}
    summary = {'mode': args.mode, 'structure': p['structure'], 'plant': p['plant'],
               'processes': {n: ' '.join(c) for n, c in stack.commands().items()},
               'stop_reason': reason, 'wall_s': elapsed, 'exit_codes': codes,
               'errors': errors, 'recording_recovered': stack.recovered,
               'cpu_share': cpu_share, 'diagnostics': diagnostics}
    try:
        write_json(os.path.join(out, 'stack.json'), summary, sort_keys=True, reserved=True)
    except OSError as err:
        print(f'run_stack: FAILED: cannot write {out}/stack.json: {err.strerror or err}',
              file=sys.stderr)
        return 1
    print(progress_line(elapsed, next((v for k, v in sorted(diagnostics.items())
                                       if k.startswith(f'{p["plant"]}: ')), {}), cpu_share))
    bad = {n: c for n, c in codes.items() if c not in (0, None)}
    failed = reason != 'duration' and not reason.startswith(FINISHING + ('interrupted',)) or bad \
        or errors
    print(f'run_stack: {"FAILED: " if failed else ""}stopped ({reason}) after {elapsed:.1f} s; '
          f'{"exit codes " + str(bad) if bad else "every process exited with 0"}'
          f'{"; ERROR on /diagnostics from " + ", ".join(sorted(errors)) if errors else ""}; '
          f'{out}/stack.json')
    if failed:
        for name in bad:
            tail = _tail(os.path.join(logs, f'{name}.log'))
            print(f'run_stack: {name}: {tail}', file=sys.stderr)
        return 1
    return 0


def _signal_name(signals) -> str:
    """' by SIGTERM' etc. for the stop reason."""
    import signal
    return f' by {signal.Signals(signals[0]).name}' if signals else ''


def _tail(path: str) -> str:
    try:
        with open(path) as fh:
            lines = [ln.strip() for ln in fh if ln.strip()]
        return lines[-1] if lines else '(empty log)'
    except OSError:
        return '(no log)'


if __name__ == '__main__':
    sys.exit(main())
