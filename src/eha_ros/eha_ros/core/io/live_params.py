"""Parameters of the live node (live.*): what is served over the Foxglove WebSocket protocol,
and which services a viewer may call (live.services_allow)."""
from __future__ import annotations

import fnmatch
import ipaddress

from ..config.params import Param, ParamError, Schema

# service types that only read: offered wherever the server is bound. Every other type (fault
# injection, channel switch, arm, reset, lifecycle change_state, set_parameters, ...) acts on
# the stack and is offered only as live.services_allow says (service_offered)
READ_ONLY_SERVICES = frozenset(
    [f'lifecycle_msgs/srv/{s}' for s in ('GetState', 'GetAvailableStates',
                                         'GetAvailableTransitions')] +
    [f'rcl_interfaces/srv/{s}' for s in ('ListParameters', 'GetParameters',
                                         'DescribeParameters', 'GetParameterTypes',
                                         'GetLoggerLevels')] +
    ['type_description_interfaces/srv/GetTypeDescription'])


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


def allow_patterns(entries) -> list[str]:
    """live.services_allow -> its globs ([] for ['']: the default of the bind address);
    ParamError names an entry that is not an absolute service name or glob."""
    out = [e for e in entries if e]
    for item in out:
        if not item.startswith(('/', '*')):
            raise ParamError(f"live.services_allow: {item!r}: expected an absolute service "
                             f"name or glob, e.g. '/eha/switch_channel' or '/eha/*'",
                             'live.services_allow')
    return out


def is_loopback(host: str) -> bool:
    """True when ``host`` reaches this machine only (127.0.0.0/8, ::1, localhost)."""
    if host.strip().lower() == 'localhost':
        return True
    try:
        return ipaddress.ip_address(host.strip('[]')).is_loopback
    except ValueError:
        return False


def actuating(type_name: str) -> bool:
    """A service of this type may act on the stack (not one of READ_ONLY_SERVICES)."""
    return type_name not in READ_ONLY_SERVICES


def service_offered(name: str, type_name: str, patterns, loopback: bool) -> bool:
    """A read-only service always; an acting one when a glob of live.services_allow matches
    it, or with no allowlist ([''] -> []) when the server is bound to loopback only."""
    if not actuating(type_name):
        return True
    if patterns:
        return any(fnmatch.fnmatchcase(name, pat) for pat in patterns)
    return loopback


def served_topics(p: dict) -> str:
    """'/eha/* + /diagnostics + ...': what the live node serves."""
    extra = {t for t in p['live.extra_topics'] if t}
    if p['live.diagnostics']:
        extra.add('/diagnostics')
    return f'/{p["live.namespace"].strip("/")}/*' + ''.join(f' + {t}' for t in sorted(extra))


def exposure(p: dict, url: str) -> str:
    """The WARN line of a server bound beyond loopback (at ``url``): what anyone who connects
    gets."""
    patterns = allow_patterns(p['live.services_allow'])
    if not p['live.services']:
        calls = 'no service offered (live.services: false)'
    elif patterns:
        calls = (f'services offered: those matching {", ".join(patterns)} '
                 f'(live.services_allow) and read-only ones')
    else:
        calls = ('read-only: no service that acts on the actuator is offered (fault, '
                 'switch, arm, reset, lifecycle; live.services_allow names those to offer)')
    params = 'parameters read-only' if p['live.parameters'] else 'no parameters'
    return (f'live: {url} is reachable from other machines: anyone who connects gets '
            f'{served_topics(p)}; {calls}; {params}')


def check(p: dict) -> None:
    """Every live.decimation entry is '/topic:N' with N >= 1; every live.services_allow
    entry an absolute name or glob."""
    decimation(p['live.decimation'])
    allow_patterns(p['live.services_allow'])


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
          doc='offer the services under the namespace to the viewer, JSON-encoded: the '
              'read-only ones, and those that act (fault injection, channel switch, arm, '
              'reset, lifecycle) as live.services_allow says'),
    Param('live.services_allow', 'str[]', '', [''], min_len=1,
          doc="services that act on the actuator a viewer may call: absolute names or "
              "fnmatch globs, e.g. ['/eha/switch_channel'] or ['/eha/*']; empty string = "
              'the default: every one when live.host is loopback (127.0.0.1, ::1, '
              'localhost), none beyond it (read-only view)'),
    Param('live.parameters', 'bool', '', True,
          doc="offer the stack's node parameters to the viewer as 'node:name', read-only "
              "(read through each node's rcl_interfaces services; setting is refused)"),
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
    Param('live.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0,
          doc='/diagnostics period'),
], check)
