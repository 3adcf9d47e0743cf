"""Both names of the Foxglove WebSocket protocol on one port: foxglove.websocket.v1 and
foxglove.sdk.v1.

foxglove-sdk's server accepts only the subprotocol name ``foxglove.sdk.v1``, which Foxglove
introduced for the unchanged ws-protocol (github.com/orgs/foxglove/discussions/1131;
Lichtblick accepts it since PR #819, Dec. 2025); PlotJuggler, older Lichtblick and
ws-protocol clients offer ``foxglove.websocket.v1`` and are refused with HTTP 400. This relay
listens on the public port, renames the offered subprotocol in the HTTP upgrade request (and
the chosen one in the answer back), then copies bytes both ways unchanged. A client offering
``foxglove.sdk.v1`` passes through as it is.
"""
from __future__ import annotations

import asyncio
import re
import threading

LEGACY, CURRENT = b'foxglove.websocket.v1', b'foxglove.sdk.v1'
_PROTOCOL = re.compile(rb'(?im)^(sec-websocket-protocol:[ \t]*)([^\r\n]*)')
_HEAD_LIMIT = 65536


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


async def _read_head(reader) -> bytes:
    return await reader.readuntil(b'\r\n\r\n')


async def _pipe(reader, writer):
    try:
        while True:
            data = await reader.read(65536)
            if not data:
                break
            writer.write(data)
            await writer.drain()
    except (ConnectionError, asyncio.CancelledError):
        pass
    finally:
        try:
            writer.close()
        except Exception:
            pass


class SubprotocolRelay:
    """Listen on (host, port), relay to the SDK server on 127.0.0.1:``target_port``; runs an
    asyncio loop in a daemon thread. ``port`` is the bound port (useful with port 0)."""

    def __init__(self, host: str, port: int, target_port: int):
        self.target_port = target_port
        self.loop = asyncio.new_event_loop()
        self.server = self.loop.run_until_complete(
            asyncio.start_server(self._client, host, port, limit=_HEAD_LIMIT))
        self.port = self.server.sockets[0].getsockname()[1]
        self.thread = threading.Thread(target=self.loop.run_forever, name='ws-relay',
                                       daemon=True)
        self.thread.start()

    async def _client(self, c_reader, c_writer):
        try:
            head, rename = rename_request(await _read_head(c_reader))
            s_reader, s_writer = await asyncio.open_connection('127.0.0.1', self.target_port,
                                                               limit=_HEAD_LIMIT)
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.LimitOverrunError,
                OSError):
            c_writer.close()
            return
        s_writer.write(head)
        try:
            answer = await _read_head(s_reader)
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.LimitOverrunError):
            c_writer.close()
            s_writer.close()
            return
        c_writer.write(rename_response(answer) if rename else answer)
        await asyncio.gather(_pipe(c_reader, s_writer), _pipe(s_reader, c_writer))

    def close(self):
        def stop():
            self.server.close()
            for task in asyncio.all_tasks(self.loop):
                task.cancel()
            self.loop.stop()
        self.loop.call_soon_threadsafe(stop)
        self.thread.join(timeout=2.0)
