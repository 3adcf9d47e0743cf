"""/diagnostics publishing shared by the nodes."""
from __future__ import annotations

from .common import publish_counted
from .compose import unlocked


def reader(method):
    """Mark a diagnostics callback that only reads node state: a composed process (eha_loop)
    runs it without the process-wide callback lock, so it never holds up the loop (tried:
    gathering under the lock, the bridge's loop tripped the supervisor's unanswered check 1.2 s
    after its start, just after the first readers ran, twice in one CI run). It runs beside
    the loop thread, so it takes the loop's containers in one C-level step -- ``dict(d)``,
    ``list(q)``, ``len``, ``sum`` of numbers, ``dict.update`` -- before it iterates them in
    Python: a Python loop over a dict or deque the loop thread changes raises 'changed size
    during iteration' (one over the loop supervisor's saturation deque did, and ended
    eha_loop)."""
    return unlocked(method)


def publisher(node):
    from diagnostic_msgs.msg import DiagnosticArray
    return node.create_publisher(DiagnosticArray, '/diagnostics', 10)


def publish(node, pub, name: str, values: dict, level: int = 0, message: str = 'ok'):
    """One DiagnosticStatus named '<node>: <name>' with values as key/value strings."""
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
