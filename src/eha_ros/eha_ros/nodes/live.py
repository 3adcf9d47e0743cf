"""live node: the running stack served over the Foxglove WebSocket protocol (foxglove-sdk).

Every topic under /eha (plus /diagnostics) is found as it appears (nodes.tap: raw CDR with the
publishers' QoS) and served as a channel with message encoding ``cdr`` and a ``ros2msg``
schema holding the full message definition, the bytes exactly as sent: the Foxglove app,
Lichtblick and PlotJuggler decode them without the packages. Inside eha_loop (run_stack
--live) the loop's topics arrive in-process as message objects, encoded here (core.io.cdr). A
message is only taken while a client is subscribed to its channel (``Channel.has_sinks``),
queued, and handed to the server in one burst every ``live.flush_period``;
``live.decimation`` keeps every N-th message of a topic. log time = the message's header stamp (sim time in lock-step, where
the newest stamp is also broadcast as the server time), else receive time.

The services under the namespace are offered to the viewer with JSON requests and responses,
each call forwarded to the ROS service: the read-only ones always, those that act on the
actuator (/eha/inject_fault, /eha/switch_channel, /eha/bridge/arm, ...) as
``live.services_allow`` says (default: all when bound to loopback, none beyond it, where one
WARN line at start-up names what is exposed). The node parameters of the stack appear in the
viewer's parameter panel as ``node:name``, read through each node's rcl_interfaces services;
setting one from the viewer is refused here. Counts per topic, clients and forwarded calls
go to /diagnostics.
"""
from __future__ import annotations

import collections
import importlib
import json
import sys
import threading
import time

import foxglove
from rclpy.clock import Clock, ClockType

from ..core.io.live_params import (SCHEMA, allow_patterns, decimation, exposure, is_loopback,
                                   served_topics, service_offered)
from ..core.io.mcap_sink import stamp_ns
from ..core.config.params import ParamError
from ..core.io.ws_subprotocol import SubprotocolRelay
from . import diag, msgdefs
from .compose import unlocked
from .common import declare_and_validate, factory, run
from .tap import TopicTap, encoder


def to_dict(msg):
    """A ROS message -> plain JSON-able dict (nested messages and arrays included)."""
    if not hasattr(msg, 'get_fields_and_field_types'):
        if isinstance(msg, (bytes, bytearray)):
            return list(msg)
        if hasattr(msg, 'tolist'):
            return msg.tolist()
        if isinstance(msg, (list, tuple)):
            return [to_dict(v) for v in msg]
        return msg
    return {f: to_dict(getattr(msg, f)) for f in msg.get_fields_and_field_types()}


def from_dict(cls, data):
    """JSON dict -> message of ``cls``; ValueError names an unknown field or a wrong type."""
    if not isinstance(data, dict):
        raise ValueError(f'{cls.__name__}: expected a JSON object, got {type(data).__name__}')
    msg = cls()
    fields = msg.get_fields_and_field_types()
    for key, value in data.items():
        if key not in fields:
            raise ValueError(f'{cls.__name__} has no field {key!r} '
                             f'(fields: {", ".join(fields)})')
        current = getattr(msg, key)
        if hasattr(current, 'get_fields_and_field_types'):
            value = from_dict(type(current), value)
        try:
            setattr(msg, key, value)
        except (TypeError, ValueError, AssertionError) as err:
            raise ValueError(f'{cls.__name__}.{key} = {value!r}: {err}') from None
    return msg


def _ros_value(p):
    """rcl_interfaces ParameterValue -> Python value (None when not set)."""
    t = p.type
    return {1: lambda: p.bool_value, 2: lambda: p.integer_value, 3: lambda: p.double_value,
            4: lambda: p.string_value, 5: lambda: bytes(p.byte_array_value),
            6: lambda: list(p.bool_array_value), 7: lambda: list(p.integer_array_value),
            8: lambda: list(p.double_array_value),
            9: lambda: list(p.string_array_value)}.get(t, lambda: None)()


# rcl_interfaces service kind -> the name every node serves it under (~/<name>)
_PARAM_SERVICES = {'ListParameters': 'list_parameters', 'GetParameters': 'get_parameters',
                   'SetParameters': 'set_parameters'}


class Listener(foxglove.ServerListener):
    """The server's callbacks (its own thread) -> the live node; the rest keep the
    protocol's defaults."""

    def __init__(self, node):
        self.node = node

    def on_subscribe(self, client, channel):
        self.node.viewers.add(client.id)

    def on_get_parameters(self, client, param_names, request_id=None):
        return self.node.get_parameters_for(param_names)

    def on_set_parameters(self, client, parameters, request_id=None):
        return self.node.set_parameters_from(parameters)


class Live:
    """The live node (rclpy base: its transport, common.bind)."""

    def __init__(self, params: dict):
        super().__init__('live')
        self.p = p = declare_and_validate(self, SCHEMA, params)
        self.every = decimation(p['live.decimation'])
        self.allow = allow_patterns(p['live.services_allow'])
        self.loopback = is_loopback(p['live.host'])
        extra = {t for t in p['live.extra_topics'] if t}
        if p['live.diagnostics']:
            extra.add('/diagnostics')
        self.channels = {}           # topic -> foxglove.Channel
        self.received = {}           # topic -> messages received
        self.sent = {}               # topic -> messages handed to the server
        self.calls = {'ok': 0, 'failed': 0}
        self.forwarded = {}          # service name -> (ROS client, srv class) or None
        self.param_clients = {}      # (node, srv kind) -> ROS client
        self.viewers = set()
        self.latest_ns = 0
        self.closed = False
        self.queue = collections.deque()   # ((topic, log, stamped), data, receive ns)
        self.dropped = 0
        self.flush = p['live.flush_period']
        sim_time = self.get_parameter('use_sim_time').value
        caps = [foxglove.Capability.Services]
        if p['live.parameters']:
            caps.append(foxglove.Capability.Parameters)
        if sim_time:
            caps.append(foxglove.Capability.Time)
        # the SDK server on a private port, behind the relay that also accepts the
        # protocol's older name (core.io.ws_subprotocol)
        self.server = foxglove.start_server(
            name='eha live', host='127.0.0.1', port=0, capabilities=caps,
            server_listener=Listener(self), supported_encodings=['json'])
        try:
            self.relay = SubprotocolRelay(p['live.host'], p['live.port'], self.server.port)
        except OSError as err:                # port taken, bad address: one line
            self.server.stop()
            raise ParamError(f'live: cannot serve on {p["live.host"]}:{p["live.port"]}: '
                             f'{err.strerror or err}') from None
        self.port = self.relay.port
        self.pub_diag = diag.publisher(self)
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.tap = TopicTap(self, p['live.namespace'], extra, p['live.depth'],
                            self.open_topic, 'serving')
        self.create_timer(p['live.discovery_period'], self.discover, clock=wall)
        self.create_timer(p['live.diagnostics_period'], self.publish_diagnostics,
                          clock=wall)
        if sim_time:
            self.create_timer(p['live.time_period'], self.broadcast_time, clock=wall)
        if self.flush:           # the hand-over in a thread of its own, off the bus lock
            self.flusher = threading.Thread(target=self.flush_every_period,
                                            name='live-flush', daemon=True)
            self.flusher.start()
        url = f'ws://{p["live.host"]}:{self.port}'
        self.get_logger().info(
            f'live: {url} (foxglove.websocket.v1 / foxglove.sdk.v1) serving '
            f'{served_topics(p)}' + (f', decimated {self.every}' if self.every else ''))
        if not self.loopback:                 # said once: who can reach it, what they get
            self.get_logger().warning(exposure(p, url))
        self.discover()

    # ---- topics
    def open_topic(self, topic, type_name, definition, stamped, ends, offered):
        pkg, name = msgdefs.split_type(type_name)
        ch = foxglove.Channel(topic, message_encoding='cdr', schema=foxglove.Schema(
            name=f'{pkg}/msg/{name}', encoding='ros2msg', data=definition.encode()))
        self.channels[topic] = ch
        self.received[topic] = self.sent[topic] = 0
        every = self.every.get(topic, 1)
        has_sinks, now = ch.has_sinks, time.time_ns
        counts, queue, at_once = self.received, self.queue, not self.flush
        backlog = self.p['live.backlog']
        entry = (topic, ch.log, stamped)
        encode = encoder(type_name)

        @unlocked                    # in eha_loop: touches nothing the loop shares
        def on_message(data):
            """CDR bytes from DDS, or in eha_loop the message object itself (delivered
            in the publisher's thread, which may reuse it: serialized here): queued
            with its receive time for the flusher."""
            n = counts[topic] = counts[topic] + 1
            if n % every or not has_sinks():
                return
            if len(queue) >= backlog:
                self.dropped += 1
                return
            if not isinstance(data, bytes):
                data = encode(data)
            queue.append((entry, data, now()))
            if at_once:
                self.flush_queue()
        on_message.eha_wanted = has_sinks     # eha_loop: nothing built for no viewer
        return on_message

    def flush_queue(self):
        """Hand the queued messages to the server. log time = the header stamp, else the
        receive time."""
        queue, sent = self.queue, self.sent
        while queue:
            (topic, log, stamped), data, t_recv = queue.popleft()
            t = stamp_ns(data) if stamped else None
            if t is None or t <= 0:
                t = t_recv
            else:
                self.latest_ns = t
            log(data, log_time=t)
            sent[topic] += 1

    def flush_every_period(self):
        """The flusher thread: one burst per period, so the server's sender wakes once
        per burst, not per message (bench live: in the receiving thread, under eha_loop's
        bus lock, it cost more)."""
        while not self.closed:
            time.sleep(self.flush)
            try:
                self.flush_queue()
            except Exception as err:         # the server stopped under us: say it once
                if not self.closed:
                    self.get_logger().error(f'live: handing messages to the server: '
                                            f'{err}')
                return

    @unlocked                    # graph queries must not hold up a composed loop
    def discover(self):
        self.tap.discover()
        if self.p['live.services']:
            self.discover_services()

    @diag.reader
    def broadcast_time(self):
        if self.latest_ns:
            self.server.broadcast_time(self.latest_ns)

    # ---- services: JSON from the viewer -> ROS service -> JSON back
    def discover_services(self):
        """Offer each new service under the namespace the viewer may call (decided once per
        name: live_params.service_offered)."""
        new = []
        for name, types in self.get_service_names_and_types():
            if name in self.forwarded or not self.tap.wanted(name) or \
                    name.startswith(f'/{self.get_name()}/'):
                continue
            self.forwarded[name] = None        # withheld unless offered below
            if not service_offered(name, types[0], self.allow, self.loopback):
                self.get_logger().info(f'{name} [{types[0]}]: not offered (acts on the '
                                       f'actuator; {self._withheld_because()})')
                continue
            service = self._offer(name, types[0])
            if service is not None:
                new.append(service)
        if new:
            self.server.add_services(new)

    def _withheld_because(self) -> str:
        if self.allow:
            return 'live.services_allow does not name it'
        return f'bound to {self.p["live.host"]}, beyond loopback, with no live.services_allow'

    def _offer(self, name, type_name):
        """The foxglove Service forwarding to ROS service ``name``; None (warned) when its
        type is not installed here."""
        pkg, _, srv = (type_name.split('/') + ['', ''])[:3]
        try:
            cls = getattr(importlib.import_module(f'{pkg}.srv'), srv)
        except (ImportError, AttributeError):
            self.get_logger().warning(f'{name}: service type {type_name} not installed: '
                                      f'not offered')
            return None
        self.forwarded[name] = (self.create_client(cls, name), cls)
        schema = foxglove.ServiceSchema(
            name=type_name,
            request=self._json_schema(f'{pkg}/srv/{srv}_Request', cls.Request),
            response=self._json_schema(f'{pkg}/srv/{srv}_Response', cls.Response))
        self.get_logger().info(f'serving service {name} [{type_name}] (JSON)')
        return foxglove.Service(name, schema=schema, handler=self.call_service)

    @staticmethod
    def _json_schema(name, cls):
        return foxglove.MessageSchema(encoding='json', schema=foxglove.Schema(
            name=name, encoding='ros2msg', data=msgdefs.generated_text(cls).encode()))

    def _wait(self, future):
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        if not done.wait(self.p['live.call_timeout']):
            raise TimeoutError(f'no answer within {self.p["live.call_timeout"]:g} s')
        return future.result()

    def call_service(self, request) -> bytes:
        """foxglove Service handler (server thread): forward, wait, answer; an exception's
        text goes back to the viewer as the error."""
        name = request.service_name
        try:
            if not self.forwarded.get(name):
                raise RuntimeError(f'{name}: not offered by this live view')
            client, cls = self.forwarded[name]
            data = json.loads(request.payload or b'{}')
            ros_request = from_dict(cls.Request, data)
            if not client.service_is_ready():
                raise RuntimeError(f'{name}: no server')
            response = self._wait(client.call_async(ros_request))
            self.calls['ok'] += 1
            self.get_logger().info(f'{name}: called from the viewer: {data} -> '
                                   f'{to_dict(response)}')
            return json.dumps(to_dict(response)).encode()
        except Exception as err:
            self.calls['failed'] += 1
            self.get_logger().warning(f'{name}: call from the viewer failed: {err}')
            raise RuntimeError(str(err)) from None

    # ---- parameters 'node:name' through the nodes' own parameter services
    def _param_client(self, node, kind):
        from rcl_interfaces import srv
        key = (node, kind)
        if key not in self.param_clients:
            self.param_clients[key] = self.create_client(
                getattr(srv, kind), f'/{node}/{_PARAM_SERVICES[kind]}')
        return self.param_clients[key]

    def _stack_nodes(self):
        return sorted({n for n, ns in self.get_node_names_and_namespaces()
                       if ns == '/' and n != self.get_name() and not n.startswith('_')})

    def _get(self, node, names=None):
        from rcl_interfaces.srv import GetParameters, ListParameters
        out = []
        lc = self._param_client(node, 'ListParameters')
        gc = self._param_client(node, 'GetParameters')
        if not (lc.service_is_ready() and gc.service_is_ready()):
            return out
        if names is None:
            names = list(self._wait(lc.call_async(ListParameters.Request())).result.names)
        if not names:
            return out
        values = self._wait(gc.call_async(GetParameters.Request(names=names))).values
        for n, v in zip(names, values):
            value = _ros_value(v)
            if value is not None:
                out.append(foxglove.Parameter(f'{node}:{n}', value=value))
        return out

    def get_parameters_for(self, param_names):
        try:
            if not param_names:
                return [p for node in self._stack_nodes() for p in self._get(node)]
            by_node = {}
            for full in param_names:
                node, _, name = full.partition(':')
                by_node.setdefault(node, []).append(name)
            return [p for node, names in by_node.items() for p in self._get(node, names)]
        except Exception as err:
            self.get_logger().warning(f'parameters requested by the viewer: {err}')
            return []

    def set_parameters_from(self, parameters):
        """Refused, every one, without reaching the node (use_sim_time and any parameter a
        node left writable would change the running stack): an error status, and the
        current values back."""
        out = []
        for par in parameters:
            node, _, name = par.name.partition(':')
            self.server.publish_status(f'{par.name}: not set: parameters are read-only in '
                                       f'the live view', foxglove.StatusLevel.Error)
            self.get_logger().warning(f'parameter {par.name} from the viewer: refused '
                                      f'(read-only)')
            try:
                out += self._get(node, [name]) if node else []
            except Exception as err:
                self.get_logger().warning(f'parameter {par.name}: {err}')
        return out

    # ---- diagnostics, shutdown
    @diag.reader
    def publish_diagnostics(self, final: bool = False):
        values = {'url': f'ws://{self.p["live.host"]}:{self.port}',
                  'topics': len(self.channels), 'services': len(
                      [s for s in self.forwarded.values() if s]),
                  'received': sum(self.received.values()), 'sent': sum(self.sent.values()),
                  'dropped': self.dropped,
                  'viewers_seen': len(self.viewers), 'calls_ok': self.calls['ok'],
                  'calls_failed': self.calls['failed'],
                  'finished': final}
        values.update({f'sent {t}': n for t, n in sorted(self.sent.items())})
        diag.publish(self, self.pub_diag, 'websocket', values)

    def close(self):
        if self.closed:
            return
        self.closed = True
        if self.flush:
            self.flusher.join(timeout=1.0)
        try:
            self.flush_queue()                 # what the last period queued
        except Exception:
            pass
        self.relay.close()
        self.server.stop()
        self.get_logger().info(f'live: {sum(self.sent.values())} of '
                               f'{sum(self.received.values())} messages served on '
                               f'{len(self.channels)} topics')
        try:
            self.publish_diagnostics(final=True)
        except Exception:                # context already shut down: the log has it
            pass


make_node = factory(Live)     # make_node(params, transport=None)


def main(argv=None) -> int:
    return run('live', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
