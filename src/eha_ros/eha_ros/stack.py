"""Start the stack's nodes as separate processes with their parameter files; stop them cleanly.

Used by scripts/run_stack, scripts/run and the DDS tests, so that every way of running the
stack starts the same executables with the same YAML.
"""
from __future__ import annotations

import ctypes
import functools
import os
import signal
import subprocess
import sys
import time

from .core.config.params import default_config_dir
# plant-side nodes and the prefix of their loop parameters (core.hardware.params.loop_params):
# their own lock-step switch (they publish /clock; the others use sim time) and start gate
from .core.config.registry import (LOOP_NODES as _LOOP, LOOP_PREFIX, LOOP_TOOLS, NODE_FILES,
                                   PLANT_NODES)


def proc_stat(pid: int) -> list[str]:
    """The fields of /proc/<pid>/stat after the command name (proc(5) numbering minus 3:
    [0] state, [1] parent pid, [11] utime, [12] stime); OSError when there is no such pid."""
    with open(f'/proc/{pid}/stat') as fh:
        return fh.read().rsplit(')', 1)[1].split()


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (all threads), from /proc."""
    fields = proc_stat(pid)
    ticks = os.sysconf('SC_CLK_TCK')
    return (int(fields[11]) + int(fields[12])) / ticks


PR_SET_PDEATHSIG = 1                     # prctl(2) option (linux/prctl.h)
try:
    _prctl = ctypes.CDLL(None, use_errno=True).prctl     # loaded here, not in the child
except (OSError, AttributeError):        # not Linux: no parent-death signal
    _prctl = None


def _die_with_parent(parent: int) -> None:
    """In the child before exec: SIGTERM when the parent exits (kept across exec); if the
    parent is already gone (it died between fork and here), exit at once."""
    if _prctl is not None:
        _prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:
        os._exit(143)


def spawn(cmd, **kw) -> subprocess.Popen:
    """Popen in a session of its own (Ctrl-C in the terminal reaches the parent, which
    stops the children in order) that dies with its parent: on Linux the kernel sends the
    child SIGTERM when the process that started it exits for any reason, SIGKILL included
    (prctl PR_SET_PDEATHSIG), and every node stops cleanly on SIGTERM. Precisely: when the
    *thread* that started it ends, so start children from a thread that lives as long as
    they should (the main thread, as run_stack, scripts/run and the tests do)."""
    return subprocess.Popen(cmd, start_new_session=True,
                            preexec_fn=functools.partial(_die_with_parent, os.getpid()), **kw)


def node_command(name: str, config_dir: str | None = None, extra=(), files=None) -> list[str]:
    """Executable (next to this interpreter, i.e. in the venv) + --ros-args with params files."""
    config_dir = config_dir or default_config_dir()
    exe = os.path.join(os.path.dirname(sys.executable), name)
    args = [exe, '--ros-args']
    for f in (files if files is not None else NODE_FILES[name]):
        args += ['--params-file', os.path.join(config_dir, f)]
    return args + list(extra)


# the 1 kHz loop: what eha_loop can host in one process (plant side first), and the tools that
# answer its ticks (the experiment node)
LOOP_NODES = PLANT_NODES + _LOOP + LOOP_TOOLS


def composed_command(nodes, config_dir: str | None = None, extra=None) -> list[str]:
    """eha_loop hosting ``nodes`` (plant side + loop nodes) with the union of their params
    files; per-node ``extra`` arguments (-p name:key:=value form) are passed through."""
    plant = 'bridge' if 'hardware_bridge' in nodes else 'sim'
    others = [n for n in nodes if n not in PLANT_NODES]
    files: list[str] = []
    for n in nodes:
        files += [f for f in NODE_FILES[n] if f not in files]
    args = ['--plant', plant, '--nodes', ','.join(others)]
    cmd = node_command('eha_loop', config_dir, files=files)
    cmd[1:1] = args
    for n in nodes:
        cmd += list((extra or {}).get(n, ()))
    return cmd


class Stack:
    """Context manager: processes started by :func:`spawn` (their own sessions, dying with
    this process), SIGINT then SIGKILL on exit.

    composed=True runs the loop nodes among ``nodes`` (LOOP_NODES) as one eha_loop process
    (in-process topics between them; real time only), listed as 'eha_loop' in procs.
    ``record='path.mcap'`` adds the recorder (every /eha topic and /diagnostics): it starts
    first and stops last, after the other nodes have exited, so their last messages are in;
    composed, it is a guest of eha_loop (the loop topics in-process, none over DDS for it),
    and eha_loop stops last.
    ``live=PORT`` adds the live node (the same topics over the Foxglove WebSocket protocol on
    that port, 0: any free one): composed, inside eha_loop (it takes the loop topics
    in-process), else as its own process."""

    def __init__(self, nodes, config_dir=None, extra=None, log_dir=None, env=None,
                 lockstep: bool = False, composed: bool = False, record: str | None = None,
                 ads_peer: bool = False, live: int | None = None):
        if composed and lockstep:
            raise ValueError('lock-step runs every node as its own process')
        self.nodes = list(nodes)
        self.ads_peer = ads_peer       # start the ADS test peer (plant behind ADS) for the bridge
        self.lockstep = lockstep
        self.composed = [n for n in self.nodes if n in LOOP_NODES] if composed else []
        if self.composed and live is not None and 'live' not in self.nodes:
            self.composed.append('live')
        if self.composed and record and 'recorder' not in self.nodes:
            self.composed.append('recorder')     # a guest: the loop topics in-process
        self.record = record
        self.live = live
        self.config_dir = config_dir
        self.extra = {k: list(v) for k, v in (extra or {}).items()}
        for name in self.nodes:
            pre = LOOP_PREFIX.get(name)
            args = self.extra.setdefault(name, [])
            if lockstep:       # the plant steps per command and publishes /clock; others follow it
                args += ['-p', f'{name}:{pre}.lockstep:=true'] if pre else \
                    ['-p', 'use_sim_time:=true']
            if pre and record:  # the plant side holds tick 0 until the recorder has subscribed
                args += ['-p', f'{name}:{pre}.start_after:=[recorder]']
            if name == 'experiment' and record:          # and the plan its start
                args += ['-p', 'experiment:experiment.start_after:=[recorder]']
        if record:
            self.extra.setdefault('recorder', [])
            self.extra['recorder'] += ['-p', f'recorder:recorder.output:={record}']
        if live is not None:
            self.extra.setdefault('live', [])
            self.extra['live'] += ['-p', f'live:live.port:={int(live)}'] + \
                (['-p', 'use_sim_time:=true'] if lockstep else [])
        self.log_dir = log_dir
        self.env = dict(os.environ, **(env or {}))
        self.env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        self.procs: dict[str, subprocess.Popen] = {}
        self.recovered: dict | None = None     # recording.recover's result, when it ran
        self._logs = []

    def commands(self) -> dict:
        """{process name: command line} of what start() runs (the recorder first)."""
        cmds = {}
        if self.ads_peer:
            cmds['ads_peer'] = [sys.executable, '-m', 'eha_ros.tools.ads_peer'] + \
                (['--config', self.config_dir] if self.config_dir else []) + \
                (['--lockstep'] if self.lockstep else [])
        if self.record and 'recorder' not in self.nodes + self.composed:
            cmds['recorder'] = node_command('recorder', self.config_dir,
                                            self.extra.get('recorder', ()))
        if self.live is not None and 'live' not in self.nodes + self.composed:
            cmds['live'] = node_command('live', self.config_dir, self.extra.get('live', ()))
        if self.composed:
            cmds['eha_loop'] = composed_command(self.composed, self.config_dir, self.extra)
        for name in self.nodes:
            if name not in self.composed:
                cmds[name] = node_command(name, self.config_dir, self.extra.get(name, ()))
        return cmds

    def start(self):
        for name, cmd in self.commands().items():
            if self.log_dir:
                os.makedirs(self.log_dir, exist_ok=True)
                log = open(os.path.join(self.log_dir, f'{name}.log'), 'w')
                self._logs.append(log)
                out = err = log
            else:
                out, err = subprocess.DEVNULL, subprocess.PIPE
            self.procs[name] = spawn(cmd, env=self.env, stdout=out, stderr=err, text=True)
        return self

    def process_of(self, node: str) -> str:
        """The process that runs ``node`` (eha_loop for a composed one)."""
        return 'eha_loop' if node in self.composed else node

    def dead(self) -> dict:
        """Nodes that exited, with their exit codes."""
        return {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}

    def stop(self, timeout: float = 10.0) -> dict:
        """SIGINT all (the recorder's process last: eha_loop when it hosts the recorder),
        wait, SIGKILL stragglers; returns {name: (returncode, stderr)}."""
        end = time.monotonic() + timeout
        last = self.process_of('recorder') if self.record else None
        nodes = {n: p for n, p in self.procs.items() if n != last}
        out = self._stop_group(nodes, end)
        if last in self.procs:             # after the others: their last messages are recorded
            out.update(self._stop_group({last: self.procs[last]},
                                        max(end, time.monotonic() + 5.0)))
            if out[last][0] != 0 and os.path.exists(self.record):
                from .core.io.recording import finished
                if not finished(self.record):    # eha_loop may end 1 for another reason
                    self.recovered = self._recover()
        for log in self._logs:
            log.close()
        return out

    def _recover(self) -> dict:
        """The recorder did not finish its file (killed, or failed): make it a finished one
        with everything that reached the disk (recording.recover)."""
        from .core.io.recording import recover
        try:
            return recover(self.record)
        except OSError as err:
            return {'error': f'{self.record}: recovery failed: {err.strerror or err} (it still '
                             f'reads with core.io.recording.read, up to its last complete chunk; '
                             f'core.io.recording.recover finishes it once there is room)'}

    @staticmethod
    def _stop_group(procs: dict, end: float) -> dict:
        for p in procs.values():
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGINT)
                    os.killpg(p.pid, signal.SIGCONT)     # a stopped one acts on it too
                except ProcessLookupError:
                    pass
        out = {}
        for name, p in procs.items():
            try:
                _, err = p.communicate(timeout=max(0.1, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                _, err = p.communicate()
            out[name] = (p.returncode, err or '')
        return out

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
