"""Several nodes in one process with in-process delivery of the topics they share.

The same node classes as the standalone executables (each keeps its name, parameters,
services and /diagnostics), but a message published by one co-located node reaches the
co-located subscribers by a direct call in the publishing thread: no DDS hop, no thread
wake-up. Over DDS a co-located publisher still publishes whenever a subscriber outside the
process listens (recorder, sweep, monitors), and always on latched topics.

Why (measured on the 2-core target, scripts/bench stack): every 1 kHz DDS hop between
processes costs 70-250 us of CPU and 0.3 ms median / several ms p99 of latency here, so a
plant -> estimator -> controller -> plant chain of processes misses its 1 ms deadline on a
large share of ticks. This is rclcpp's component container with intra-process
communication, for rclpy, and ros2_control's layout (hardware read -> controllers -> write
in one real-time thread).

All callbacks of the composed nodes (local deliveries, DDS subscriptions, timers, services)
run under one process-wide re-entrant lock, so a node never sees two callbacks at once and
the lock order cannot deadlock.
"""
from __future__ import annotations

import functools
import threading
import time
from collections import defaultdict

from ..core.io import cdr


def unlocked(method):
    """Mark a timer callback that must not hold up the loop: a composed process runs it without
    the process-wide lock (it only reads node state, or takes the lock itself where needed)."""
    method.eha_unlocked = True
    return method


class Bus:
    """Registry of the process's local publishers and subscribers, plus the callback lock."""

    DDS_CHECK_PERIOD = 0.2      # s between looks at a publisher's remote subscription count

    def __init__(self):
        self.lock = threading.RLock()
        self.subscribers: dict[str, list] = defaultdict(list)     # topic -> callbacks
        self.published: set[str] = set()
        self.deferred: list = []             # DDS subscriptions decided at finalize()
        self.guests: set[str] = set()        # nodes without the process's global ROS args
        self.latched: dict[str, object] = {}  # topic -> last message of a latched publisher
        self.names: set[str] = set()         # the co-located nodes
        self.final = False

    def guard(self, callback):
        """Run callback under the process lock (not an :func:`unlocked` one)."""
        if getattr(callback, 'eha_unlocked', False):
            return callback
        lock = self.lock

        @functools.wraps(callback)   # rclpy inspects the signature (timer info, message info)
        def guarded(*args):
            with lock:
                return callback(*args)
        return guarded

    def finalize(self):
        """Create DDS subscriptions for the topics no co-located node publishes."""
        for node, topic, args, kwargs, handle in self.deferred:
            if topic not in self.published:
                handle.dds = node.dds_subscription(topic, *args, **kwargs)
        self.deferred.clear()
        self.final = True

    def local_topics(self) -> list[str]:
        return sorted(t for t in self.published if self.subscribers.get(t))


class Subscription:
    """What a composed node's create_subscription returns before :meth:`Bus.finalize`:
    ``dds`` is the DDS subscription once finalize made one (the topic has no co-located
    publisher), else None (in-process deliveries only)."""

    dds = None


class LocalPublisher:
    """Publisher that calls the co-located subscribers, then DDS if anyone outside listens."""

    def __init__(self, bus: Bus, topic: str, dds, latched: bool):
        self.bus, self.topic, self.dds, self.latched = bus, topic, dds, latched
        self._remote = 0
        self._checked = -1.0
        # to DDS as CDR bytes from one struct.pack (core.io.cdr): rclpy would first convert
        # the whole message to C; a type cdr cannot lay out is published as the message
        try:
            self._encode = cdr.encoder(dds.msg_type)
        except (cdr.Unsupported, AttributeError):       # not a message class
            self._encode = None

    def remote_subscribers(self) -> int:
        now = time.monotonic()
        if now - self._checked > Bus.DDS_CHECK_PERIOD:
            self._remote = self.dds.get_subscription_count()
            self._checked = now
        return self._remote

    def publish(self, msg):
        with self.bus.lock:           # the co-located callbacks run under it (Bus.guard's lock)
            if self.latched:          # transient local: a later local subscriber gets it too
                self.bus.latched[self.topic] = msg
            for callback in self.bus.subscribers.get(self.topic, ()):
                callback(msg)
        if self.latched or self.remote_subscribers():
            self.dds.publish(msg if self._encode is None else self._encode(msg))

    def get_subscription_count(self) -> int:
        """Co-located subscribers that want messages now + outside ones (the latter looked up
        every 0.2 s). A callback's ``eha_wanted()``, where it has one, says whether it wants
        them (the live view: only while a viewer is subscribed), so a publisher that builds a
        message only for listeners (the plant's truth) does not build it for nobody."""
        return self.remote_subscribers() + sum(
            1 for cb in self.bus.subscribers.get(self.topic, ())
            if getattr(cb, 'eha_wanted', None) is None or cb.eha_wanted())

    def __getattr__(self, name):
        return getattr(self.dds, name)


def is_latched(qos_profile) -> bool:
    """A transient-local QoS profile (a depth alone is volatile)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    return isinstance(qos_profile, QoSProfile) and \
        qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL


def composed_base(bus: Bus):
    """The transport of the nodes of a composed process (nodes.common.bind): an rclpy Node
    subclass whose topics, timers and services go through ``bus``."""
    from rclpy.node import Node

    class ComposedNode(Node):
        callback_lock = bus.lock
        composed_bus = bus

        def __init__(self, node_name, *args, **kwargs):
            if node_name in bus.guests:      # its parameters come from its own sections only
                kwargs.setdefault('use_global_arguments', False)
            super().__init__(node_name, *args, **kwargs)
            bus.names.add(self.get_name())

        def create_publisher(self, msg_type, topic, qos_profile, **kwargs):
            dds = super().create_publisher(msg_type, topic, qos_profile, **kwargs)
            name = self.resolve_topic_name(topic)
            if name == '/clock' or name == '/diagnostics' or name.startswith('/rosout'):
                return dds
            bus.published.add(name)
            return LocalPublisher(bus, name, dds, is_latched(qos_profile))

        def create_subscription(self, msg_type, topic, callback, qos_profile, **kwargs):
            name = self.resolve_topic_name(topic)
            guarded = bus.guard(callback)
            with bus.lock:          # a callback may subscribe from outside the lock (live)
                # in-process deliveries run under the lock LocalPublisher.publish holds
                bus.subscribers[name].append(callback)
                if name in bus.latched and is_latched(qos_profile):
                    callback(bus.latched[name])      # as DDS does for a late joiner
            if bus.final:
                if name not in bus.published:
                    return self.dds_subscription(name, msg_type, guarded, qos_profile, **kwargs)
                return None
            handle = Subscription()
            bus.deferred.append((self, name, (msg_type, guarded, qos_profile), kwargs, handle))
            return handle

        def dds_subscription(self, topic, msg_type, callback, qos_profile, **kwargs):
            return super().create_subscription(msg_type, topic, callback, qos_profile, **kwargs)

        def create_timer(self, timer_period_sec, callback, *args, **kwargs):
            return super().create_timer(timer_period_sec, bus.guard(callback), *args, **kwargs)

        def create_service(self, srv_type, srv_name, callback, **kwargs):
            return super().create_service(srv_type, srv_name, bus.guard(callback), **kwargs)

    return ComposedNode
