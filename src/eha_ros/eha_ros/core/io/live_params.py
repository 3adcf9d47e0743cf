"""Parameters of the live node (live.*): what is served over the Foxglove WebSocket protocol."""
from __future__ import annotations

from ..config.params import Param, ParamError, Schema


def decimation(entries) -> dict[str, int]:
    """['/eha/sim/truth:10', ...] -> {'/eha/sim/truth': 10}; ParamError names a bad entry."""
    out = {}
    for item in entries:
        if not item:
            continue
        topic, sep, n = item.rpartition(':')
        try:
            every = int(n)
        except ValueError:
            every = 0
        if not sep or not topic.startswith('/') or every < 1:
            raise ParamError(f"live.decimation: {item!r}: expected '/topic:N' with N >= 1",
                             'live.decimation')
        out[topic] = every
    return out


def check(p: dict) -> None:
    """Every live.decimation entry is '/topic:N' with N >= 1."""
    decimation(p['live.decimation'])


SCHEMA = Schema('live', [
    Param('live.host', 'str', '', '127.0.0.1',
          doc='address the WebSocket server binds to (0.0.0.0: every interface)'),
    Param('live.port', 'int', '', 8765, 0, 65535,
          doc='WebSocket port (foxglove.websocket.v1; 0: any free port, logged)'),
    Param('live.namespace', 'str', '', '/eha', doc='every topic under this namespace is served'),
    Param('live.diagnostics', 'bool', '', True, doc='also serve /diagnostics'),
    Param('live.extra_topics', 'str[]', '', [''], min_len=1,
          doc='further topics to serve by exact name (e.g. /clock); empty string = none'),
    Param('live.decimation', 'str[]', '', [''], min_len=1,
          doc="per-topic decimation 'topic:N' (every N-th message), e.g. "
              "'/eha/sim/truth:10'; empty string = every topic at full rate"),
    Param('live.services', 'bool', '', True,
          doc='offer the services under the namespace (fault injection, channel switch, arm) '
              'to the viewer, JSON-encoded'),
    Param('live.parameters', 'bool', '', True,
          doc="offer the stack's node parameters to the viewer as 'node:name' "
              '(get and set through each node\'s rcl_interfaces services)'),
    Param('live.call_timeout', 'float', 's', 2.0, 0.01, 60.0,
          doc='a forwarded service call or parameter request fails after this'),
    Param('live.discovery_period', 'float', 's', 1.0, 0.01, 10.0,
          doc='look for new topics and services this often (wall time)'),
    Param('live.flush_period', 'float', 's', 0.02, 0.0, 0.1,
          doc='messages for the viewer are queued as they arrive and handed to the server '
              'in one burst this often, by a thread of its own (0: each at once, in the '
              'receiving thread); a viewer draws at <= 60 Hz'),
    Param('live.backlog', 'int', '', 10000, 10, 10000000,
          doc='at most this many messages wait for the next flush; more are dropped and '
              'counted (dropped on /diagnostics)'),
    Param('live.depth', 'int', '', 1000, 1, 100000,
          doc='subscription queue depth (reliable topics): 1 s of a 1 kHz stream'),
    Param('live.time_period', 'float', 's', 0.02, 0.001, 10.0,
          doc='sim time (header stamp of the newest message) broadcast to the viewer this '
              'often, with use_sim_time (lock-step)'),
    Param('live.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0),
], check)
