"""Free ports for the servers the tests and the benchmarks start, below the ephemeral range."""

from __future__ import annotations

import random
import socket
import threading
from collections import deque

__all__ = ["TEST_PORTS", "free_port"]

#: Ports handed out for tests: below Linux's ephemeral range (32768-60999), where the
#: kernel picks the local port of every outgoing connection; a port the kernel gave us
#: from that range can be taken by someone's connection before our server binds it
TEST_PORTS = range(20000, 32768)


#: the ports this process handed out last: a port is free until its server binds it, seconds
#: later for a system started in processes, so two calls in a row (a system's gateway port and
#: its router's) could get the same one (a gateway that could not listen on its router's port)
_GIVEN: deque[int] = deque(maxlen=512)
_GIVEN_LOCK = threading.Lock()


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A port nothing listens on (TCP, or UDP with ``socket.SOCK_DGRAM``), on any address, and
    none of the last 512 this process handed out."""
    for _ in range(200):
        port = random.choice(TEST_PORTS)
        with _GIVEN_LOCK:
            if port in _GIVEN:
                continue
            with socket.socket(socket.AF_INET, kind) as sock:
                try:
                    sock.bind(("0.0.0.0", port))
                except OSError:
                    continue
            _GIVEN.append(port)
        return port
    raise RuntimeError("no free port for a test")
