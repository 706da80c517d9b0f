"""The TCP side of the gateway: one client at a time, greeting, handshake, framing.

Like the original, the server talks to one client at a time. Unlike the original
(whose second client hung and was then reset), a second client gets one clear line
and is closed, without disturbing the first. A client whose connection closes while
it waits for a move is gone (``Connection.poll``): the move is abandoned, the session
ends at once (its close event says why) and the robot stops (``Gateway.end_session``),
so the next client is accepted instead of waiting for the end of a move nobody waits for.

Each session runs on a thread of its own that reads the socket, executes the command
and answers, with blocking calls all the way: a command that crosses the bus waits
for its Zenoh reply on this same thread (``rob6.bus.Bus.request``), so a request costs
the TCP round trip, the Zenoh round trip and the work, and no hand-off between threads
or an event loop (docs/PERFORMANCE.md).
"""

from __future__ import annotations

import contextlib
import ipaddress
import itertools
import logging
import select
import socket
import threading
import time
from collections import deque

from rob6.bus import new_cid

from .commands import ClientGone, Close, Gateway
from .framing import MAX_LINE, Framer, Line
from .state import Session

log = logging.getLogger("rob6.gateway")

GREETING = b"welcome to rob6server 0.1.01 !\n"
BUSY = b"ERROR: server busy, another client is connected\n"
HANDSHAKE = ("Hello Robot", "Hello Kuka")
QUEUE_LIMIT = 256  # pipelined commands read ahead; beyond it TCP back-pressure holds the client
RECV_BYTES = 65536
#: a client arriving while the last one's connection has closed but its session is still
#: ending (its thread has yet to read the close, or a move is being abandoned) waits this
#: long for the session's end rather than be told the server is busy
RELEASE_WAIT_S = 1.0


class Connection:
    """One client's socket, read by its session's thread: the lines it sent, and whether
    it closed.

    ``next_line`` blocks for the next command; ``poll`` (the bus's watcher thread, while the
    session's thread waits for a move) takes in what has arrived without blocking and tells
    whether the client has gone.
    """

    def __init__(self, sock: socket.socket, max_line: int, pause_s: float, idle_timeout_s: float | None):
        self.sock = sock
        self.framer = Framer(max_line)
        self.pause_s = pause_s
        self.idle_timeout_s = idle_timeout_s
        self.lines: deque[Line] = deque()
        self.closed = False  # the client closed its side (or the connection broke)
        self._timeout: float | None = -1.0  # what the socket is set to (-1: not set yet)

    def next_line(self) -> Line | None:
        """The next complete line; None when the client closed or stayed idle too long."""
        while not self.lines:
            if self.closed:
                return None
            # an unterminated command is complete once the client pauses
            timeout = self.pause_s if self.framer.pending() else self.idle_timeout_s
            if timeout != self._timeout:
                self.sock.settimeout(timeout)
                self._timeout = timeout
            try:
                data = self.sock.recv(RECV_BYTES)
            except TimeoutError:
                if not self.framer.pending():
                    log.warning("closing an idle connection after %.0f s", self.idle_timeout_s or 0)
                    return None
                self.lines.extend(self.framer.flush())
                continue
            except OSError:
                self.closed = True
                continue
            self._take(data)
        return self.lines.popleft()

    def poll(self) -> bool:
        """Take in what the client sent meanwhile, without waiting; True once it has gone."""
        if self.closed:
            return True
        if len(self.lines) >= QUEUE_LIMIT:  # read ahead far enough: let TCP hold the client
            return False
        try:
            readable, _, _ = select.select([self.sock], [], [], 0)
            if readable:
                self._take(self.sock.recv(RECV_BYTES))
        except OSError:
            self.closed = True
        return self.closed

    def has_closed(self) -> bool:
        """Has the client closed its side? Asked from another thread: looks, takes nothing."""
        if self.closed:
            return True
        try:
            return self.sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
        except BlockingIOError:
            return False
        except OSError:
            return True

    def _take(self, data: bytes) -> None:
        if data:
            self.lines.extend(self.framer.feed(data))
        else:  # the client closed: what it sent before still counts
            self.closed = True
            self.lines.extend(self.framer.flush())

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)


class Server:
    def __init__(self, gateway: Gateway, *, pause_s: float = 0.005, idle_timeout_s: float = 0.0,
                 max_line: int = MAX_LINE, allow: AddressFilter | None = None):
        self.gateway = gateway
        self.pause_s = pause_s
        self.idle_timeout_s = idle_timeout_s or None
        self.max_line = max_line
        self.allow = allow
        self.active: Session | None = None
        self._connection: Connection | None = None  # the active session's
        self._free = threading.Event()  # no session is active
        self._free.set()
        self._numbers = itertools.count(1)
        self._threads: list[threading.Thread] = []  # the sessions' threads, ended ones pruned
        self.stopping = False  # rob6 stops: the session still open ends because of that, not its client

    def serve_forever(self, listener: socket.socket) -> None:
        """Accept clients until ``listener`` is closed; each session on a thread of its own."""
        while True:
            try:
                sock, peer = listener.accept()
            except OSError:  # the listener was closed: the gateway stops
                return
            try:
                self.accept(sock, peer)
            except Exception:  # one client's trouble never stops the server
                log.exception("could not take the client %s", peer)
                _close(sock)

    def accept(self, sock: socket.socket, peer: tuple[str, int] | tuple[str, int, int, int]) -> None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        peer_text = f"{peer[0]}:{peer[1]}" if peer else "?"
        if self.allow is not None and peer and not self.allow.allows(peer[0]):
            log.warning("refused client %s: not in the allowed networks", peer_text)
            _close(sock, b"ERROR: access denied for " + peer[0].encode() + b"\n")
            return
        connection = self._connection
        if self.active is not None and connection is not None and connection.has_closed():
            self._free.wait(RELEASE_WAIT_S)  # the last client has gone: its session is ending
        if self.active is not None:
            log.warning("refused client %s: session %d is active", peer_text, self.active.number)
            _close(sock, BUSY)
            return
        connection = Connection(sock, self.max_line, self.pause_s, self.idle_timeout_s)
        session = Session(number=next(self._numbers), peer=peer_text, client_gone=connection.poll)
        self._free.clear()
        self.active, self._connection = session, connection
        thread = threading.Thread(target=self.handle, args=(session, connection), name=f"session-{session.number}",
                                  daemon=True)
        self._threads = [t for t in self._threads if t.is_alive()] + [thread]
        thread.start()

    def close(self, timeout: float) -> None:
        """The gateway stops (after the listener closed): the session still open ends (the
        planner brings whatever it left moving to rest), and every session's thread, and
        that end, get ``timeout`` to finish, so its last records (the reply to Quit, the
        close event) are queued before the bus closes."""
        self.stopping = True
        connection = self._connection
        if self.active is not None and connection is not None:
            with contextlib.suppress(OSError):  # already closed
                connection.sock.shutdown(socket.SHUT_RDWR)  # wakes its thread's read
        deadline = time.monotonic() + timeout
        for thread in list(self._threads):
            thread.join(max(0.0, deadline - time.monotonic()))
        self.gateway.wait_session_end(max(0.0, deadline - time.monotonic()))

    def handle(self, session: Session, connection: Connection) -> None:
        log.info("session %d: client %s connected", session.number, session.peer)
        self.gateway.record_event(session, "open", GREETING.decode())
        reason = ""
        try:
            connection.send(GREETING)
            self._serve(session, connection)
        except (OSError, ClientGone) as exc:
            if self.stopping:  # the gateway closed the connection: not the client's doing
                reason = "rob6 stopped"
                log.info("session %d: %s", session.number, reason)
            elif isinstance(exc, ClientGone):
                reason = str(exc)
                log.warning("session %d: %s", session.number, reason)
            else:
                log.info("session %d: connection to client lost", session.number)
        except Exception:
            log.exception("session %d failed", session.number)
        finally:
            self._release(session, abandoned=bool(reason))
            _close(connection.sock)
            log.info("session %d ended", session.number)
            self.gateway.record_event(session, "close", reason=reason)

    def _release(self, session: Session, abandoned: bool = False) -> None:
        """The session is over: whatever it left moving stops from now (``Gateway.end_session``),
        and the next client is taken. Before the last reply (Quit's ``bye!``) or the close,
        so a client that reconnects the moment it read them is never told the server is busy."""
        if self.active is session:
            self.gateway.end_session(session, abandoned=abandoned)
            self.active = None
            self._free.set()

    def _serve(self, session: Session, connection: Connection) -> None:
        gateway = self.gateway
        handshake_done = False
        while (line := connection.next_line()) is not None:
            received = time.time()
            session.cid = new_cid()
            close = shutdown = False
            reply: str | None
            if line.too_long:
                reply = f"ERROR: line too long ({line.too_long} bytes, limit {self.max_line})\n"
            elif not handshake_done:
                handshake_done = any(word in line.text for word in HANDSHAKE)
                reply = "accepted\n" if handshake_done else "failed\n"
                close = not handshake_done
            elif not line.text:
                continue  # empty lines get no answer (some clients send "\n\n")
            else:
                try:
                    reply = gateway.execute(session, line.text)
                except Close as exc:
                    reply, close, shutdown = exc.reply, True, exc.shutdown
                except ClientGone:
                    gateway.record(session, received, line, None)
                    raise
            if close:
                self._release(session)
            if reply:
                connection.send(reply.encode("latin-1"))  # the whole reply in one send
            if gateway.verbosity >= 3:
                log.info("<<< %s", line.text)
                if reply:
                    log.info(">>> %s", reply.rstrip("\n"))
            gateway.record(session, received, line, reply)
            if shutdown:
                gateway.shutdown_requested.set()
            if close:
                return


class AddressFilter:
    """Client allowlist: addresses or networks (CIDR)."""

    def __init__(self, networks: list[str]):
        self._networks = [ipaddress.ip_network(n, strict=False) for n in networks]

    def allows(self, host: str) -> bool:
        address = ipaddress.ip_address(host)
        if address.version == 6 and address.ipv4_mapped:
            address = address.ipv4_mapped
        return any(address in network for network in self._networks)


def _close(sock: socket.socket, last: bytes = b"") -> None:
    try:
        if last:
            sock.sendall(last)
        sock.close()
    except OSError:
        pass
