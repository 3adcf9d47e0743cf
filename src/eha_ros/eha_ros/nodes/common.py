"""rclpy plumbing shared by every node: parameters through the one loader, QoS, spinning.

A node module defines a ``Schema``, its node class (module level, without its rclpy base) and
a ``make_node(params: dict, transport=None) -> rclpy.node.Node`` factory that puts the class
on its transport (:func:`bind`: DDS, or eha_loop's in-process bus); :func:`run` does the rest.
Parameter files are validated before ``rclpy.init`` (so a malformed file gives one line, not
an rcl traceback), then declared as read-only ROS parameters and validated again from what
rclpy holds (``-p`` overrides included).
"""
from __future__ import annotations

import contextlib
import functools
import gc
import json
import re
import signal
import sys
import threading
import time
from typing import Callable

from ..core.config.cli import guarded
from ..core import topics
from ..core.config.params import ParamError, Schema, ROS_BUILTINS, load, parse_ros_args


def qos_of(spec, depth: int | None = None):
    """The rclpy QoSProfile of a topic of core.topics (or of its plain-data Qos), with
    ``depth`` instead of the table's where an endpoint wants a deeper queue."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    q = getattr(spec, 'qos', spec)
    return QoSProfile(depth=q.depth if depth is None else depth,
                      reliability=ReliabilityPolicy[q.reliability.upper()],
                      history=HistoryPolicy[q.history.upper()],
                      durability=DurabilityPolicy[q.durability.upper()])


def stream_qos():
    """The 1 kHz streams' QoS (core.topics.STREAM)."""
    return qos_of(topics.STREAM)


def latched_qos():
    """For low-rate state that late joiners need (core.topics.LATCHED)."""
    return qos_of(topics.LATCHED)


def clock_s(node) -> float:
    """The node's clock in seconds: /clock time under use_sim_time (lock-step), else system
    time. Watchdogs and staleness use it, so they count plant time in lock-step. (rclpy's
    Clock.now() costs ~5 us; at 1 kHz the wall clock is read directly.)"""
    sim = getattr(node, '_eha_sim_time', None)
    if sim is None:
        sim = node._eha_sim_time = bool(node.get_parameter('use_sim_time').value)
    if sim:
        return node.get_clock().now().nanoseconds * 1e-9
    return time.time()


def declare_and_validate(node, schema: Schema, params: dict) -> dict:
    """Declare every schema parameter on the node (read-only) and re-validate rclpy's values."""
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.parameter import Parameter
    overrides = dict(getattr(node, '_parameter_overrides', {}) or {})
    values = {}
    for spec in schema.params:
        desc = ParameterDescriptor(description=f'{spec.doc} [{spec.expected()}]'.strip(),
                                   read_only=True, dynamic_typing=True)
        param = node.declare_parameter(spec.name, params[spec.name], desc)
        value = param.value
        values[spec.name] = value if param.type_ != Parameter.Type.NOT_SET else params[spec.name]
    unknown = [k for k in overrides if k not in schema.by_name and k not in ROS_BUILTINS]
    if unknown:
        key = unknown[0]
        raise ParamError(f'parameters: unknown parameter {key!r} = '
                         f'{overrides[key].value!r} for node {schema.node!r}')
    return schema.validate(values, context='ROS parameters')


def run(name: str, schema: Schema, make_node: Callable, argv=None) -> int:
    """Entry point body of a node executable: validate parameters, spin, shut down cleanly."""
    argv = list(sys.argv if argv is None else argv)

    def main() -> int:
        files, overrides, node_name, namespace = parse_ros_args(argv[1:])
        params = load(schema, files, overrides, node=node_name or name, namespace=namespace)
        return spin(argv, lambda: [make_node(params)])

    return guarded(name, main)


# how long a node that ended itself waits for its subscribers to acknowledge its last samples
DELIVERY_TIMEOUT_S = 3.0      # under run_stack's 5 s silence limit (realtime)


def delivered(node, timeout: float) -> bool:
    """Wait, ``timeout`` s at most in all, until every matched reliable subscriber acknowledged
    all that ``node`` published. A reliable writer delivers only while it lives: a tool node
    that ends itself (sweep, experiment) and exits at once took its last ~20 samples with it
    when a recorder lagged on a loaded machine. False (and one WARN line) if some were not."""
    from rclpy.duration import Duration
    end = time.monotonic() + timeout
    late = []
    for pub in list(node.publishers):
        left = max(0.0, end - time.monotonic())
        try:
            if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                late.append(pub.topic_name)
        except Exception as err:         # rclpy/rmw error: say so, do not hang the exit
            late.append(f'{pub.topic_name} ({rcl_message(err)})')
    if late:
        node.get_logger().warning(f'not acknowledged by every subscriber within {timeout:g} s '
                                  f'at exit: {", ".join(late)}')
    return not late


def spin(argv, make_nodes: Callable) -> int:
    """rclpy.init, build the nodes, spin them on one executor until Ctrl-C/SIGTERM or until a
    node ends itself (node.done); then close and destroy them. Returns the worst exit code."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    # We own SIGINT/SIGTERM: stop the nodes' own threads first, then shut rclpy down,
    # so nothing publishes on an invalid context during shutdown.
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:          # rclpy's RCLError: a malformed --ros-args list
        raise ParamError(f'ROS arguments: {rcl_message(err)}') from None
    # the handler only appends to a list: no lock. An Event.set() in a handler deadlocks when
    # a second signal lands while the first handler holds the Event's lock (seen: SIGTERM
    # twice during shutdown left eha_loop hung forever)
    stop: list = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _: stop.append(signum))
    nodes = []
    try:
        nodes = make_nodes()
        executor = make_executor()
        for node in nodes:
            executor.add_node(node)
        # start-up made ~10^6 long-lived objects (numba, scipy, rclpy): keep them out of the
        # collector, so a full collection does not stall a 1 kHz loop for tens of ms
        gc.collect()
        gc.freeze()
        while not stop and rclpy.ok() and \
                not any(getattr(n, 'done', False) for n in nodes):
            executor.spin_once(timeout_sec=0.1)     # a node may end itself (node.done)
    except KeyboardInterrupt:
        pass
    finally:
        for node in nodes:
            close = getattr(node, 'close', None)
            if close:
                close()
        for node in nodes:
            if getattr(node, 'done', False) and rclpy.ok():
                delivered(node, DELIVERY_TIMEOUT_S)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return max((int(getattr(n, 'exit_code', 0) or 0) for n in nodes), default=0)


def rcl_message(err: Exception) -> str:
    """rcl's own words without the 'failed to initialize rcl' prefix and the ', at
    /project/src/rcl/arguments.c:419' source locations."""
    text = str(err).split('failed to initialize rcl: ', 1)[-1]
    return re.sub(r', at /\S+:\d+', '', text).strip()


def realtime_priority(priority: int, log) -> int:
    """Put the calling thread (a loop) under SCHED_FIFO at ``priority`` (1-99; ros2_control's
    thread_priority): other work on the machine then cannot delay its wake-up. The process's
    other Python threads go to SCHED_FIFO 1: they share the GIL with the loop, and one that
    ordinary work preempts while it holds the GIL holds up the loop's tick (two busy loops
    beside eha_loop recording: 159 overruns and 2 lost ticks in 60 s with them at normal
    priority, 10 and 0 at 1); threads they start later inherit it. 0 leaves everything as it
    is. Refused by the OS (no CAP_SYS_NICE, RLIMIT_RTPRIO below it): said once, normal
    scheduling. Returns the loop's priority in effect (0: normal)."""
    if priority <= 0:
        return 0
    import os
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as err:
        log.warning(f'loop thread: SCHED_FIFO priority {priority} refused '
                    f'({getattr(err, "strerror", None) or err}): normal scheduling (allow it '
                    f'with CAP_SYS_NICE or "ulimit -r {priority}", or set thread_priority 0)')
        return 0
    others = [t for t in threading.enumerate() if t is not threading.current_thread()]
    for t in others:
        try:
            os.sched_setscheduler(t.native_id, os.SCHED_FIFO, os.sched_param(1))
        except (OSError, TypeError):          # ended meanwhile
            pass
    log.info(f'loop thread: SCHED_FIFO priority {priority} (the {len(others)} other Python '
             f'threads: 1)')
    return priority


def make_executor():
    """EventsExecutor: about a third of the default executor's CPU at 1 kHz (ROS2_WHEELS.md)."""
    try:
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    except ImportError:  # pragma: no cover - older rclpy
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor()


@functools.cache
def dds_transport():
    """The transport of a standalone node: rclpy's Node over DDS, with a ``callback_lock``
    (taken by a node's own loop thread around a tick) that does nothing. A composed process
    (eha_loop) passes eha_ros.nodes.compose.composed_base(bus) instead: the process-wide lock,
    and topics between co-located nodes delivered in-process."""
    from rclpy.node import Node

    class EhaNode(Node):
        callback_lock = contextlib.nullcontext()
        composed_bus = None          # eha_loop's nodes: their in-process Bus
    return EhaNode


def bind(cls, transport=None):
    """``cls`` (a node class written without its rclpy base) on ``transport``, the rclpy Node
    class it runs on (None: :func:`dds_transport`); kept as ``transport`` on the class, whose
    ``__init__`` the lifecycle nodes call before LifecycleNodeMixin's."""
    return _bound(cls, transport or dds_transport())


def factory(cls) -> Callable:
    """The ``make_node(params, transport=None)`` of a node class: the node on its transport."""
    def make_node(params: dict, transport=None):
        return bind(cls, transport)(params)
    return make_node


@functools.cache
def _bound(cls, transport):
    return type(cls.__name__, (cls, transport),
                {'transport': transport, '__module__': cls.__module__})


PLANT_STATE_TOPIC = topics.PLANT_STATE.name


class PlantState:
    """The plant side's state on ``eha/plant_state`` (lifecycle_msgs/State, latched): ACTIVE
    while it applies eha/command (its lifecycle state is ACTIVE: armed), INACTIVE otherwise.
    The controller is inactive (zero output, no integration) while it is not ACTIVE and
    starts from the piston position when it becomes ACTIVE. Published on every change, from
    whichever thread saw it."""

    def __init__(self, node):
        from lifecycle_msgs.msg import State
        self.State = State
        self.node = node
        self.pub = node.create_publisher(State, PLANT_STATE_TOPIC, latched_qos())
        self.active = None
        # a composed process delivers to co-located subscribers under its callback lock:
        # taken first, so a thread publishing here and one holding it cannot deadlock
        self.outer = node.callback_lock
        self.lock = threading.Lock()

    def set(self, active: bool) -> bool:
        """Publish when it changed; True when it did (called every bridge cycle: the common
        case, no change, does not take the lock)."""
        S, active = self.State, bool(active)
        if active == self.active:
            return False
        with self.outer, self.lock:
            if active == self.active:
                return False
            self.pub.publish(S(id=S.PRIMARY_STATE_ACTIVE, label='active') if active else
                             S(id=S.PRIMARY_STATE_INACTIVE, label='inactive'))
            self.active = active                  # after the publication (acked() follows it)
        return True

    def acked(self, timeout: float) -> bool:
        """True once every subscriber the graph shows is matched and acknowledged the last
        state (reliable QoS), within ``timeout`` s."""
        from rclpy.duration import Duration
        end = time.monotonic() + timeout
        while self.pub.get_subscription_count() < self.node.count_subscribers(PLANT_STATE_TOPIC):
            if time.monotonic() > end:
                return False
            time.sleep(0.01)
        left = max(0.0, end - time.monotonic())
        return self.pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))


def channel_ok(node, msg, counters) -> bool:
    """A /eha/channel_select for channel 0 or 1; anything else is counted, warned, ignored."""
    if msg.channel <= 1:
        return True
    counters.bump('rejected_selects')
    node.get_logger().warning(f'channel_select: channel {msg.channel} is not 0 or 1; ignored')
    return False


def publish_counted(node, pub, msg, what: str, seq=None) -> None:
    """Publish from a loop thread; a failure (e.g. RCLError under DDS overload) is counted as
    publish_errors (where the node keeps counters) and logged ('publishing <what> <seq>
    failed', the text made only then), so the loop goes on."""
    try:
        pub.publish(msg)
    except Exception as err:
        counters = getattr(node, 'c', None)
        if counters is not None:
            counters.bump('publish_errors')
        what = what if seq is None else f'{what} {seq}'
        node.get_logger().error(f'publishing {what} failed: {err}', throttle_duration_sec=1.0)


class CountReport:
    """JSON {topic: count} on ``~/<TOPIC>``, published when it changed (:meth:`update`);
    :meth:`parse` reads it back."""
    TOPIC = ''

    def __init__(self, node, qos):
        from std_msgs.msg import String
        self.msg, self.last = String, None
        self.pub = node.create_publisher(String, f'~/{self.TOPIC}', qos)

    def update(self, counts: dict):
        if counts != self.last:
            self.last = dict(counts)
            self.pub.publish(self.msg(data=json.dumps(counts, sort_keys=True)))

    @staticmethod
    def parse(text: str) -> dict:
        """{topic: count}; anything else (not ours) counts as nothing."""
        try:
            got = json.loads(text)
            return {str(k): int(v) for k, v in got.items()} if isinstance(got, dict) else {}
        except (ValueError, TypeError, AttributeError):
            return {}


class MatchReport(CountReport):
    """What DDS has matched to a node's subscriptions, for :class:`StartGate`: {topic:
    publishers matched} on ``~/matched``, latched (the recorder)."""
    TOPIC = 'matched'

    def __init__(self, node):
        super().__init__(node, latched_qos())


class ReceivedReport(CountReport):
    """How many messages a node (the recorder) has received per topic, for :class:`Pace`:
    {topic: count} on ``~/received``, looked at every PERIOD of wall time."""
    TOPIC = 'received'
    PERIOD = 0.01           # [s]

    def __init__(self, node, counts: Callable[[], dict]):
        from rclpy.clock import Clock, ClockType
        super().__init__(node, 1)
        node.create_timer(self.PERIOD, lambda: self.update(counts()),
                          clock=Clock(clock_type=ClockType.STEADY_TIME))


class Pace:
    """Lock-step back-pressure: a tick waits while a node named in ``names`` (the recorder) is
    more than LAG messages behind on a stream this node counts (``counts``: {topic: messages
    it sent or got}), by that node's :class:`ReceivedReport`; its queues hold
    core.topics.STREAM (1000) messages, and a lock-step loop that runs ahead of a starved
    recorder would overrun them. A node that has never reported is not waited for; one that
    makes no progress for STALL s of wall time is left behind, with a warning (once)."""
    LAG = 250
    STALL = 5.0             # [s]

    def __init__(self, node, names):
        from std_msgs.msg import String
        self.node = node
        self.reports: dict[str, dict] = {}          # name -> {topic: received}
        self.moved: dict[str, float] = {}           # name -> wall time of its last progress
        self.dropped: set[str] = set()
        self.waits = 0                              # ticks that waited
        for name in (n for n in names if n):
            node.create_subscription(String, f'{name}/{ReceivedReport.TOPIC}',
                                     functools.partial(self._report, name), 10)

    def _report(self, name, msg):
        got = CountReport.parse(msg.data)
        if got != self.reports.get(name):
            self.reports[name] = got
            self.moved[name] = time.monotonic()

    def behind(self, name: str, counts: dict) -> int:
        got = self.reports[name]
        return max((n - got[topic] for topic, n in counts.items() if topic in got), default=0)

    def wait(self, counts: dict, running: Callable[[], bool]):
        """Return once every followed node is at most LAG behind (or left behind)."""
        waited = False
        for name in list(self.reports):
            since = time.monotonic()            # a caught-up report has not moved: fine
            while name not in self.dropped and running() and \
                    self.behind(name, counts) > self.LAG:
                waited = True
                if time.monotonic() - max(since, self.moved[name]) > self.STALL:
                    self.dropped.add(name)
                    self.node.get_logger().warning(
                        f'lock-step: {name} has made no progress for {self.STALL:g} s, '
                        f'{self.behind(name, counts)} messages behind: stepping on without '
                        'waiting for it (its recording may miss messages)')
                    break
                time.sleep(0.001)
        self.waits += waited


class StartGate:
    """Start gate (the plant side's tick 0, an experiment's plan): held until every node named
    in ``names`` subscribes to every topic under ``prefix`` that has a publisher and has
    matched each of those publishers (its report on ``<name>/matched``, :class:`MatchReport`,
    in the gated node's namespace: the graph shows a subscription before DDS has matched it to
    every publisher, and the messages in between are lost to a recorder), and each of the
    node's ``own`` publishers has matched every subscription the graph shows on its topic
    (a named node co-located in eha_loop takes a topic published there in-process: its report
    naming the topic is enough);
    seen for ``settle`` s in a row, or until ``timeout`` s of wall time after start-up (then a
    warning names what was missing)."""

    CHECK_PERIOD = 0.01     # [s] between looks at the graph (the plant side polls every 20 ms)

    def __init__(self, node, names, prefix: str, timeout: float, own=(), settle: float = 0.25):
        self.node, self.prefix, self.own, self.settle = node, prefix, tuple(own), settle
        self.names = [n for n in names if n]
        self.deadline = time.monotonic() + timeout
        self.timeout = timeout
        self.open = not self.names
        self.since = None                 # wall time since which nothing was missing
        self.next_check = 0.0             # wall time of the next look at the graph
        self.reports = {name: {} for name in self.names}     # name -> {topic: matched}
        from std_msgs.msg import String
        for name in self.names:
            node.create_subscription(String, f'{name}/{MatchReport.TOPIC}',
                                     functools.partial(self._report, name), latched_qos())

    def _report(self, name, msg):
        self.reports[name] = MatchReport.parse(msg.data)

    def missing(self) -> list[str]:
        n = self.node
        bus = getattr(n, 'composed_bus', None)
        here, local = (bus.names, bus.published) if bus is not None else ((), ())
        out = []
        for topic, _ in n.get_topic_names_and_types():
            if not topic.startswith(self.prefix):
                continue
            publishers = n.count_publishers(topic)
            if not publishers:
                continue
            subs = {i.node_name for i in n.get_subscriptions_info_by_topic(topic)}
            for name in self.names:
                matched = self.reports[name].get(topic, 0)
                if name in here and topic in local:     # in-process: not on the graph
                    if topic not in self.reports[name]:
                        out.append(f'{name} on {topic}')
                elif name not in subs:
                    out.append(f'{name} on {topic}')
                elif matched < publishers:
                    out.append(f'{name} matching {topic} ({matched} of {publishers} '
                               'publishers)')
        out += [f'matching on {p.topic_name}' for p in self.own
                if p.get_subscription_count() < n.count_subscribers(p.topic_name)]
        return out

    def poll(self) -> bool:
        """True once open (call it while the loop is ready to step). The graph is looked at
        every CHECK_PERIOD at most: an experiment polls on each state (lock-step: faster than
        1 kHz), and each look queries every topic of the graph."""
        if self.open:
            return True
        now = time.monotonic()
        if now < self.next_check:
            return False
        self.next_check = now + self.CHECK_PERIOD
        missing = self.missing()
        self.since = None if missing else (self.since or now)
        if self.since is not None and now - self.since >= self.settle:
            self.open = True
            self.node.get_logger().info(f'start gate: {", ".join(self.names)} subscribed '
                                        f'to every {self.prefix}* topic, its publishers '
                                        'matched; going on')
        elif now > self.deadline:
            self.open = True
            self.node.get_logger().warning(
                f'start gate: still missing after {self.timeout:g} s: '
                f'{", ".join(missing[:6])}; going on anyway')
        return self.open
