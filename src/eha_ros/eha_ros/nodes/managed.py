"""What the managed (lifecycle) nodes share: reaching a start-up state by itself
(core.hardware.params.AUTOSTART), the state's label and the wrapper of their transition
callbacks (rclpy.lifecycle, lifecycle_msgs services ~/change_state, ~/get_state, ...)."""
from __future__ import annotations

import functools


def transition(method):
    """A lifecycle callback: an exception is logged and counted (``self.c``), and answers ERROR
    (rclpy would turn it into ERROR silently)."""
    @functools.wraps(method)
    def wrapped(self, state):
        from rclpy.lifecycle import TransitionCallbackReturn
        try:
            return method(self, state)
        except Exception as err:
            self.c.bump('lifecycle_errors')
            self.get_logger().error(f'{method.__name__} failed: {err!r}')
            return TransitionCallbackReturn.ERROR
    return wrapped


def state_label(node) -> str:
    """The node's primary lifecycle state: unconfigured, inactive, active, finalized."""
    return node._state_machine.current_state[1]


def autostart(node, target: str) -> None:
    """Reach ``target`` (unconfigured, inactive, active) by itself, as a manager would by
    change_state."""
    if target in ('inactive', 'active'):
        node.trigger_configure()
    if target == 'active' and state_label(node) == 'inactive':
        node.trigger_activate()
