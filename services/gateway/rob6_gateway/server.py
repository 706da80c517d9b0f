"""The TCP side of the gateway: one client at a time, greeting, handshake, framing.

Like the original, the server talks to one client at a time. Unlike the original
(whose second client hung and was then reset), a second client gets one clear line
and is closed, without disturbing the first. A client whose connection closes while
it waits for a move is gone (``Session.gone``): the move is abandoned, the session ends
at once (its close event says why) and the robot stops (``Gateway.end_session``), so
the next client is accepted instead of waiting for the end of a move nobody waits for.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import socket
import time

from rob6.bus import new_cid

from .commands import ClientGone, Close, Gateway
from .framing import MAX_LINE, Framer, Line
from .state import Session

log = logging.getLogger("rob6.gateway")

GREETING = b"welcome to rob6server 0.1.01 !\n"
BUSY = b"ERROR: server busy, another client is connected\n"
HANDSHAKE = ("Hello Robot", "Hello Kuka")
QUEUE_LIMIT = 256  # pipelined commands waiting; beyond it TCP back-pressure holds the client


class Server:
    def __init__(self, gateway: Gateway, *, pause_s: float = 0.005, idle_timeout_s: float = 0.0,
                 max_line: int = MAX_LINE, allow: "AddressFilter | None" = None):
        self.gateway = gateway
        self.pause_s = pause_s
        self.idle_timeout_s = idle_timeout_s or None
        self.max_line = max_line
        self.allow = allow
        self.active: Session | None = None
        self._numbers = itertools.count(1)

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        peer_text = f"{peer[0]}:{peer[1]}" if peer else "?"
        sock = writer.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if self.allow is not None and peer and not self.allow.allows(peer[0]):
            log.warning("refused client %s: not in the allowed networks", peer_text)
            await _close(writer, b"ERROR: access denied for " + peer[0].encode() + b"\n")
            return
        if self.active is not None:
            log.warning("refused client %s: session %d is active", peer_text, self.active.number)
            await _close(writer, BUSY)
            return
        session = Session(number=next(self._numbers), peer=peer_text)
        self.active = session
        log.info("session %d: client %s connected", session.number, peer_text)
        self.gateway.record_event(session, "open", GREETING.decode())
        reason = ""
        try:
            await self._run(session, reader, writer)
        except (ConnectionError, asyncio.IncompleteReadError):
            log.info("session %d: connection to client lost", session.number)
        except ClientGone as exc:
            reason = str(exc)
            log.warning("session %d: %s", session.number, reason)
        finally:
            self.active = None
            self.gateway.end_session(session, abandoned=bool(reason))  # the robot stops (if it moves) from now
            await _close(writer)
            log.info("session %d ended", session.number)
            self.gateway.record_event(session, "close", reason=reason)

    async def _run(self, session: Session, reader, writer) -> None:
        writer.write(GREETING)
        lines: asyncio.Queue[Line | None] = asyncio.Queue(QUEUE_LIMIT)
        read_task = asyncio.create_task(self._read(reader, lines, session.gone))
        try:
            await self._serve(session, lines, writer)
        finally:
            read_task.cancel()

    async def _read(self, reader: asyncio.StreamReader, lines: asyncio.Queue, gone: asyncio.Event) -> None:
        """Lines into ``lines`` (None at the end); ``gone`` set when the client closed (not
        at the idle timeout)."""
        framer = Framer(self.max_line)
        try:
            while True:
                timeout = self.pause_s if framer.pending() else self.idle_timeout_s
                try:
                    data = await asyncio.wait_for(reader.read(65536), timeout)
                except TimeoutError:
                    if not framer.pending():
                        log.warning("closing an idle connection after %.0f s", self.idle_timeout_s)
                        break
                    for line in framer.flush():  # an unterminated command, now complete
                        await lines.put(line)
                    continue
                if not data:
                    gone.set()
                    for line in framer.flush():
                        await lines.put(line)
                    break
                for line in framer.feed(data):
                    await lines.put(line)
        except (ConnectionError, OSError):
            gone.set()
        finally:
            await lines.put(None)

    async def _serve(self, session: Session, lines: asyncio.Queue, writer) -> None:
        gateway = self.gateway
        handshake_done = False
        while True:
            line = await lines.get()
            if line is None:
                return
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
                    reply = await gateway.execute(session, line.text)
                except Close as exc:
                    reply, close, shutdown = exc.reply, True, exc.shutdown
                except ClientGone:
                    gateway.record(session, received, line, None)
                    raise
            if reply:
                writer.write(reply.encode("latin-1"))  # the whole reply in one send
                await writer.drain()
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
        import ipaddress
        self._networks = [ipaddress.ip_network(n, strict=False) for n in networks]
        self._address = ipaddress.ip_address

    def allows(self, host: str) -> bool:
        address = self._address(host)
        if address.version == 6 and address.ipv4_mapped:
            address = address.ipv4_mapped
        return any(address in network for network in self._networks)


async def _close(writer: asyncio.StreamWriter, last: bytes = b"") -> None:
    try:
        if last:
            writer.write(last)
            await writer.drain()
        writer.close()
        await writer.wait_closed()
    except (ConnectionError, OSError):
        pass
