"""recorder node: every topic under /eha (plus /diagnostics) into one MCAP file.

Topics are discovered periodically (wall-time timer, nodes.tap: raw CDR with the publishers'
QoS), so topics that appear later are caught. As a guest of eha_loop (``--nodes ...,recorder``,
what run_stack --record does in real time) the loop's topics arrive in-process as message
objects, encoded here (core.io.cdr), and nothing is published over DDS for the recorder's sake.
Messages go to a writer thread (core.io.mcap_sink) with log_time = receive time (wall clock) and
publish_time = header stamp. On SIGINT/SIGTERM the queues are drained and the file finished;
message counts per topic go to /diagnostics and to the log. For the plant side: what DDS has
matched (~/matched, its start gate) and what was received (~/received, lock-step pacing).
"""
from __future__ import annotations

import datetime
import os
import sys
import time

from ..core.io.mcap_sink import McapSink
from ..core.io.recorder_params import SCHEMA
from . import diag
from .common import MatchReport, ReceivedReport, declare_and_validate, factory, run
from .compose import unlocked
from .tap import TopicTap, encoder, qos_yaml


def default_output() -> str:
    return os.path.join('out', datetime.datetime.now().strftime('recording_%Y%m%d-%H%M%S.mcap'))


class Recorder:
    """The recorder node (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict):
        super().__init__('recorder')
        self.p = p = declare_and_validate(self, SCHEMA, params)
        extra = {t for t in p['recorder.extra_topics'] if t}
        if p['recorder.diagnostics']:
            extra.add('/diagnostics')
        self.output = p['recorder.output'] or default_output()
        guest = getattr(self, 'composed_bus', None) is not None      # inside eha_loop
        self.sink = McapSink(self.output, p['recorder.compression'],
                             p['recorder.chunk_size'], on_error=self.on_write_error,
                             burst=McapSink.GUEST_BURST if guest else McapSink.BURST)
        self.started = time.monotonic()
        self.closed = False
        self.exit_code = 0
        self.pub_diag = diag.publisher(self)
        from rclpy.clock import Clock, ClockType
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(p['recorder.diagnostics_period'], self.publish_diagnostics,
                          clock=wall)
        self.tap = TopicTap(self, p['recorder.namespace'], extra, p['recorder.depth'],
                            self.open_topic, 'recording')
        self.matched = MatchReport(self)     # what the plant side's start gate waits for
        if not guest:                        # what a lock-step plant paces on
            self.received = ReceivedReport(self, self.counts)
        self.create_timer(p['recorder.discovery_period'], self.discover, clock=wall)
        self.get_logger().info(f'recorder: {self.tap.ns}/*{" + " if extra else ""}'
                               f'{", ".join(sorted(extra))} -> {self.output}')
        self.discover()

    @unlocked                    # graph queries must not hold up a composed loop
    def discover(self):
        self.tap.discover()
        self.matched.update(self.tap.matched())

    def open_topic(self, topic, type_name, definition, stamped, ends, offered):
        meta = {'offered_qos_profiles': qos_yaml(ends) if offered else ''}
        cid = self.sink.add_topic(topic, type_name, definition, stamped, meta)
        put, now, encode = self.sink.put, time.time_ns, encoder(type_name)

        @unlocked                # touches only the sink's queue
        def on_message(data):
            """CDR bytes from DDS, or in eha_loop the message object (its publisher may reuse
            it: encoded now)."""
            put(cid, now(), data if isinstance(data, bytes) else encode(data))
        return on_message

    def on_write_error(self, text: str):
        """Writer thread, once: the recording stopped (disk full): say so now."""
        self.get_logger().error(f'recorder: {text}: recording stopped')
        self.publish_diagnostics()

    def counts(self) -> dict:
        return {self.sink.topics[c]: self.sink.received[c] for c in self.sink.topics}

    @diag.reader
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
        drained = self.tap.drain()
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


make_node = factory(Recorder)     # make_node(params, transport=None)


def main(argv=None) -> int:
    return run('recorder', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
