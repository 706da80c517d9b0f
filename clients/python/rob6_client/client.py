"""The blocking client: ``Robot("host", 5005)``."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from typing import TypeVar

from ._methods import RobotCommands
from .errors import Rob6ConnectionError, Rob6Error, Rob6Timeout
from .protocol import MAYBE_FALSE, MAYBE_FALSE_GRACE_S, READ, Command, ExchangeOf, Pause, Send, handshake

DEFAULT_PORT = 5005

R = TypeVar("R")


class Robot(RobotCommands):
    """A session with rob6 or the original rob6server: connects, reads the greeting and
    shakes hands (``Hello Robot`` -> ``accepted``).

    Every protocol command is a method (``forward_calc``, ``move_ptp_joints``...) taking
    ``timeout=`` (seconds); without it, ``timeout`` applies, or ``move_timeout`` for the
    commands that answer when a motion is over. One command is in flight at a time (calls
    from several threads are serialised). After a timeout (or an interrupted call) the
    connection is closed.

    Works with the original rob6server as well: each command goes out in its own write and
    the next only after the whole reply (the original runs only the first command of a
    read); replies are read line by line to their known length (the original writes each
    line separately); arguments are checked before sending (the original would wait for a
    missing one). Per-command differences are in the methods' docstrings.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, timeout: float = 10.0,
                 move_timeout: float = 300.0, connect_timeout: float = 5.0) -> None:
        self.host, self.port = host, port
        self.timeout = timeout
        self.move_timeout = move_timeout
        self._lock = threading.Lock()
        self._buffer = bytearray()
        try:
            self._sock: socket.socket | None = socket.create_connection((host, port), timeout=connect_timeout)
        except OSError as exc:
            raise Rob6ConnectionError(f"cannot connect to {host}:{port}: {exc}") from exc
        # one command per segment: the original treats each read as one message
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            self.greeting: str = self._run("handshake", handshake(), connect_timeout)
        except Rob6Timeout:
            raise Rob6ConnectionError(
                f"{host}:{port} sent no greeting within {connect_timeout:g} s (the original rob6server "
                "keeps a second client waiting silently while another one is connected)") from None

    def __repr__(self) -> str:
        return f"<Robot {self.host}:{self.port} {'connected' if self.connected else 'closed'}>"

    @property
    def connected(self) -> bool:
        return self._sock is not None

    def __enter__(self) -> Robot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Say ``Quit`` if the connection is still usable, then close it (idempotent)."""
        if self._sock is None:
            return
        with suppress(Rob6Error, Rob6ConnectionError):
            self.quit(timeout=min(self.timeout, 2.0))
        self._drop()

    @contextmanager
    def alter(self, *, adept: bool = False, timeout: float | None = None) -> Iterator[Robot]:
        """Alter (real-time) mode for the ``with`` block: EnableAlter (``adept``:
        EnableAdeptAlter) on entry, DisableAlter on exit, also when the block raises.

        Raises Rob6Error when the server refuses the mode (see ``enable_alter``: the original
        refuses it in dummy mode, and dies on kr16).
        """
        enable = self.enable_adept_alter if adept else self.enable_alter
        if not enable(timeout=timeout):
            raise Rob6Error("EnableAdeptAlter" if adept else "EnableAlter", "Alter mode refused (false)")
        try:
            yield self
        except BaseException:
            if self.connected:  # best effort: the block's exception is the one to report
                with suppress(Exception):
                    self.disable_alter(timeout=timeout)
            raise
        if self.connected:
            self.disable_alter(timeout=timeout)

    # ------------------------------------------------------------------ I/O

    def _call(self, command: Command, line: str, timeout: float | None) -> object:
        if timeout is None:
            timeout = self.move_timeout if command.long else self.timeout
        value = self._run(command.name, command.exchange(line), timeout)
        if command.reply.closes:
            self._drop()
        return value

    def _run(self, name: str, exchange: ExchangeOf[R], timeout: float) -> R:
        with self._lock:
            if self._sock is None:
                raise Rob6ConnectionError(f"{name}: the connection is closed")
            deadline = time.monotonic() + timeout
            try:
                action = next(exchange)
                while True:
                    result: str | bool | None
                    if action is READ:
                        result = self._read_line(name, deadline, timeout)
                    elif action is MAYBE_FALSE:
                        result = self._maybe_false()
                    elif isinstance(action, Send):
                        self._send(name, action.line)
                        result = None
                    elif isinstance(action, Pause):
                        time.sleep(action.seconds)
                        result = None
                    action = exchange.send(result)
            except StopIteration as stop:
                value: R = stop.value
                return value
            except Rob6Error:
                raise  # the whole reply was read: the connection is in step
            except BaseException:
                self._drop()  # timeout, EOF, garbage, Ctrl-C: replies no longer match commands
                raise

    def _send(self, name: str, line: str) -> None:
        assert self._sock is not None  # connected: _run checked
        try:
            self._sock.sendall(line.encode("latin-1") + b"\n")
        except OSError as exc:
            raise Rob6ConnectionError(f"{name}: sending failed: {exc}") from exc

    def _read_line(self, name: str, deadline: float, timeout: float) -> str:
        while (end := self._buffer.find(b"\n")) < 0:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not self._receive(remaining):
                raise Rob6Timeout(f"{name}: no complete reply within {timeout:g} s; connection closed")
        line = bytes(self._buffer[:end])
        del self._buffer[:end + 1]
        return line.decode("latin-1")

    def _maybe_false(self) -> bool:
        deadline = time.monotonic() + MAYBE_FALSE_GRACE_S
        while b"\n" not in self._buffer:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not self._receive(remaining):
                return False
        if self._buffer.startswith(b"false\n"):
            del self._buffer[:6]
            return True
        return False

    def _receive(self, timeout: float) -> bool:
        """Append what arrives within ``timeout`` to the buffer; False when nothing did."""
        assert self._sock is not None  # connected: _run checked
        self._sock.settimeout(timeout)
        try:
            chunk = self._sock.recv(65536)
        except TimeoutError:
            return False
        except OSError as exc:
            raise Rob6ConnectionError(f"connection lost: {exc}") from exc
        if not chunk:
            raise Rob6ConnectionError("the server closed the connection")
        self._buffer += chunk
        return True

    def _drop(self) -> None:
        sock, self._sock = self._sock, None
        self._buffer.clear()
        if sock is not None:
            sock.close()
