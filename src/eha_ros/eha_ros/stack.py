"""Start the stack's nodes as separate processes with their parameter files; stop them cleanly.

Used by scripts/run_stack, scripts/run and the DDS tests, so that every way of running the
stack starts the same executables with the same YAML.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from .core.batch import NODE_FILES
from .core.params import default_config_dir

# plant-side nodes: their own lock-step switch (they publish /clock); the others use sim time
LOCKSTEP_PARAM = {'plant_sim': 'plant_sim:sim_node.lockstep:=true',
                  'hardware_bridge': 'hardware_bridge:bridge.lockstep:=true'}


def node_command(name: str, config_dir: str | None = None, extra=(), files=None) -> list[str]:
    """Executable (next to this interpreter, i.e. in the venv) + --ros-args with params files."""
    config_dir = config_dir or default_config_dir()
    exe = os.path.join(os.path.dirname(sys.executable), name)
    args = [exe, '--ros-args']
    for f in (files if files is not None else NODE_FILES[name]):
        args += ['--params-file', os.path.join(config_dir, f)]
    return args + list(extra)


class Stack:
    """Context manager: processes started in their own sessions, SIGINT then SIGKILL on exit."""

    def __init__(self, nodes, config_dir=None, extra=None, log_dir=None, env=None,
                 lockstep: bool = False):
        self.nodes = list(nodes)
        self.config_dir = config_dir
        self.extra = {k: list(v) for k, v in (extra or {}).items()}
        if lockstep:           # the plant steps per command and publishes /clock; others follow it
            for name in self.nodes:
                self.extra.setdefault(name, [])
                self.extra[name] += (['-p', LOCKSTEP_PARAM[name]] if name in LOCKSTEP_PARAM
                                     else ['-p', 'use_sim_time:=true'])
        self.log_dir = log_dir
        self.env = dict(os.environ, **(env or {}))
        self.env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        self.procs: dict[str, subprocess.Popen] = {}
        self._logs = []

    def start(self):
        for name in self.nodes:
            cmd = node_command(name, self.config_dir, self.extra.get(name, ()))
            if self.log_dir:
                os.makedirs(self.log_dir, exist_ok=True)
                log = open(os.path.join(self.log_dir, f'{name}.log'), 'w')
                self._logs.append(log)
                out = err = log
            else:
                out, err = subprocess.DEVNULL, subprocess.PIPE
            self.procs[name] = subprocess.Popen(cmd, env=self.env, stdout=out, stderr=err,
                                                text=True, start_new_session=True)
        return self

    def dead(self) -> dict:
        """Nodes that exited, with their exit codes."""
        return {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}

    def stop(self, timeout: float = 10.0) -> dict:
        """SIGINT all, wait, SIGKILL stragglers; returns {name: (returncode, stderr)}."""
        for p in self.procs.values():
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        end = time.monotonic() + timeout
        out = {}
        for name, p in self.procs.items():
            try:
                _, err = p.communicate(timeout=max(0.1, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                _, err = p.communicate()
            out[name] = (p.returncode, err or '')
        for log in self._logs:
            log.close()
        return out

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
