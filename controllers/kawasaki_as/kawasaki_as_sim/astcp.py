"""The controller's TCP/IP option: the AS TCP instructions on real sockets, with their codes and limits.

``TCP_LISTEN`` opens a port (8192..65535), ``TCP_ACCEPT`` waits up to its timeout (above 0, up to 60 s)
for a client and gives it a socket number, ``TCP_RECV`` waits up to its timeout for data
and returns it split into string elements of at most ``max`` characters (1..255), at
most 4096 bytes a call, ``TCP_SEND`` sends string elements, ``TCP_CLOSE`` and
``TCP_END_LISTEN`` close. Results: 0 (or the socket number) done, -34024 the timeout ran
out, -34025 the connection failed or is gone; a peer that closed makes ``TCP_RECV``
return 0 with no element. (Codes and limits: deploy/kawasaki/REFERENCES.md.)

Nothing blocks: an instruction that has to wait returns None and is asked again on the
next tick. Time is the controller's clock (server.py), which never runs ahead of
``time.monotonic()``: data that arrived after it is not there yet. A port of the program
is reached on the host at ``port_map[port]`` (the stand-in's ``--port``), any other at its
own number. ``latency_s`` holds what arrives back that long (a slow controller network,
the fault ``slow_ack``).
"""

from __future__ import annotations

import socket
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from .asrun import AsError, Value

TIMEOUT = -34024.0
FAILED = -34025.0
PORT_RANGE = (8192, 65535)
#: (exclusive, inclusive): sub-second timeouts are what public AS code uses (issue 58 item 9)
TIMEOUT_RANGE = (0.0, 60.0)
MAX_ELEMENT = 255
MAX_BYTES_PER_RECV = 4096


@dataclass
class Conn:
    sock: socket.socket
    peer: tuple[str, int]
    inbound: deque[tuple[float, bytes]] = field(default_factory=deque)  # (arrival, data)
    outbound: bytearray = field(default_factory=bytearray)
    closed_by_peer: bool = False
    failed: bool = False


class TcpOption:
    def __init__(self, host: str, port_map: dict[int, int], on_accept: Callable[[Conn], None],
                 on_data: Callable[[Conn, bytes, float], None], on_sent: Callable[[Conn, bytes, float], None]):
        self.host = host
        self.port_map = port_map
        self.listeners: dict[int, socket.socket] = {}
        self.conns: dict[int, Conn] = {}
        self.latency_s = 0.0
        self.accepted: dict[int, int] = {}  # connections accepted, by the program's port
        self._polled = time.monotonic()  # when the network was last read
        self._next = 1
        self._on_accept, self._on_data, self._on_sent = on_accept, on_data, on_sent

    def address(self, port: int) -> tuple[str, int] | None:
        sock = self.listeners.get(port)
        if sock is None:
            return None
        host, bound = sock.getsockname()[:2]
        return host, bound

    # ---- the instructions --------------------------------------------------------
    def op(self, name: str, args: list[Value], started: float, now: float) -> tuple[Value, ...] | None:
        """The instruction ``name`` begun at ``started``: its results, or None while it waits."""
        if name == "tcp_listen":
            port = _port(args[0])
            if port not in self.listeners:
                sock = socket.create_server((self.host, self.port_map.get(port, port)), backlog=4)
                sock.setblocking(False)
                self.listeners[port] = sock
            return (0.0,)
        if name == "tcp_end_listen":
            listening = self.listeners.pop(_port(args[0]), None)
            if listening is None:
                return (FAILED,)
            listening.close()
            return (0.0,)
        if name == "tcp_accept":
            port, timeout = _port(args[0]), _timeout(args[1])
            listener = self.listeners.get(port)
            if listener is None:
                return (FAILED,)
            try:
                sock, peer = listener.accept()
            except BlockingIOError:
                return (TIMEOUT,) if now - started >= timeout else None
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            number = self._next
            self._next += 1
            conn = Conn(sock, peer[:2])
            self.conns[number] = conn
            self.accepted[port] = self.accepted.get(port, 0) + 1
            self._on_accept(conn)
            return (float(number), *(float(b) for b in socket.inet_aton(peer[0])))
        client = self.conns.get(_number(args[0]))
        if name == "tcp_close":
            if client is None:
                return (FAILED,)
            self._close(_number(args[0]))
            return (0.0,)
        if name == "tcp_recv":
            timeout, most = _timeout(args[3]), args[4]
            if not isinstance(most, float) or most != int(most) or not 1 <= most <= MAX_ELEMENT:
                raise AsError("E4007", f"TCP_RECV: at most {MAX_ELEMENT} characters an element, not {most!r}")
            if client is None or client.failed:
                return (FAILED,)
            received = self._take(client, now)
            if received:
                text = received.decode("latin-1")
                step = int(most)
                return (0.0, *(text[i:i + step] for i in range(0, len(text), step)))
            if client.closed_by_peer and not client.inbound:
                return (0.0,)
            return (TIMEOUT,) if now - started >= timeout else None
        if name == "tcp_send":
            payload, timeout = args[1], _timeout(args[3])
            assert isinstance(payload, str)
            if client is None or client.failed or client.closed_by_peer:
                return (FAILED,)
            if len(client.outbound) > 65536:  # the peer does not read: wait for room
                return (TIMEOUT,) if now - started >= timeout else None
            raw = payload.encode("latin-1")
            client.outbound += raw
            self._on_sent(client, raw, time.monotonic())
            self._flush(client)
            return (0.0,)
        raise AsError("", f"unknown instruction {name.upper()}")

    def _take(self, conn: Conn, now: float) -> bytes:
        out = bytearray()
        while conn.inbound and conn.inbound[0][0] + self.latency_s <= now and len(out) < MAX_BYTES_PER_RECV:
            arrival, chunk = conn.inbound.popleft()
            room = MAX_BYTES_PER_RECV - len(out)
            if len(chunk) > room:
                conn.inbound.appendleft((arrival, chunk[room:]))
                chunk = chunk[:room]
            out += chunk
        return bytes(out)

    # ---- the network -------------------------------------------------------------
    def sockets(self) -> list[socket.socket]:
        return [c.sock for c in self.conns.values() if not c.failed and not c.closed_by_peer]

    def poll(self) -> None:
        """Read what arrived and send what waits, on every connection. What is read now
        arrived at the latest now, at the earliest when the network was last read: it is
        stamped with the earliest, so that the ticks a held-up controller catches up on
        (server.py) see it, as a controller that was not held up would have."""
        now, since = time.monotonic(), self._polled
        self._polled = now
        for conn in list(self.conns.values()):
            if conn.failed:
                continue
            while not conn.closed_by_peer:
                try:
                    data = conn.sock.recv(65536)
                except BlockingIOError:
                    break
                except OSError:
                    conn.failed = True
                    break
                if not data:
                    conn.closed_by_peer = True
                    break
                conn.inbound.append((since, data))
                self._on_data(conn, data, now)
            self._flush(conn)

    def _flush(self, conn: Conn) -> None:
        while conn.outbound and not conn.failed:
            try:
                sent = conn.sock.send(conn.outbound)
            except BlockingIOError:
                return
            except OSError:
                conn.failed = True
                return
            del conn.outbound[:sent]

    def drop(self) -> bool:
        """The network drops every connection (a fault): the client sees it closed, the
        program its next TCP_RECV or TCP_SEND fail."""
        dropped = False
        for conn in self.conns.values():
            if not conn.failed:
                conn.failed = dropped = True
                conn.sock.close()
        return dropped

    def _close(self, number: int) -> None:
        conn = self.conns.pop(number)
        if not conn.failed:
            self._flush(conn)
            conn.sock.close()

    def connected(self) -> bool:
        return any(not c.failed and not c.closed_by_peer for c in self.conns.values())

    def close_all(self) -> None:
        for number in list(self.conns):
            self._close(number)
        for sock in self.listeners.values():
            sock.close()
        self.listeners.clear()


def _port(x: Value) -> int:
    if not isinstance(x, float) or x != int(x) or not PORT_RANGE[0] <= x <= PORT_RANGE[1]:
        raise AsError("", f"port {x!r} outside {PORT_RANGE[0]}..{PORT_RANGE[1]}")
    return int(x)


def _timeout(x: Value) -> float:
    if not isinstance(x, float) or not TIMEOUT_RANGE[0] < x <= TIMEOUT_RANGE[1]:
        raise AsError("", f"timeout {x!r} not above {TIMEOUT_RANGE[0]:g} and up to {TIMEOUT_RANGE[1]:g} s")
    return x


def _number(x: Value) -> int:
    if not isinstance(x, float) or x != int(x):
        raise AsError("", f"socket number {x!r}")
    return int(x)
