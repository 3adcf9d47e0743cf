"""/diagnostics publishing shared by the nodes."""
from __future__ import annotations

import functools
import threading

from .common import publish_counted
from .compose import unlocked

_pending = threading.local()     # a reader's publishes, sent once its lock is released


def reader(method):
    """Mark a diagnostics callback that reads the state the loop thread changes. It gathers its
    values under the node's callback lock (in a composed process, eha_loop, the process-wide
    lock the loop holds for one tick at most): read beside the loop thread, the loop's dicts
    and deques raise 'changed size during iteration' (the loop supervisor's deque did, and
    ended eha_loop, while a profiler slowed its threads). Its publishes -- the message and the
    DDS write, the costly part -- run after the lock is released, so a reader holds up the
    loop only for the gathering."""
    @functools.wraps(method)
    def run(self, *args, **kwargs):
        if getattr(_pending, 'queue', None) is not None:     # a reader inside a reader
            return method(self, *args, **kwargs)
        queue = _pending.queue = []
        try:
            with self.callback_lock:
                result = method(self, *args, **kwargs)
        finally:
            _pending.queue = None
        for item in queue:
            _send(*item)
        return result
    return unlocked(run)


def publisher(node):
    from diagnostic_msgs.msg import DiagnosticArray
    return node.create_publisher(DiagnosticArray, '/diagnostics', 10)


def publish(node, pub, name: str, values: dict, level: int = 0, message: str = 'ok'):
    """One DiagnosticStatus named '<node>: <name>' with values as key/value strings (inside a
    :func:`reader`: once its lock is released)."""
    queue = getattr(_pending, 'queue', None)
    if queue is not None:
        queue.append((node, pub, name, dict(values), level, message))
    else:
        _send(node, pub, name, values, level, message)


def _send(node, pub, name: str, values: dict, level: int, message: str):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    arr = DiagnosticArray()
    arr.header.stamp = node.get_clock().now().to_msg()
    status = DiagnosticStatus(level=bytes([level]), name=f'{node.get_name()}: {name}',
                              message=message, hardware_id='eha')
    status.values = [KeyValue(key=str(k), value=_fmt(v)) for k, v in values.items()]
    arr.status = [status]
    publish_counted(node, pub, arr, '/diagnostics')


def _fmt(v) -> str:
    if isinstance(v, float):
        return f'{v:.6g}'
    return str(v)


OK, WARN, ERROR = 0, 1, 2
