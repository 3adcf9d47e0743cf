"""Test-side ROS endpoints shared by the DDS tests: a /diagnostics collector and a Probe base
(subscriptions that keep what arrives, service calls, waits).

Both only create subscriptions, publishers and clients on a node the test already spins (the
ros_node fixture's Spinner, or a test's own Spinner / executor): their callbacks run on that
executor's thread, and the waits here block the test's thread until the data has arrived."""
from __future__ import annotations

import threading
import time
from collections.abc import Mapping

from ros_util import wait_for


class Status:
    """One DiagnosticStatus as it arrived: ``t`` (time.monotonic() on arrival), ``name``,
    ``level`` (0 OK, 1 WARN, 2 ERROR, ...), ``message``, ``values`` (key -> value: strings, or
    what the collector's ``parse`` made of them) and ``msg`` (the DiagnosticStatus itself)."""

    __slots__ = ('t', 'name', 'level', 'message', 'values', 'msg')

    def __init__(self, t, msg, parse=None):
        self.t, self.msg, self.name, self.message = t, msg, msg.name, msg.message
        self.level = msg.level[0] if isinstance(msg.level, (bytes, bytearray)) else int(msg.level)
        self.values = {kv.key: (kv.value if parse is None else parse(kv.value))
                       for kv in msg.values}

    def fields(self) -> dict:
        """The values with the level and the message as ``_level`` and ``_message``."""
        return dict(self.values, _level=self.level, _message=self.message)

    def __repr__(self):
        return f'Status({self.name!r}, level={self.level}, {self.message!r}, {self.values})'


class DiagnosticsCollector:
    """Subscribes /diagnostics on ``node`` and keeps every status that arrives, by name, under
    a lock. A status is selected by its exact name ('hardware_bridge: loop') or, with
    ``prefix=True``, by the start of it ('plant_sim': every status of that node)."""

    def __init__(self, node, depth: int = 50, parse=None):
        from diagnostic_msgs.msg import DiagnosticArray
        self._cond = threading.Condition()
        self._statuses = []                 # every status, in arrival order
        self._by_name = {}                  # name -> its statuses, in arrival order
        self._parse = parse
        self.subscription = node.create_subscription(DiagnosticArray, '/diagnostics',
                                                     self._on_diag, depth)

    def _on_diag(self, msg):
        now = time.monotonic()
        got = [Status(now, st, self._parse) for st in msg.status]
        with self._cond:
            for s in got:
                self._statuses.append(s)
                self._by_name.setdefault(s.name, []).append(s)
            self._cond.notify_all()

    def _select(self, name, prefix):
        if name is None:
            return self._statuses
        if not prefix:
            return self._by_name.get(name, [])
        names = [n for n in self._by_name if n.startswith(name)]
        if len(names) <= 1:
            return self._by_name[names[0]] if names else []
        return [s for s in self._statuses if s.name.startswith(name)]

    def _count(self, name, prefix):
        if not prefix:
            return len(self._select(name, prefix))
        return sum(len(v) for n, v in self._by_name.items() if n.startswith(name))

    def _newest(self, name, prefix):
        if not prefix:
            got = self._select(name, prefix)
            return got[-1] if got else None
        return next((s for s in reversed(self._statuses) if s.name.startswith(name)), None)

    def all(self, name: str | None = None, prefix: bool = False) -> list:
        """The statuses of ``name`` (None: of every name), oldest first."""
        with self._cond:
            return list(self._select(name, prefix))

    def latest(self, name: str, prefix: bool = False) -> Status | None:
        """The newest status of ``name``, None before the first."""
        with self._cond:
            return self._newest(name, prefix)

    def latest_by_name(self) -> dict:
        """name -> its newest status, for every name seen."""
        with self._cond:
            return {n: v[-1] for n, v in self._by_name.items()}

    def values(self, name: str, prefix: bool = False, merged: bool = False,
               fields: bool = False) -> dict:
        """The newest status's values ({} before the first); ``merged``: every key ever
        reported by a matching status, each with its newest value; ``fields``: with the
        newest status's level and message as ``_level`` and ``_message`` (Status.fields)."""
        with self._cond:
            newest = self._newest(name, prefix)
            if newest is None:
                return {}
            if merged:
                out = {}
                for s in self._select(name, prefix):
                    out.update(s.values)
            else:
                out = dict(newest.values)
            if fields:
                out.update(_level=newest.level, _message=newest.message)
            return out

    def fields(self, name: str, prefix: bool = False) -> dict:
        """The newest status's Status.fields() ({} before the first)."""
        return self.values(name, prefix, fields=True)

    def view(self, name: str, prefix: bool = False, merged: bool = False,
             fields: bool = False) -> Mapping:
        """A read-only dict that always shows ``values(name, prefix, merged, fields)`` as of
        the moment it is read."""
        return _LiveValues(lambda: self.values(name, prefix, merged, fields))

    def wait(self, name: str, pred=None, timeout: float = 20.0, prefix: bool = False,
             new: bool = False) -> bool:
        """Wait until the newest status of ``name`` satisfies ``pred(status)`` (None: until
        there is one); ``new``: only a status that arrives after this call counts. True, or
        False after ``timeout`` seconds."""
        end = time.monotonic() + timeout
        with self._cond:
            n0 = self._count(name, prefix) if new else 0
            while True:
                if self._count(name, prefix) > n0 and \
                        (pred is None or pred(self._newest(name, prefix))):
                    return True
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.5))


class _LiveValues(Mapping):
    def __init__(self, get):
        self._get = get

    def __getitem__(self, key):
        return self._get()[key]

    def __iter__(self):
        return iter(self._get())

    def __len__(self):
        return len(self._get())

    def __repr__(self):
        return repr(self._get())


class Probe:
    """Base of the tests' helper objects on a test-side node: subscriptions that keep what
    arrives (under ``self.lock``: hold it to read several of them consistently), service
    calls with timeouts, waits, and ``self.diagnostics`` (a DiagnosticsCollector; none with
    ``diagnostics=None``)."""

    def __init__(self, node, diagnostics: int | None = 50, parse=None):
        self.node = node
        self.lock = threading.Lock()
        self.diagnostics = DiagnosticsCollector(node, diagnostics, parse) \
            if diagnostics else None
        self._clients = {}

    # ------------------------------------------------------------------ subscriptions
    def subscribe(self, msg_type, topic: str, callback, qos=1000):
        """A plain subscription (``qos``: a depth or a QoSProfile)."""
        return self.node.create_subscription(msg_type, topic, callback, qos)

    def received(self, msg_type, topic: str, qos=1000, stamped: bool = False) -> list:
        """Subscribe ``topic``; returns the list every message is appended to (``stamped``:
        as (time.monotonic() on arrival, message))."""
        got = []

        def on_msg(msg):
            with self.lock:
                got.append((time.monotonic(), msg) if stamped else msg)
        self.subscribe(msg_type, topic, on_msg, qos)
        return got

    def by_seq(self, msg_type, topic: str, qos=1000, value=None) -> dict:
        """Subscribe ``topic``; returns the dict seq -> message (or ``value(message)``)."""
        got = {}

        def on_msg(msg):
            v = msg if value is None else value(msg)
            with self.lock:
                got[msg.seq] = v
        self.subscribe(msg_type, topic, on_msg, qos)
        return got

    # ------------------------------------------------------------------ services
    def client(self, srv_type, name: str):
        """A client of service ``name`` (one per type and name)."""
        key = (srv_type, name)
        if key not in self._clients:
            self._clients[key] = self.node.create_client(srv_type, name)
        return self._clients[key]

    def call(self, client, request, service_timeout: float = 30.0, timeout: float = 20.0):
        """Call ``client`` once its service is there; the response (asserted within the
        timeouts)."""
        assert client.wait_for_service(timeout_sec=service_timeout), \
            f'no {client.srv_name} service'
        fut = client.call_async(request)
        assert wait_for(fut.done, timeout), f'{client.srv_name} did not answer'
        return fut.result()

    def service(self, srv_type, name: str, service_timeout: float = 30.0,
                timeout: float = 20.0, **fields):
        """Call service ``name`` with a ``srv_type.Request(**fields)``; the response."""
        return self.call(self.client(srv_type, name), srv_type.Request(**fields),
                         service_timeout, timeout)

    # ------------------------------------------------------------------ waiting
    def wait(self, pred, timeout: float, message='', period: float = 0.02):
        """Assert that ``pred()`` becomes true within ``timeout`` seconds (polled every
        ``period`` while the executor's thread delivers); ``message``: the assertion's text,
        or a function giving it (evaluated on failure)."""
        assert wait_for(pred, timeout, period), message() if callable(message) else message
