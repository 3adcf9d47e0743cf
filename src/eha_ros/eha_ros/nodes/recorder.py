"""recorder node: every topic under /eha (plus /diagnostics) into one MCAP file.

Topics are discovered periodically (wall-time timer), so topics that appear later are caught.
Each is subscribed serialized (raw CDR, no deserialisation in Python) with its publishers' QoS:
reliable and deep enough for 1 kHz, transient local when every publisher is latched (so the
last latched sample is recorded even if it was published before the recorder started).
Messages go to a writer thread (core.mcap_sink) with log_time = receive time (wall clock) and
publish_time = header stamp. On SIGINT/SIGTERM the queues are drained and the file finished;
message counts per topic go to /diagnostics and to the log.
"""
from __future__ import annotations

import datetime
import os
import sys
import time

from ..core.mcap_sink import McapSink
from ..core.recorder_params import SCHEMA
from . import diag, msgdefs
from .common import declare_and_validate, node_base, run


def default_output() -> str:
    return os.path.join('out', datetime.datetime.now().strftime('recording_%Y%m%d-%H%M%S.mcap'))


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


def make_node(params: dict):
    Node = node_base()

    class Recorder(Node):
        def __init__(self):
            super().__init__('recorder')
            self.p = p = declare_and_validate(self, SCHEMA, params)
            self.ns = '/' + p['recorder.namespace'].strip('/')
            self.extra = {t for t in p['recorder.extra_topics'] if t}
            if p['recorder.diagnostics']:
                self.extra.add('/diagnostics')
            self.output = p['recorder.output'] or default_output()
            self.sink = McapSink(self.output, p['recorder.compression'],
                                 p['recorder.chunk_size'])
            self.subs = {}               # topic -> (subscription, channel id, qos)
            self.skipped = {}            # topic -> reason (warned once)
            self.pub_counts = {}         # topic -> publishers checked for QoS
            self.started = time.monotonic()
            self.closed = False
            self.exit_code = 0
            self.pub_diag = diag.publisher(self)
            from rclpy.clock import Clock, ClockType
            wall = Clock(clock_type=ClockType.STEADY_TIME)
            self.create_timer(p['recorder.discovery_period'], self.discover, clock=wall)
            self.create_timer(p['recorder.diagnostics_period'], self.publish_diagnostics,
                              clock=wall)
            self.get_logger().info(f'recorder: {self.ns}/*{" + " if self.extra else ""}'
                                   f'{", ".join(sorted(self.extra))} -> {self.output}')
            self.discover()

        def wanted(self, topic: str) -> bool:
            return topic.startswith(self.ns + '/') or topic in self.extra

        def discover(self):
            """Subscribe to new topics; QoS from the publishers, or (no publisher yet) what the
            subscribers imply, so the first messages of a publisher that starts later are in."""
            for topic, types in self.get_topic_names_and_types():
                if topic in self.subs:
                    self.check_qos(topic)
                    continue
                if topic in self.skipped or not self.wanted(topic):
                    continue
                ends = self.get_publishers_info_by_topic(topic)
                offered = bool(ends)
                if not ends:
                    ends = [e for e in self.get_subscriptions_info_by_topic(topic)
                            if e.node_name != self.get_name()]
                if not ends:
                    continue
                try:
                    self.subscribe(topic, types[0], ends, offered)
                except ValueError as err:
                    self.skipped[topic] = str(err)
                    self.get_logger().warning(f'{topic}: not recorded: {err}')
                if len(types) > 1:
                    self.get_logger().warning(f'{topic}: several types {types}; recording '
                                              f'{types[0]}')

        def subscribe(self, topic, type_name, ends, offered: bool):
            cls = msgdefs.message_class(type_name)
            qos = qos_for(ends, self.p['recorder.depth'])
            meta = {'offered_qos_profiles': qos_yaml(ends) if offered else ''}
            cid = self.sink.add_topic(topic, type_name, msgdefs.definition(type_name),
                                      msgdefs.header_first(cls), meta)
            put, now = self.sink.put, time.time_ns
            sub = self.create_subscription(cls, topic, lambda data: put(cid, now(), data), qos,
                                           raw=True)
            self.subs[topic] = (sub, cid, qos)
            self.pub_counts[topic] = 0
            self.get_logger().info(f'recording {topic} [{type_name}] '
                                   f'{qos.reliability.name.lower()}, '
                                   f'{qos.durability.name.lower()}, depth {qos.depth}'
                                   f'{"" if offered else " (no publisher yet)"}')

        def check_qos(self, topic):
            """A publisher our subscription cannot match (best effort, or volatile on a latched
            topic) is not recorded: say so once per topic."""
            from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
            n = self.count_publishers(topic)
            if n <= self.pub_counts[topic]:
                return
            self.pub_counts[topic] = n
            _, _, qos = self.subs[topic]
            for info in self.get_publishers_info_by_topic(topic):
                q = info.qos_profile
                if (qos.reliability == ReliabilityPolicy.RELIABLE and
                        q.reliability != ReliabilityPolicy.RELIABLE) or \
                        (qos.durability == DurabilityPolicy.TRANSIENT_LOCAL and
                         q.durability != DurabilityPolicy.TRANSIENT_LOCAL):
                    self.pub_counts[topic] = 1 << 30          # warned once
                    self.get_logger().warning(
                        f'{topic}: publisher {info.node_name} offers '
                        f'{q.reliability.name.lower()}/{q.durability.name.lower()}, which the '
                        f'recording subscription ({qos.reliability.name.lower()}/'
                        f'{qos.durability.name.lower()}) does not match: not recorded')
                    return

        def drain(self) -> int:
            """Take what DDS still holds for us (the executor has stopped spinning)."""
            n = 0
            for sub, cid, _ in self.subs.values():
                while True:
                    try:
                        with sub.handle:
                            got = sub.handle.take_message(sub.msg_type, sub.raw)
                    except Exception:        # destroyed handle or context: nothing left to take
                        break
                    if got is None:
                        break
                    self.sink.put(cid, time.time_ns(), got[0])
                    n += 1
            return n

        def counts(self) -> dict:
            return {self.sink.topics[c]: self.sink.received[c] for c in self.sink.topics}

        def publish_diagnostics(self, final: bool = False):
            counts = self.counts()
            values = {'output': self.output, 'topics': len(counts),
                      'messages': sum(counts.values()), 'backlog': self.sink.backlog(),
                      'elapsed_s': time.monotonic() - self.started, 'finished': final}
            values.update({f'count {t}': n for t, n in sorted(counts.items())})
            if self.sink.error:
                values['error'] = self.sink.error
            diag.publish(self, self.pub_diag, 'mcap', values,
                         diag.ERROR if self.sink.error else diag.OK, self.sink.error or 'ok')

        def close(self):
            """Drain, finish the file, report counts (log and /diagnostics)."""
            if self.closed:
                return
            self.closed = True
            drained = self.drain()
            written = self.sink.close()
            total = sum(written.values())
            size = os.path.getsize(self.output) if os.path.exists(self.output) else 0
            log = self.get_logger()
            if self.sink.error:
                self.exit_code = 1
                log.error(f'recorder: {self.sink.error}')
            log.info(f'recorder: {total} messages on {len(written)} topics '
                     f'({drained} drained at exit), {size / 1e6:.2f} MB in {self.output}')
            for topic, n in sorted(written.items()):
                log.info(f'recorder: {topic}: {n}')
            try:
                self.publish_diagnostics(final=True)
            except Exception:                # context already shut down: the log has it
                pass

    return Recorder()


def main(argv=None) -> int:
    return run('recorder', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
