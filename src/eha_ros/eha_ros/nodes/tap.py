"""Serialized taps on a set of topics, found as they appear (the recorder's and live's input).

Topics are discovered periodically: each wanted topic is subscribed raw (CDR bytes, no
deserialisation in Python) with its publishers' QoS: reliable and deep enough for 1 kHz,
transient local when every publisher is latched (so the last latched sample is seen even if it
was published before the tap started). A topic with no publisher yet is subscribed with what
its subscribers imply, so the first messages of a publisher that starts later are in.
"""
from __future__ import annotations

from typing import Callable

from ..core.io import cdr
from . import msgdefs


def qos_for(endpoints, depth: int):
    """Subscription QoS that matches every publisher: reliable/transient local only if all are.
    Given subscribers instead, the same rule picks what any publisher they match must offer."""
    from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)
    qos = [p.qos_profile for p in endpoints]
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in qos)
    latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in qos)
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)


def qos_yaml(publishers) -> str:
    """Offered QoS of the publishers, as rosbag2 stores it in the channel metadata (short form)."""
    lines = []
    for p in publishers:
        q = p.qos_profile
        lines += [f'- history: {int(q.history)}', f'  depth: {int(q.depth)}',
                  f'  reliability: {int(q.reliability)}', f'  durability: {int(q.durability)}']
    return '\n'.join(lines)


def dds_of(sub):
    """The DDS subscription behind what create_subscription returned (eha_loop: None or a
    nodes.compose.Subscription, whose ``dds`` is None for a topic delivered in-process)."""
    return getattr(sub, 'dds', sub)


def encoder(type_name: str):
    """msg -> CDR bytes, for a message delivered in-process (eha_loop) as the object: core.io.cdr's
    one struct.pack where the type has a fixed layout (every eha_msgs type), else
    serialize_message."""
    try:
        return cdr.encoder(msgdefs.message_class(type_name))
    except (cdr.Unsupported, ValueError):
        from rclpy.serialization import serialize_message
        return serialize_message


class TopicTap:
    """Raw subscriptions of ``node`` on every topic under ``namespace`` and on ``extra``.

    ``open_topic(topic, type_name, definition, header_first, ends, offered)`` is called once per
    new topic and returns the callback that gets each message's CDR bytes; ``verb`` names what
    is done with them in the log ('recording', 'serving')."""

    def __init__(self, node, namespace: str, extra, depth: int, open_topic: Callable,
                 verb: str):
        self.node = node
        self.ns = '/' + namespace.strip('/')
        self.extra = set(extra)
        self.depth = depth
        self.open_topic = open_topic
        self.verb = verb
        self.subs = {}               # topic -> (subscription, callback, qos)
        self.skipped = {}            # topic -> reason (warned once)
        self.pub_counts = {}         # topic -> publishers checked for QoS

    def wanted(self, topic: str) -> bool:
        return topic.startswith(self.ns + '/') or topic in self.extra

    def discover(self):
        """Subscribe to new topics; check the QoS of new publishers on known ones."""
        node = self.node
        for topic, types in node.get_topic_names_and_types():
            if topic in self.subs:
                self.check_qos(topic)
                continue
            if topic in self.skipped or not self.wanted(topic):
                continue
            ends = node.get_publishers_info_by_topic(topic)
            offered = bool(ends)
            if not ends:
                ends = [e for e in node.get_subscriptions_info_by_topic(topic)
                        if e.node_name != node.get_name()]
            if not ends:
                continue
            try:
                self.subscribe(topic, types[0], ends, offered)
            except ValueError as err:
                self.skipped[topic] = str(err)
                node.get_logger().warning(f'{topic}: not {self.verb}: {err}')
            if len(types) > 1:
                node.get_logger().warning(f'{topic}: several types {types}; {self.verb} '
                                          f'{types[0]}')

    def subscribe(self, topic, type_name, ends, offered: bool):
        cls = msgdefs.message_class(type_name)
        qos = qos_for(ends, self.depth)
        callback = self.open_topic(topic, type_name, msgdefs.definition(type_name),
                                   msgdefs.header_first(cls), ends, offered)
        sub = self.node.create_subscription(cls, topic, callback, qos, raw=True)
        self.subs[topic] = (sub, callback, qos)
        self.pub_counts[topic] = 0
        self.node.get_logger().info(f'{self.verb} {topic} [{type_name}] '
                                    f'{qos.reliability.name.lower()}, '
                                    f'{qos.durability.name.lower()}, depth {qos.depth}'
                                    f'{"" if offered else " (no publisher yet)"}')

    def check_qos(self, topic):
        """A publisher our subscription cannot match (best effort, or volatile on a latched
        topic) is not seen: say so once per topic."""
        from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
        n = self.node.count_publishers(topic)
        if n <= self.pub_counts[topic]:
            return
        self.pub_counts[topic] = n
        _, _, qos = self.subs[topic]
        for info in self.node.get_publishers_info_by_topic(topic):
            q = info.qos_profile
            if (qos.reliability == ReliabilityPolicy.RELIABLE and
                    q.reliability != ReliabilityPolicy.RELIABLE) or \
                    (qos.durability == DurabilityPolicy.TRANSIENT_LOCAL and
                     q.durability != DurabilityPolicy.TRANSIENT_LOCAL):
                self.pub_counts[topic] = 1 << 30          # warned once
                self.node.get_logger().warning(
                    f'{topic}: publisher {info.node_name} offers '
                    f'{q.reliability.name.lower()}/{q.durability.name.lower()}, which the '
                    f'subscription ({qos.reliability.name.lower()}/'
                    f'{qos.durability.name.lower()}) does not match: not {self.verb}')
                return

    def matched(self) -> dict:
        """{topic: publishers DDS has matched to our subscription} (the graph can show a
        publisher before it is matched; its messages until then are not seen). In eha_loop a
        topic published in the process is delivered in-process: its publishers on the graph."""
        out = {}
        for topic, (sub, _, _) in self.subs.items():
            dds = dds_of(sub)
            out[topic] = self.node.count_publishers(topic) if dds is None else \
                dds.get_publisher_count()
        return out

    def drain(self) -> int:
        """Hand what DDS still holds to the callbacks (the executor has stopped spinning)."""
        n = 0
        for sub, callback, _ in self.subs.values():
            sub = dds_of(sub)
            while sub is not None:
                try:
                    with sub.handle:
                        got = sub.handle.take_message(sub.msg_type, sub.raw)
                except Exception:        # destroyed handle or context: nothing left to take
                    break
                if got is None:
                    break
                callback(got[0])
                n += 1
        return n
