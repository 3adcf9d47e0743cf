"""Helpers for benchmarks that run nodes as separate processes: start/stop, CPU share."""
from __future__ import annotations

import os
import signal
import subprocess
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), '..', '..', '..', '..'))
CONFIG = os.path.join(ROOT, 'config')


def node_command(name: str, files: list[str], *extra: str) -> list[str]:
    """The node's executable from the venv (next to this interpreter) with params files."""
    exe = os.path.join(os.path.dirname(sys.executable), name)
    args = [exe, '--ros-args']
    for f in files:
        args += ['--params-file', os.path.join(CONFIG, f)]
    return args + list(extra)


def start(args: list[str]) -> subprocess.Popen:
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def stop(proc: subprocess.Popen, timeout: float = 10.0) -> str:
    """SIGINT and wait; returns stderr (SIGKILL if it does not stop)."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
    return err or ''


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (all threads), from /proc."""
    with open(f'/proc/{pid}/stat') as fh:
        fields = fh.read().rsplit(')', 1)[1].split()
    ticks = os.sysconf('SC_CLK_TCK')
    return (int(fields[11]) + int(fields[12])) / ticks
