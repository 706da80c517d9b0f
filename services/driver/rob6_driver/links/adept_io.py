"""The Adept V+ server program's digital I/O port (11001): SIGNAL n for the simple_message link.

The program (``ros.io`` in ``adept_ros.v2``, deploy/adept/README.md section 4) serves up to
five clients with its own protocol, not simple_message. Per request it does two V+
``READ``s, each taking what has arrived as one record, and reads a big-endian int32 from the
first four bytes of each: the mode (1 read, anything else write), then the signal number.
A write runs ``SIGNAL (n)`` (a negative n switches off) and answers the one ASCII byte
``1``. Nothing frames the two numbers, so they must arrive as two records: like the ROS
node written for it (``adept_io_service_node.cpp``, ``socket_rate`` 10), rob6 sends the
number ``GAP_S`` after the mode.

The connection is opened on the first request and kept; a request on a kept connection
that the controller has closed meanwhile is sent again once on a new one (switching an
output twice is the same as once).
"""

from __future__ import annotations

import socket
import struct
import threading
import time

from rob6.errors import LinkError

#: the mode rob6 sends: any value but 1 (read) makes the program write
WRITE_MODE = 2
#: between the mode and the number: two records for the program's two READs
GAP_S = 0.1
ANSWER_TIMEOUT_S = 2.0
CONNECT_TIMEOUT_S = 2.0
_INT32 = struct.Struct(">i")


class IoPortError(LinkError):
    """The I/O port could not switch the signal (the text says why)."""


class _Lost(IoPortError):
    """The connection failed or was closed (a kept one may have been closed meanwhile)."""


class AdeptIoPort:
    """One client connection to the program's I/O port, used by one request at a time."""

    def __init__(self, host: str, port: int, *, gap_s: float = GAP_S,
                 answer_timeout_s: float = ANSWER_TIMEOUT_S) -> None:
        self.addr = (host, port)
        self.name = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
        self.gap_s = gap_s
        self.answer_timeout_s = answer_timeout_s
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None

    def bound_s(self, count: int) -> float:
        """The longest ``count`` writes take by this port's own timeouts: a connection,
        and for each signal the gap and the answer, once more on a new connection."""
        return CONNECT_TIMEOUT_S + count * 2 * (self.gap_s + self.answer_timeout_s)

    def write(self, signal: int) -> None:
        """``SIGNAL (signal)`` on the controller; IoPortError when it was not confirmed."""
        with self._lock:
            kept = self._sock is not None
            try:
                self._write(signal)
            except _Lost:
                if not kept:
                    raise
                self._write(signal)  # the controller may have closed the kept connection meanwhile

    def close(self) -> None:
        with self._lock:
            self._close()

    def _write(self, signal: int) -> None:
        sock = self._connection()
        try:
            sock.sendall(_INT32.pack(WRITE_MODE))
            time.sleep(self.gap_s)
            sock.sendall(_INT32.pack(signal))
            answer = self._answer(sock)
        except OSError as exc:
            self._close()
            raise _Lost(f"the I/O connection to the controller at {self.name} failed: "
                        f"{exc.strerror or exc}") from None
        except IoPortError:
            self._close()
            raise
        if answer != b"1":
            self._close()  # whatever it was, the next request starts on a fresh connection
            raise IoPortError(f"the controller at {self.name} answered {answer.decode('latin-1')!r} to "
                              f"SIGNAL {signal} instead of '1'")

    def _answer(self, sock: socket.socket) -> bytes:
        sock.settimeout(self.answer_timeout_s)
        try:
            answer = sock.recv(64)
        except TimeoutError:
            ms = round(self.answer_timeout_s * 1000)
            raise IoPortError(f"no answer from the controller's I/O port {self.name} within {ms} ms") from None
        if not answer:
            raise _Lost(f"the controller at {self.name} closed the I/O connection without an answer")
        return answer

    def _connection(self) -> socket.socket:
        if self._sock is None:
            try:
                sock = socket.create_connection(self.addr, timeout=CONNECT_TIMEOUT_S)
            except OSError as exc:
                raise IoPortError(f"cannot reach the controller's I/O port {self.name}: "
                                  f"{exc.strerror or exc}") from None
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._sock = sock
        return self._sock

    def _close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
