"""/diagnostics publishing shared by the nodes."""
from __future__ import annotations

from .common import publish_counted
from .compose import unlocked


def reader(method):
    """Mark a timer callback that only reads node state (diagnostics): a composed process
    (eha_loop) runs it without the process-wide callback lock, so it never holds up the loop."""
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
