"""The asyncio twin: ``async with AsyncRobot("host", 5005) as robot: await robot.get_robot()``."""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager, suppress
from typing import TypeVar

from ._methods import AsyncRobotCommands
from .client import DEFAULT_PORT
from .errors import Rob6ConnectionError, Rob6Error, Rob6Timeout
from .protocol import MAYBE_FALSE, MAYBE_FALSE_GRACE_S, READ, Command, ExchangeOf, Pause, Send, handshake

R = TypeVar("R")


class AsyncRobot(AsyncRobotCommands):
    """The same methods as ``Robot``, as coroutines; the same parsing, only the I/O differs.

    Connect with ``async with AsyncRobot(host, port) as robot:`` or ``await robot.connect()``.
    Calls from several tasks are serialised. A call that is cancelled or times out closes
    the connection (its reply could otherwise be taken for the next command's).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, timeout: float = 10.0,
                 move_timeout: float = 300.0, connect_timeout: float = 5.0) -> None:
        self.host, self.port = host, port
        self.timeout = timeout
        self.move_timeout = move_timeout
        self.connect_timeout = connect_timeout
        self.greeting: str | None = None
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._buffer = bytearray()
        self._lock = asyncio.Lock()

    def __repr__(self) -> str:
        return f"<AsyncRobot {self.host}:{self.port} {'connected' if self.connected else 'closed'}>"

    @property
    def connected(self) -> bool:
        return self._writer is not None

    async def connect(self) -> AsyncRobot:
        """Open the connection, read the greeting and shake hands."""
        if self.connected:
            return self
        try:
            self._reader, self._writer = reader, writer = await asyncio.wait_for(
                asyncio.open_connection(self.host, self.port), self.connect_timeout)
        except (TimeoutError, OSError) as exc:
            raise Rob6ConnectionError(f"cannot connect to {self.host}:{self.port}: {exc!r}") from exc
        writer.get_extra_info("socket").setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            self.greeting = await self._run("handshake", handshake(), self.connect_timeout)
        except Rob6Timeout:
            raise Rob6ConnectionError(
                f"{self.host}:{self.port} sent no greeting within {self.connect_timeout:g} s (the original "
                "rob6server keeps a second client waiting silently while another one is connected)") from None
        return self

    async def __aenter__(self) -> AsyncRobot:
        return await self.connect()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self) -> None:
        """Say ``Quit`` if the connection is still usable, then close it (idempotent)."""
        if not self.connected:
            return
        with suppress(Rob6Error, Rob6ConnectionError):
            await self.quit(timeout=min(self.timeout, 2.0))
        self._drop()

    @asynccontextmanager
    async def alter(self, *, adept: bool = False, timeout: float | None = None) -> AsyncIterator[AsyncRobot]:
        """Alter (real-time) mode for the ``async with`` block; see ``Robot.alter``."""
        enable = self.enable_adept_alter if adept else self.enable_alter
        if not await enable(timeout=timeout):
            raise Rob6Error("EnableAdeptAlter" if adept else "EnableAlter", "Alter mode refused (false)")
        try:
            yield self
        except BaseException:
            if self.connected:  # best effort: the block's exception is the one to report
                with suppress(Exception):
                    await self.disable_alter(timeout=timeout)
            raise
        if self.connected:
            await self.disable_alter(timeout=timeout)

    # ------------------------------------------------------------------ I/O

    async def _call(self, command: Command, line: str, timeout: float | None) -> object:
        if timeout is None:
            timeout = self.move_timeout if command.long else self.timeout
        value = await self._run(command.name, command.exchange(line), timeout)
        if command.reply.closes:
            self._drop()
        return value

    async def _run(self, name: str, exchange: ExchangeOf[R], timeout: float) -> R:
        async with self._lock:
            if self._writer is None:
                raise Rob6ConnectionError(f"{name}: the connection is closed")
            deadline = time.monotonic() + timeout
            try:
                action = next(exchange)
                while True:
                    result: str | bool | None
                    if action is READ:
                        result = await self._read_line(name, deadline, timeout)
                    elif action is MAYBE_FALSE:
                        result = await self._maybe_false()
                    elif isinstance(action, Send):
                        await self._send(name, action.line)
                        result = None
                    elif isinstance(action, Pause):
                        await asyncio.sleep(action.seconds)
                        result = None
                    action = exchange.send(result)
            except StopIteration as stop:
                value: R = stop.value
                return value
            except Rob6Error:
                raise  # the whole reply was read: the connection is in step
            except BaseException:
                self._drop()  # timeout, EOF, garbage, cancellation: replies no longer match commands
                raise

    async def _send(self, name: str, line: str) -> None:
        assert self._writer is not None  # connected: _run checked
        try:
            self._writer.write(line.encode("latin-1") + b"\n")
            await self._writer.drain()
        except OSError as exc:
            raise Rob6ConnectionError(f"{name}: sending failed: {exc}") from exc

    async def _read_line(self, name: str, deadline: float, timeout: float) -> str:
        while (end := self._buffer.find(b"\n")) < 0:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not await self._receive(remaining):
                raise Rob6Timeout(f"{name}: no complete reply within {timeout:g} s; connection closed")
        line = bytes(self._buffer[:end])
        del self._buffer[:end + 1]
        return line.decode("latin-1")

    async def _maybe_false(self) -> bool:
        deadline = time.monotonic() + MAYBE_FALSE_GRACE_S
        while b"\n" not in self._buffer:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not await self._receive(remaining):
                return False
        if self._buffer.startswith(b"false\n"):
            del self._buffer[:6]
            return True
        return False

    async def _receive(self, timeout: float) -> bool:
        """Append what arrives within ``timeout`` to the buffer; False when nothing did."""
        assert self._reader is not None  # connected: _run checked
        try:
            chunk = await asyncio.wait_for(self._reader.read(65536), timeout)
        except TimeoutError:
            return False
        except OSError as exc:
            raise Rob6ConnectionError(f"connection lost: {exc}") from exc
        if not chunk:
            raise Rob6ConnectionError("the server closed the connection")
        self._buffer += chunk
        return True

    def _drop(self) -> None:
        writer, self._writer, self._reader = self._writer, None, None
        self._buffer.clear()
        if writer is not None:
            writer.close()
