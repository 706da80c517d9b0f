"""A raw TCP client of the gateway's legacy line protocol, for the tests and the benchmarks.

It reads exactly the lines asked for (``ask``, ``read_lines``) or whatever comes until the
line goes quiet (``read_quiet``); the handshake (greeting, ``Hello Robot``) by default.
"""

from __future__ import annotations

import socket
import time

__all__ = ["Client", "connect"]


class Client:
    """A raw TCP client of the gateway."""

    def __init__(self, port: int, *, host: str = "127.0.0.1", handshake: bool = True, timeout: float = 10.0) -> None:
        self.sock = socket.create_connection((host, port), timeout=timeout)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.timeout = timeout
        self.buffer = b""
        self.greeting = self.read_lines(1)
        if handshake:
            assert self.greeting == "welcome to rob6server 0.1.01 !\n", self.greeting
            assert self.ask("Hello Robot") == "accepted\n"

    def send(self, data: bytes | str) -> None:
        self.sock.sendall(data.encode("latin-1") if isinstance(data, str) else data)

    def read_lines(self, count: int, timeout: float | None = None) -> str:
        """Exactly ``count`` lines (or what came before EOF/timeout)."""
        self.sock.settimeout(timeout or self.timeout)
        while self.buffer.count(b"\n") < count and self._receive():
            pass
        lines = self.buffer.split(b"\n")
        taken = b"".join(line + b"\n" for line in lines[:count]) if len(lines) > count else self.buffer
        self.buffer = self.buffer[len(taken):]
        return taken.decode("latin-1")

    def _receive(self) -> bool:
        """One chunk into the buffer; False at the socket's timeout or at EOF."""
        try:
            chunk = self.sock.recv(65536)
        except TimeoutError:
            return False
        if not chunk:
            return False
        self.buffer += chunk
        return True

    def read_quiet(self, quiet: float = 0.15) -> str:
        """Whatever arrives until nothing more comes for ``quiet`` seconds."""
        self.sock.settimeout(quiet)
        while self._receive():
            pass
        data, self.buffer = self.buffer, b""
        return data.decode("latin-1")

    def ask(self, command: str, lines: int = 1, timeout: float | None = None) -> str:
        self.send(command + "\n")
        return self.read_lines(lines, timeout)

    def closed(self, timeout: float = 2.0) -> bool:
        """True when the server closed the connection (EOF) within ``timeout``."""
        self.sock.settimeout(timeout)
        try:
            return self.sock.recv(1) == b""
        except TimeoutError:
            return False
        except ConnectionError:
            return True

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def connect(port: int, *, handshake: bool = True, attempts: int = 50, timeout: float = 10.0) -> Client:
    """A client of a gateway that may not be listening yet, or busy: it retries as a lab
    client does (a container's health check holds the one client slot for a few ms)."""
    for _ in range(attempts):
        try:
            client = Client(port, handshake=False, timeout=timeout)
        except OSError:
            time.sleep(0.2)  # not listening yet: the container is starting
            continue
        if client.greeting.startswith("ERROR: server busy"):
            client.close()
            time.sleep(0.1)  # the slot is taken for a moment: a retry, as a lab client does
            continue
        assert client.greeting == "welcome to rob6server 0.1.01 !\n", client.greeting
        if handshake:
            assert client.ask("Hello Robot") == "accepted\n"
        return client
    raise AssertionError(f"cannot connect to the gateway on port {port}")
