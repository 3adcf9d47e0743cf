"""Watch a running stack from outside: the nodes' /diagnostics and the processes' CPU.

Used by scripts/run_stack (progress lines, stack.json) and scripts/bench stack.
"""
from __future__ import annotations

import os
import threading
import time

from .core.config.cli import UsageError
from .stack import cpu_seconds
from .core import topics as T

ERROR = 2                       # diagnostic_msgs/DiagnosticStatus ERROR (3: STALE)
PLANT_TOPIC = T.STATE.path      # published by exactly one plant side per stack
DISCOVERY_WAIT = 2.0            # [s] to see the publishers already on the domain


def parse_value(text: str):
    """Diagnostic values travel as strings: numbers back to int/float, the rest as is."""
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {'True': True, 'False': False}.get(text, text)


class DiagMonitor:
    """Latest /diagnostics values per status name ('<node>: <what>'), spun on a thread."""

    def __init__(self, name: str = 'stack_monitor'):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        self._own_context = not rclpy.ok()
        if self._own_context:        # signals stay the program's (cli.interrupt_on_signals):
            rclpy.init(signal_handler_options=SignalHandlerOptions.NO)   # rclpy's would end
            # this context on SIGTERM and leave the program running without its monitor
        self.node = rclpy.create_node(name)
        self.latest: dict[str, dict] = {}
        self.levels: dict[str, int] = {}
        self.arrival: dict[str, float] = {}          # monotonic time of the latest per name
        self.errors: dict[str, tuple[float, str]] = {}   # first ERROR/STALE per name: (t, message)
        self.lock = threading.Lock()
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 100)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._spin, name='diag_monitor', daemon=True)
        self.thread.start()

    def _on_diag(self, msg):
        with self.lock:
            for s in msg.status:
                self.latest[s.name] = {v.key: parse_value(v.value) for v in s.values}
                level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
                self.levels[s.name] = level
                self.arrival[s.name] = now = time.monotonic()
                if level >= ERROR and s.name not in self.errors:
                    self.errors[s.name] = (now, s.message)

    def _spin(self):
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.1)

    def new_errors(self, seen: set) -> list[tuple[str, float, str]]:
        """(name, monotonic time, message) of first ERRORs not in ``seen`` (added to it)."""
        with self.lock:
            out = [(n, t, m) for n, (t, m) in self.errors.items() if n not in seen]
        seen.update(n for n, _, _ in out)
        return sorted(out, key=lambda e: e[1])

    def silent(self, after: float) -> dict[str, float]:
        """{node: seconds} of the nodes whose newest status (any of theirs) is older than
        ``after`` seconds: stopped (SIGSTOP), hung, or dead. Nodes never heard are not listed."""
        now, newest = time.monotonic(), {}
        with self.lock:
            for name, t in self.arrival.items():
                node = name.split(': ', 1)[0]
                newest[node] = max(newest.get(node, t), t)
        return {n: now - t for n, t in sorted(newest.items()) if now - t > after}

    def snapshot(self) -> dict:
        with self.lock:
            return {k: dict(v) for k, v in self.latest.items()}

    def find(self, prefix: str) -> dict:
        """Values of the first status whose name starts with prefix ('plant_sim: loop')."""
        snap = self.snapshot()
        for name in sorted(snap):
            if name.startswith(prefix):
                return snap[name]
        return {}

    def next_after(self, prefix: str, t: float, timeout: float = 5.0) -> tuple[dict, float]:
        """The first values of ``prefix`` that arrived after monotonic time t, and when."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                names = sorted(n for n in self.latest if n.startswith(prefix))
                if names and self.arrival[names[0]] > t:
                    return dict(self.latest[names[0]]), self.arrival[names[0]]
            time.sleep(0.01)
        raise TimeoutError(f'no /diagnostics from {prefix!r} within {timeout:g} s')

    def publishers(self, topic: str, wait: float) -> list[str]:
        """The node of each publisher of ``topic`` (one entry per publisher, sorted) as soon
        as discovery shows one (its node's name may come up to 1 s after the endpoint), else
        [] after ``wait`` seconds."""
        end, named_by = time.monotonic() + wait, None
        while True:
            infos = self.node.get_publishers_info_by_topic(topic)
            now = time.monotonic()
            if infos:
                named_by = named_by or now + 1.0
                if now >= named_by or not any(i.node_name.startswith('_NODE_NAME_UNKNOWN')
                                              for i in infos):
                    return sorted(f'{i.node_namespace.rstrip("/")}/{i.node_name}'
                                  for i in infos)
            elif now >= end:
                return []
            time.sleep(0.05)

    def wait_for(self, prefix: str, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.find(prefix):
                return True
            time.sleep(0.05)
        return False

    def close(self):
        import rclpy
        self._stop.set()
        self.thread.join(timeout=2.0)
        self.node.destroy_node()
        if self._own_context:
            rclpy.try_shutdown()


def duplicated_nodes(monitor: DiagMonitor, nodes) -> list[str]:
    """Those of ``nodes`` (names in the root namespace) the graph shows more than once: ours
    and another stack's (a lifecycle call to one of them may be answered by the other)."""
    if not nodes:
        return []
    graph = monitor.node.get_node_names_and_namespaces()
    return [f'/{n}' for n in nodes if sum(1 for g, ns in graph if g == n and ns == '/') > 1]


def refuse_second_stack(monitor: DiagMonitor, hint: str, wait: float = DISCOVERY_WAIT,
                        own: int = 0, nodes=()):
    """UsageError (one line, exit 2) when a plant other than our ``own`` (0 or 1) publishes
    PLANT_TOPIC on this ROS domain: two stacks on one domain would drive each other's nodes
    (states, commands, fault injections and lock-step clocks mix). ``hint`` says how to start
    one beside it. Checked before the start (discovery may show a stack later than ``wait``
    on a loaded machine), while our nodes are brought up (``nodes``: ours, seen twice) and
    once our own loop runs (own=1, wait=0)."""
    names = monitor.publishers(PLANT_TOPIC, wait)
    twice = duplicated_nodes(monitor, nodes)
    if len(names) > own or twice:
        raise UsageError(f'another EHA stack runs on ROS domain '
                         f'{os.environ.get("ROS_DOMAIN_ID", "0")} '
                         f'({", ".join(sorted(set(names or twice)))} publishes '
                         f'{PLANT_TOPIC}): stop it, or run this one on a domain of its own: '
                         f'{hint}')


class CpuMeter:
    """CPU share of one core per process between start() and read()."""

    def __init__(self, procs: dict):
        self.procs = procs
        self.t0 = None
        self.c0: dict = {}

    def start(self):
        self.t0 = time.monotonic()
        self.c0 = {n: self._cpu(p) for n, p in self.procs.items()}

    def over(self, seconds: float) -> dict:
        """start(), wait ``seconds``, read()."""
        self.start()
        time.sleep(seconds)
        return self.read()

    def read(self) -> dict:
        dt = max(time.monotonic() - self.t0, 1e-9)
        out = {}
        for n, p in self.procs.items():
            c = self._cpu(p)
            if c is not None and self.c0.get(n) is not None:
                out[n] = (c - self.c0[n]) / dt
        return out

    @staticmethod
    def _cpu(proc):
        try:
            return cpu_seconds(proc.pid)
        except (FileNotFoundError, ProcessLookupError, IndexError):
            return None
