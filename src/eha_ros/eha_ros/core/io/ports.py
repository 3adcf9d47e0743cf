"""TCP ports on the loopback for the servers the tools and tests start (live view, dashboard)."""
from __future__ import annotations

import random
import socket


def is_free(port: int) -> bool:
    """True when a TCP socket can bind ``port`` on the loopback right now."""
    with socket.socket() as s:
        try:
            s.bind(('127.0.0.1', port))
            return True
        except OSError:
            return False


def free_port() -> int:
    """A TCP port free on the loopback right now, drawn below the kernel's ephemeral range: a
    port the kernel hands out itself (bind to port 0, the local end of a connection) can be
    taken again between this call and the server's bind (the live view's server found its port
    in use, once in three runs of tests/test_live.py)."""
    try:
        with open('/proc/sys/net/ipv4/ip_local_port_range') as fh:
            first = int(fh.read().split()[0])
    except (OSError, ValueError, IndexError):
        first = 32768
    draw = random.SystemRandom()
    for _ in range(200):
        port = draw.randrange(max(1024, first - 12000), first)
        if is_free(port):
            return port
    raise RuntimeError('no free TCP port below the ephemeral range')
