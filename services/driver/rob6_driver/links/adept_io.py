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

``SIGNAL`` of an output the controller has not installed is a V+ error, and ``ros.io`` has
no handler: its task ends for good (nothing restarts it; ``a.ros()`` again does). So only
the outputs the lab lists as installed (``ROB6_SM_OUTPUTS``, ``parse_outputs``) are sent.
"""

from __future__ import annotations

import socket
import struct
import threading
import time

from rob6.errors import LinkError
from rob6.vplus import OUTPUTS, SOFT_SIGNALS

#: the outputs a controller has without saying: a SmartController's XDIO outputs, and the
#: software signals every V+ system has (rob6.vplus)
DEFAULT_OUTPUTS = "1-8,2001-2512"
#: the mode rob6 sends: any value but 1 (read) makes the program write
WRITE_MODE = 2
#: between the mode and the number: two records for the program's two READs
GAP_S = 0.1
ANSWER_TIMEOUT_S = 2.0
CONNECT_TIMEOUT_S = 2.0
_INT32 = struct.Struct(">i")


def parse_outputs(text: str) -> tuple[range, ...]:
    """The installed outputs from ``ROB6_SM_OUTPUTS`` ("1-8,97-104,2001-2512"); ValueError
    (one line) for anything but ranges of V+ outputs (1-512) and software signals (2001-2512)."""
    out = []
    for part in text.replace(" ", "").split(","):
        first, dash, last = part.partition("-")
        if not first.isdigit() or (dash and not last.isdigit()):
            raise ValueError(f"ROB6_SM_OUTPUTS={text!r}: expected ranges of signal numbers like 1-8,2001-2512")
        numbers = range(int(first), int(last if dash else first) + 1)
        if not numbers or not any(numbers[0] in r and numbers[-1] in r for r in (OUTPUTS, SOFT_SIGNALS)):
            raise ValueError(f"ROB6_SM_OUTPUTS={text!r}: {part} is not a range of V+ outputs "
                             f"({OUTPUTS.start}-{OUTPUTS.stop - 1}) or software signals "
                             f"({SOFT_SIGNALS.start}-{SOFT_SIGNALS.stop - 1})")
        out.append(numbers)
    return tuple(out)


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
        if answer.strip() != b"1":  # "/N": no line end; whitespace around it would change nothing
            self._close()  # whatever it was, the next request starts on a fresh connection
            raise IoPortError(f"the controller at {self.name} answered {answer.decode('latin-1')!r} to "
                              f"SIGNAL {signal} instead of '1'")

    def _answer(self, sock: socket.socket) -> bytes:
        sock.settimeout(self.answer_timeout_s)
        try:
            answer = sock.recv(64)
        except TimeoutError:
            ms = round(self.answer_timeout_s * 1000)
            raise IoPortError(f"no answer from the controller's I/O port {self.name} within {ms} ms (has its "
                              "I/O task ended? a.ros() starts it again)") from None
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
