"""Watch a running stack from outside: the nodes' /diagnostics and the processes' CPU.

Used by scripts/run_stack (progress lines, stack.json) and scripts/bench stack.
"""
from __future__ import annotations

import threading
import time

from .stack import cpu_seconds


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
        self._own_context = not rclpy.ok()
        if self._own_context:
            rclpy.init()
        self.node = rclpy.create_node(name)
        self.latest: dict[str, dict] = {}
        self.levels: dict[str, int] = {}
        self.arrival: dict[str, float] = {}          # monotonic time of the latest per name
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
                self.levels[s.name] = s.level[0] if isinstance(s.level, bytes) else int(s.level)
                self.arrival[s.name] = time.monotonic()

    def _spin(self):
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.1)

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
