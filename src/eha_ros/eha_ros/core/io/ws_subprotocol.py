"""Both names of the Foxglove WebSocket protocol on one port: foxglove.websocket.v1 and
foxglove.sdk.v1.

foxglove-sdk's server accepts only the subprotocol name ``foxglove.sdk.v1``, which Foxglove
introduced for the unchanged ws-protocol (github.com/orgs/foxglove/discussions/1131;
Lichtblick accepts it since PR #819, Dec. 2025); PlotJuggler, older Lichtblick and
ws-protocol clients offer ``foxglove.websocket.v1`` and are refused with HTTP 400. This relay
listens on the public port, renames the offered subprotocol in the HTTP upgrade request (and
the chosen one in the answer back), then copies bytes both ways unchanged. A client offering
``foxglove.sdk.v1`` passes through as it is.

The copy is two blocking threads per connection that move whatever arrived, then sleep
BATCH_PERIOD: the frames of the 1 kHz streams cross in a few large reads and writes instead
of one Python wake-up per frame (asyncio reads each segment as it lands: 0.06 core at 4000
frames/s here). The sockets' calls release the GIL; the loop thread hardly notices.
"""
from __future__ import annotations

import re
import socket
import threading
import time

LEGACY, CURRENT = b'foxglove.websocket.v1', b'foxglove.sdk.v1'
_PROTOCOL = re.compile(rb'(?im)^(sec-websocket-protocol:[ \t]*)([^\r\n]*)')
_HEAD_LIMIT = 65536
# s between two copies on a connection; a viewer draws at <= 60 Hz
BATCH_PERIOD = 0.01
_CHUNK = 1 << 20
_HANDSHAKE_TIMEOUT = 5.0


def rename_request(head: bytes) -> tuple[bytes, bool]:
    """Upgrade request head -> (head for the SDK server, whether the answer must be renamed
    back). Only a request that offers the legacy name and not the current one is changed."""
    m = _PROTOCOL.search(head)
    if not m:
        return head, False
    offered = [p.strip() for p in m.group(2).split(b',')]
    if LEGACY not in offered or CURRENT in offered:
        return head, False
    names = b', '.join(CURRENT if p == LEGACY else p for p in offered)
    return head[:m.start(2)] + names + head[m.end(2):], True


def rename_response(head: bytes) -> bytes:
    """The server's chosen subprotocol back to the name the client offered."""
    return _PROTOCOL.sub(lambda m: m.group(1) + m.group(2).replace(CURRENT, LEGACY), head,
                         count=1)


def _read_head(sock) -> bytes:
    """Bytes up to the end of an HTTP head (the rest of a read stays appended)."""
    data = b''
    while b'\r\n\r\n' not in data:
        chunk = sock.recv(4096)
        if not chunk or len(data) > _HEAD_LIMIT:
            raise ConnectionError('no complete HTTP head')
        data += chunk
    return data


def _pump(src, dst, period: float):
    """Copy src -> dst until either side closes; then shut both down."""
    buf = bytearray(_CHUNK)
    view = memoryview(buf)
    try:
        while True:
            n = src.recv_into(buf)
            if not n:
                break
            dst.sendall(view[:n])
            time.sleep(period)
    except OSError:
        pass
    finally:
        for sock in (src, dst):
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


class SubprotocolRelay:
    """Listen on (host, port), relay to the SDK server on 127.0.0.1:``target_port``; an accept
    thread plus two copy threads per connection (daemons). ``port`` is the bound port (useful
    with port 0)."""

    def __init__(self, host: str, port: int, target_port: int,
                 period: float = BATCH_PERIOD):
        self.target_port = target_port
        self.period = period
        self.listener = socket.create_server((host, port))
        self.port = self.listener.getsockname()[1]
        self.closed = False
        self.conns: list[tuple] = []        # (client, server) sockets being relayed
        self.thread = threading.Thread(target=self._accept, name='ws-relay', daemon=True)
        self.thread.start()

    def _accept(self):
        while not self.closed:
            try:
                client, _ = self.listener.accept()
            except OSError:
                break
            threading.Thread(target=self._connect, args=(client,), name='ws-relay',
                             daemon=True).start()

    def _connect(self, client):
        server = None
        try:
            client.settimeout(_HANDSHAKE_TIMEOUT)
            head, rename = rename_request(_read_head(client))
            server = socket.create_connection(('127.0.0.1', self.target_port),
                                              timeout=_HANDSHAKE_TIMEOUT)
            server.sendall(head)
            answer = _read_head(server)
            client.sendall(rename_response(answer) if rename else answer)
        except OSError:
            for sock in (client, server):
                if sock is not None:
                    sock.close()
            return
        for sock in (client, server):
            sock.settimeout(None)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        pair = (client, server)
        self.conns.append(pair)
        threading.Thread(target=_pump, args=(client, server, self.period), name='ws-relay',
                         daemon=True).start()
        _pump(server, client, self.period)
        self.conns.remove(pair)
        client.close()
        server.close()

    def close(self):
        self.closed = True
        for sock in [self.listener] + [s for pair in list(self.conns) for s in pair]:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()
        self.thread.join(timeout=2.0)
