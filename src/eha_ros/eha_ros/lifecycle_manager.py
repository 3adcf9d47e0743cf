"""run_stack's lifecycle manager: brings a stack's managed nodes up through the standard
lifecycle_msgs services and reports what they do.

Like nav2's lifecycle_manager, in short: ``bring_up`` calls ~/change_state on each node in
order (configure the plant side, configure and activate the controller, then activate the
plant side when the stack's plant may move), retrying a plant-side transition that is refused
for a reason that can pass (a PLC not reachable yet, arming conditions) until a deadline. Every
state change of a managed node (``~/transition_event``, its own and the manager's requests
alike: a link loss that deactivates the bridge) is printed once and kept in
'<monitor>: lifecycle' on /diagnostics (one value per node: its state), published every
second. A transition that cannot be carried out ends the bring-up with its reason, which the
plant side gives on /diagnostics (transition_refused).
"""
from __future__ import annotations

import threading
import time

RETRY_PERIOD = 1.0          # [s] between attempts of a refused plant-side transition
CALL_TIMEOUT = 10.0         # [s] for one ChangeState / GetState answer
GOAL = {'configure': 'inactive', 'activate': 'active', 'deactivate': 'inactive',
        'cleanup': 'unconfigured', 'shutdown': 'finalized'}
VERB = {'configuring': 'configure', 'activating': 'activate', 'deactivating': 'deactivate',
        'cleaningup': 'cleanup', 'shuttingdown': 'shutdown', 'errorprocessing': 'error'}


class LifecycleManager:
    """Clients of ``nodes`` (names) on the DiagMonitor's node (spun by its thread)."""

    def __init__(self, monitor, nodes, say=print):
        from diagnostic_msgs.msg import DiagnosticArray
        from lifecycle_msgs.msg import TransitionEvent
        from lifecycle_msgs.srv import ChangeState, GetState
        self.monitor, self.nodes, self.say = monitor, list(nodes), say
        self.ChangeState, self.GetState = ChangeState, GetState
        node = monitor.node
        self.change_clients = {n: node.create_client(ChangeState, f'/{n}/change_state')
                               for n in self.nodes}
        self.get_clients = {n: node.create_client(GetState, f'/{n}/get_state')
                            for n in self.nodes}
        self.lock = threading.Lock()
        self.states = {n: 'not seen' for n in self.nodes}
        self.transitions = 0
        self.failure = ''
        for n in self.nodes:
            node.create_subscription(TransitionEvent, f'/{n}/transition_event',
                                     lambda msg, n=n: self.on_event(n, msg), 10)
        self.pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.timer = node.create_timer(1.0, self.publish)

    # ---- what the nodes do ----
    def on_event(self, name: str, msg):
        goal = msg.goal_state.label
        if msg.goal_state.id >= 10:          # a transition state (configuring, ...): not yet
            return
        verb = VERB.get(msg.start_state.label, msg.start_state.label)
        with self.lock:
            before, self.states[name] = self.states[name], goal
            self.transitions += 1
        self.say(f'run_stack: lifecycle: {name} {before} -> {goal} ({verb}'
                 f'{" failed" if goal == before else ""})')
        if before != goal:
            self.publish()

    def publish(self):
        from .nodes import diag
        with self.lock:
            values = dict(self.states, transitions=self.transitions)
            failure = self.failure
        diag.publish(self.monitor.node, self.pub, 'lifecycle', values,
                     diag.ERROR if failure else diag.OK, failure or 'ok')

    # ---- service calls ----
    def _call(self, client, request, timeout: float = CALL_TIMEOUT):
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout):
            client.remove_pending_request(future)
            return None
        return future.result()

    def state(self, name: str) -> str:
        res = self._call(self.get_clients[name], self.GetState.Request())
        return res.current_state.label if res is not None else 'no answer'

    def wait_for_services(self, deadline: float, dead=lambda: {}) -> str:
        """'' once every node answers get_state, else why not (a node exited, timeout)."""
        for name in self.nodes:
            while not self.get_clients[name].wait_for_service(timeout_sec=0.2) or \
                    not self.change_clients[name].service_is_ready():
                gone = dead()
                if gone:
                    return 'node exited: ' + ', '.join(f'{n} ({c})' for n, c in gone.items())
                if time.monotonic() > deadline:
                    return f'{name}: no lifecycle services (~/change_state) in time'
            label = self.state(name)
            with self.lock:
                self.states[name] = label
        return ''

    def change(self, name: str, transition: str) -> tuple[bool, str]:
        """ChangeState by label; (success, reason): the node's transition_refused, if any."""
        t0 = time.monotonic()
        req = self.ChangeState.Request()
        req.transition.label = transition
        res = self._call(self.change_clients[name], req)
        if res is None:
            return False, f'no answer from /{name}/change_state within {CALL_TIMEOUT:g} s'
        if res.success:
            return True, ''
        state = self.state(name)
        reason = ''
        try:                                 # a refusing plant side publishes why at once
            values, _ = self.monitor.next_after(f'{name}: loop', t0, timeout=2.0)
            reason = str(values.get('transition_refused', '')).removeprefix(
                f'{transition} refused: ')
        except TimeoutError:
            pass
        return False, reason or f'{transition} not possible from {state}'

    def bring_up(self, steps, deadline: float, dead=lambda: {}) -> str:
        """Carry out ``steps`` [(node, transition, retry)] in order; '' when all succeeded,
        else the reason (reported ERROR on /diagnostics)."""
        why = self.wait_for_services(deadline, dead)
        for name, transition, retry in steps:
            if why:
                break
            why = self.carry_out(name, transition, retry, deadline, dead)
        if why:
            with self.lock:
                self.failure = why
            self.publish()
            return why
        end = time.monotonic() + 1.0             # their transition_events printed first
        while time.monotonic() < end and any(self.states[n] != GOAL[t] for n, t, _ in steps):
            time.sleep(0.01)
        return ''

    def carry_out(self, name: str, transition: str, retry: bool, deadline: float, dead) -> str:
        """One transition; '' when done, else why not. ``retry``: a refusal is retried every
        RETRY_PERIOD until ``deadline`` (its reason printed once, again when it changes)."""
        said = ''
        while True:
            ok, reason = self.change(name, transition)
            if ok:
                return ''
            gone = dead()
            if not retry or time.monotonic() + RETRY_PERIOD > deadline or gone:
                return f'{name} {transition} refused: {reason}' + (
                    '; node exited: ' + ', '.join(gone) if gone else '')
            if reason != said:
                self.say(f'run_stack: lifecycle: {name} {transition} refused: {reason}; '
                         f'retried every {RETRY_PERIOD:g} s')
                said = reason
            time.sleep(RETRY_PERIOD)
