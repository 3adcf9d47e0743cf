"""Helpers for tests that talk DDS: deterministic sample messages, subprocess nodes, waiting."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import zlib

from eha_ros.core.io.ports import free_port  # noqa: F401  (the tests import it from here)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV_BIN = os.path.join(ROOT, '.venv', 'bin')

MSG_TYPES = ['ActuatorState', 'PlantTruth', 'PositionEstimate', 'PositionReference',
             'ActuatorCommand', 'RedundancyStatus', 'ExternalLoad', 'ChannelSelect']

# The step's steady error against the truth over DDS: one run is one noise realization. Issue
# 42's 20 um is sensor-limited (the position sensor's 1 Hz Gauss-Markov error: the best linear
# estimate of a constant from 1.35 s of it has a sigma of 8.8 um, so even an ideal estimator
# misses 20 um on 2.3 % of runs); Table 4.5 on the held-out seeds misses it on 6.1 % of 1350 runs,
# p99 28.1 um, worst 36.2 um (docs/measurements.md). A single run is held to that worst + margin;
# the 20 um verdict is printed.
STEP_STEADY_LIMIT = 40e-6


def _value(field: str, ftype: str, salt: int):
    """A distinctive value for a field, the same in every process."""
    h = zlib.crc32(f'{field}:{salt}'.encode())
    if ftype.startswith('sequence') or '[' in ftype:
        base = ftype.split('[')[0].replace('sequence<', '').rstrip('>')
        n = int(ftype.split('[')[1].rstrip(']')) if '[' in ftype else 2
        return [_value(f'{field}{i}', base, salt) for i in range(n)]
    if ftype == 'boolean':
        return bool(h & 1)
    if ftype in ('double', 'float'):
        return (h % 100000) / 7.0 - 5000.0
    if ftype.startswith('uint'):
        return h % (2 if field in ('channel', 'active_channel') else 250)
    if ftype.startswith('int'):
        return h % 120 - 60
    if ftype == 'string':
        return f'{field}-{h:x}'
    raise TypeError(ftype)


def fill(msg, salt: int = 1):
    """Fill every field of a ROS message (recursively into std_msgs/Header)."""
    for field, ftype in msg.get_fields_and_field_types().items():
        if ftype == 'std_msgs/Header':
            msg.header.frame_id = f'frame-{salt}'
            msg.header.stamp.sec = 1000 + salt
            msg.header.stamp.nanosec = 123456 + salt
            continue
        setattr(msg, field, _value(field, ftype, salt))
    return msg


def start_process(args, env=None, **kw) -> subprocess.Popen:
    """Start a node/peer as a separate process in its own process group (dying with the
    test process: stack.spawn)."""
    from eha_ros.stack import spawn
    full_env = dict(os.environ)
    full_env.update(env or {})
    return spawn(args, env=full_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                 text=True, **kw)


def stop_process(proc: subprocess.Popen, timeout: float = 10.0):
    """SIGINT, then SIGKILL; returns (returncode, stdout, stderr)."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGINT)
        except ProcessLookupError:
            pass
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
    return proc.returncode, out, err


def python_module(module: str, *args) -> list:
    return [sys.executable, '-m', module, *args]


class Spinner:
    """Spin an rclpy node in a background thread for the duration of a test."""

    def __init__(self, node, executor=None):
        from rclpy.executors import SingleThreadedExecutor
        self.node = node
        self.executor = executor or SingleThreadedExecutor()
        self.executor.add_node(node)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def close(self):
        self._stop.set()
        self.thread.join(timeout=5)
        self.executor.remove_node(self.node)


def wait_for(pred, timeout: float, period: float = 0.02) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(period)
    return pred()


def wait_matched(*publishers, timeout: float = 60.0):
    """Block until every publisher has matched a subscriber: a message published before
    discovery has paired the two ends is dropped (volatile QoS), and a loaded machine can take
    seconds to discover a new publisher."""
    assert wait_for(lambda: all(p.get_subscription_count() > 0 for p in publishers), timeout), \
        'no subscriber matched: ' + ', '.join(p.topic_name for p in publishers
                                              if p.get_subscription_count() == 0)


def wait_fed(*subscriptions, publishers: int = 1, timeout: float = 60.0):
    """Block until every subscription has matched ``publishers`` publishers: what a node under
    test publishes before discovery has paired it with the test's subscription is lost
    (volatile QoS), and the graph (count_publishers) shows a publisher before DDS has matched
    it."""
    assert wait_for(lambda: all(s.get_publisher_count() >= publishers for s in subscriptions),
                    timeout), 'no publisher matched: ' + ', '.join(
        s.topic_name for s in subscriptions if s.get_publisher_count() < publishers)
