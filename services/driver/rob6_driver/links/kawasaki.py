"""The kawasaki link: drives a Kawasaki FS03N (``kaw_fs``) through rob6's AS program pair.

The program runs on the controller (deploy/kawasaki); the link keeps two TCP connections to
its PC programs (``ROB6_KAS_HOST``): points and answers on ``ROB6_KAS_PORT``, the state on
``ROB6_KAS_STATE_PORT`` (default the next port up), in the protocol of ``kawasaki_codec.py``.

The clock is the driver's own: every ``robot.cycle_s`` (16 ms) the motion core steps,
and while the robot moves every ``period_s`` (default 48 ms, three cycles) its setpoint
becomes one point ``P`` with the plan's time since the previous point as its duration; the
last point of a motion is marked final (the arm stops exactly there; the others blend, CP
ON). Each point waits for its answer ``A`` before the next goes out; points made meanwhile
are merged into one (the newest position, durations summed; ``late`` counts them). The
controller's robot program waits for three points (or a final one) before it starts a
motion, so it runs two periods behind rob6 and a point may come up to two periods late
before the arm would run dry (an underrun). When its queue holds more than those three (its
monitor speed below 100 % stretches every segment), the base slows rob6's core
(``_held_s``, pacing by acknowledgement), so the arm and the plan stay together.

Every setpoint has passed the core's limit monitor; the link also refuses to send one
outside the controller's joint ranges (they and rob6's differ, see kawasaki_codec).

A motion returns ``true`` only when the robot has arrived: every point answered, the
controller reports it at rest and its joints are the final setpoint within
``ARRIVAL_TOL_DEG``. Otherwise, and on every fault, the motion ends with ``false`` and an
error the gateway shows as ``ERROR: driver: ...``:

* no connection yet: ``robot not connected (waiting for the Kawasaki AS program at HOST:PORT)``;
* the connection lost (closed, no state for ``state_timeout_s``, no answer for
  ``ack_timeout_s``): ``kawasaki link lost: ...``; rob6 reconnects every ``retry_s``;
* the state: ``robot reports motor power off`` (also what an E-stop shows: AS has no switch
  that tells an E-stop apart), ``robot reports teach mode``, ``robot reports controller error N``,
  ``robot program rob6_motion not running ...`` (never started, held, or stopped: the
  program answers every point "not ready" then, and the queue would never drain);
* a point refused: ``robot refused a point (code N: ...)``; the robot not at the target
  when it stopped: ``robot stopped short of the target ...``.

Motion commands meanwhile get the same error. The link resumes once connected, the state
clear and the robot at rest (two states after the fault, the same position in both): the
core continues from the robot's actual position, never from where an interrupted motion
would have been. A stream cut mid-motion is cancelled (``C``): the controller drops its
queue and the arm stops after the point under way.
"""

from __future__ import annotations

import logging
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Unpack

from rob6.messages import LinkEvent, LinkStatus
from rob6.robots import RobotModel

from ..motion import MotionCore
from . import Publish
from .kawasaki_codec import (
    ACK_CODES,
    MAX_LINE,
    MAX_SEQUENCE,
    Ack,
    Hello,
    KasError,
    State,
    cancel,
    from_controller_deg,
    outside_controller_range,
    parse,
    point,
)
from .streamed_points import Joints, LinkDown, StreamedPointsLink, Timeouts, check_address, check_period
from .streaming import endpoint_name, send_all

log = logging.getLogger("rob6.driver")

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 49200
DEFAULT_PERIOD_S = 0.048
HELLO_TIMEOUT_S = 2.0
FAULT_GRACE_S = 0.3
ARRIVAL_TOL_DEG = 0.002  # the wire carries 1e-3 deg

Message = Hello | Ack | State


@dataclass(frozen=True)
class KawasakiSettings:
    """Where the controller's PC program listens (``ROB6_KAS_*``)."""

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    period_s: float = DEFAULT_PERIOD_S
    state_port: int = 0  # 0: port + 1, where rob6.as's rob6_state listens

    @property
    def state_address_port(self) -> int:
        return self.state_port or self.port + 1

    def check(self) -> None:
        """ValueError (one line, naming the setting) when a value cannot work."""
        check_address("ROB6_KAS", self.host, ("PORT", self.port), ("STATE_PORT", self.state_address_port))
        check_period("ROB6_KAS", self.period_s)


class KawasakiLink(StreamedPointsLink):
    kind = "kawasaki"
    arrival_tol_deg = ARRIVAL_TOL_DEG

    def __init__(self, core: MotionCore, robot: RobotModel, settings: KawasakiSettings, publish: Publish,
                 on_event: Callable[[LinkEvent], None] | None = None, **timeouts: Unpack[Timeouts]) -> None:
        if not robot.is_kawa:
            raise ValueError(f"the kawasaki link drives the Kawasaki FS03N (kaw_fs), not {robot.name}")
        settings.check()
        self.settings = settings
        self.addr = (settings.host, int(settings.port))
        self.name = endpoint_name(self.addr)
        self.state_addr = (settings.host, int(settings.state_address_port))
        self.state_name = endpoint_name(self.state_addr)
        # the state connection (the connection thread's own)
        self._state_sock: socket.socket | None = None
        self._state_buffer = bytearray()
        self._state_heard = 0.0
        # the connection (guarded by _cond)
        self._up = False
        self._robot: State | None = None
        self._sequence = 0  # the wire's number of the last message sent
        self.cancels = 0
        self.underruns = 0  # as the controller last reported them
        #: points waiting in the controller's queue, as its last answer or state said (-1: not
        #: connected): how far rob6 is ahead of the arm, for pacing by acknowledgement
        self.controller_queued = -1
        self.controller_capacity = 0  # the queue's size, from the hello
        waiting = f"robot not connected (waiting for the Kawasaki AS program at {self.name})"
        super().__init__(core, robot, settings, publish, on_event, waiting, **timeouts)
        # the program starts a motion at three points (deploy/kawasaki/PROTOCOL.md): those it
        # holds by design; more is the arm falling behind (a monitor speed below 100 %)
        self.pace_lead_s = 3 * self.period_s

    def _held_s(self) -> float:
        """The points the controller's queue holds, as its last answer or state said, at a
        period each (a merged one may be longer): the stream the arm has not run yet."""
        return max(self.controller_queued, 0) * self.period_s

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        self._report("waiting", f"driver: waiting for the robot: the Kawasaki AS program at {self.name}",
                     logging.WARNING)
        self._start_threads(((self._report_loop, "driver-kas-events"), (self._connection_loop, "driver-kas")))

    # ------------------------------------------------------------------ status
    def status(self, reset: bool = False) -> LinkStatus:
        """``address``: the controller's port; ``packets``: points acknowledged, ``late``: points
        merged because an answer came late, ``runs``: connections made, ``missed``: the
        controller's queue underruns plus driver cycles skipped, ``latency_us``: point
        sent -> answered (p50, p99, max)."""
        return self._status(self.name, self.name, reset)

    # ------------------------------------------------------------------ the wire's hooks
    def _link_up(self) -> bool:
        return self._up

    def _sending_up(self) -> bool:
        return self._up

    def _controller_fault(self) -> str | None:
        st = self._robot
        if st is None:
            return None
        if st.teach:
            return "robot reports teach mode"
        if not st.motor:
            return "robot reports motor power off"
        if st.error:
            return f"robot reports controller error {st.error}"
        if not st.running:
            return ("robot program rob6_motion not running (start it: EXECUTE rob6_motion, "
                    "or CONTINUE after a HOLD)")
        return ""

    def _controller_moving(self) -> bool | None:
        if self._robot is None:
            return None
        return self._robot.moving or self._robot.queued != 0

    def _outside_range(self, q: Joints) -> str:
        return outside_controller_range(q)

    def _controller_missed(self) -> int:
        return self.underruns

    # ------------------------------------------------------------------ the connection
    def _connection_loop(self) -> None:
        self._keep_connected(self.addr, "the Kawasaki AS program at {}", self._serve, self._down)

    def _down(self, detail: str) -> None:
        with self._cond:
            self._up = False
            self._inflight = False
            self._stop_pending = False
            self._robot = None
            self.controller_queued = -1
            self._lost = detail
            self._evaluate()

    def _serve(self, sock: socket.socket) -> str:
        buffer = bytearray()
        sock.setblocking(False)
        hello = self._await(sock, buffer, Hello, HELLO_TIMEOUT_S, "no hello")
        assert isinstance(hello, Hello)
        try:
            state = socket.create_connection(self.state_addr, timeout=HELLO_TIMEOUT_S)
        except OSError as exc:
            raise LinkDown(f"no state connection to {self.state_name}: {exc.strerror or exc}") from None
        state.setblocking(False)
        self._state_sock, self._state_buffer = state, bytearray()
        self._state_heard = time.monotonic()
        try:
            return self._serve_points(sock, buffer, hello)
        finally:
            self._state_sock = None
            state.close()

    def _select(self, sock: socket.socket, timeout: float, *more: socket.socket) -> list[socket.socket]:
        """Wait up to ``timeout`` for ``sock`` (or ``more``); the state connection's lines are
        taken in meanwhile. The readable ones of ``sock`` and ``more``."""
        watch = [sock, *more] + ([self._state_sock] if self._state_sock is not None else [])
        readable, _, _ = select.select(watch, [], [], timeout)
        if self._state_sock is not None and self._state_sock in readable:
            self._receive(self._state_sock, self._state_buffer, "state connection", self.state_name)
            for message in self._messages(self._state_buffer, name=self.state_name):
                if not isinstance(message, State):
                    raise LinkDown(f"a message other than a state on the state connection to {self.state_name}")
                self._state_heard = time.monotonic()
        return [s for s in readable if s is not self._state_sock]

    def _serve_points(self, sock: socket.socket, buffer: bytearray, hello: Hello) -> str:
        with self._cond:
            self._up = True
            self._inflight = False
            self._stop_pending = False
            self._sequence = 0
            self._robot = self._position = self._previous_position = None
            self.controller_capacity = hello.capacity
            self.controller_queued = 0
            self.runs += 1
            self._evaluate()
        while not self._closing.is_set():
            with self._cond:
                request = self._next_request()
            if request is None:
                readable = self._select(sock, 0.1, self._wake_r)
                if self._wake_r in readable:
                    self._drain_wake()
                if sock in readable:
                    self._receive(sock, buffer, "connection", self.name)
                    for message in self._messages(buffer):
                        if isinstance(message, Ack):
                            self._garbage(f"driver: an unasked answer for point {message.sequence}")
                if time.monotonic() - self._state_heard > self.state_timeout_s:
                    ms = round(self.state_timeout_s * 1000)
                    raise LinkDown(f"no state message from the controller at {self.state_name} for {ms} ms")
                continue
            frame, sequence, q, is_cancel = request
            sent = time.perf_counter()
            try:
                send_all(sock, frame, self.ack_timeout_s)
            except OSError as exc:
                raise LinkDown(f"sending to the controller at {self.name} failed: {exc.strerror or exc}") from None
            ack = self._await(sock, buffer, Ack, self.ack_timeout_s, "no acknowledgement", sequence)
            assert isinstance(ack, Ack)
            self._on_ack(sock, buffer, ack, q, is_cancel, time.perf_counter() - sent)
        return "closing"

    def _next_request(self) -> tuple[bytes, int, Joints | None, bool] | None:
        """(frame, sequence, rob6 joints, is_cancel) of the next message, or None (lock held)."""
        if self._stop_pending:
            self._stop_pending = False
            self._inflight = True
            self._sequence = self._sequence % MAX_SEQUENCE + 1
            return cancel(self._sequence), self._sequence, None, True
        if not self._outbox:
            return None
        # the program times each segment (SPEED ... S) and its monitor speed stretches that time:
        # the plan's seconds, not the core's clock, or a slowed core would slow the arm twice
        last, _, plan_s = self._merge()
        self._sequence = self._sequence % MAX_SEQUENCE + 1
        return point(self._sequence, last.q, plan_s, last.final), self._sequence, last.q, False

    def _await(self, sock: socket.socket, buffer: bytearray, kind: type[Hello] | type[Ack], timeout: float,
               what: str, sequence: int | None = None) -> Message:
        """The next message of ``kind`` (the answer to ``sequence``), states handled meanwhile."""
        deadline = time.monotonic() + timeout
        while True:
            for message in self._messages(buffer, until=kind):
                if isinstance(message, kind):
                    if isinstance(message, Ack) and message.sequence != sequence:
                        raise LinkDown(f"the controller at {self.name} answered point {message.sequence}, "
                                       f"expected {sequence}")
                    return message
            remaining = deadline - time.monotonic()
            if self._closing.is_set():
                raise LinkDown("closing")
            if remaining <= 0:
                ms = round(timeout * 1000)
                extra = " (is it rob6's AS program?)" if kind is Hello else ""
                raise LinkDown(f"{what} from the controller at {self.name} for {ms} ms{extra}")
            if self._select(sock, min(remaining, 0.1)):
                self._receive(sock, buffer, "connection", self.name)

    def _messages(self, buffer: bytearray, until: type[Hello] | type[Ack] | None = None,
                  name: str = "") -> list[Message]:
        """Parse the complete lines in ``buffer``; states are taken in at once. Stops after
        the first message of type ``until`` (the rest stays in the buffer)."""
        name = name or self.name
        out: list[Message] = []
        while True:
            end = buffer.find(b"\n")
            if end < 0:
                if len(buffer) > MAX_LINE:
                    raise LinkDown(f"unreadable data from the controller at {name} "
                                   f"(no line end in {len(buffer)} bytes)")
                return out
            line = bytes(buffer[:end])
            del buffer[:end + 1]
            try:
                message = parse(line)
            except KasError as exc:
                self._garbage(f"driver: unreadable message from {name}: {exc}")
                raise LinkDown(f"unreadable message from the controller at {name} ({exc})") from None
            if isinstance(message, State):
                self._on_state(message)
            out.append(message)
            if until is not None and isinstance(message, until):
                return out

    def _on_state(self, st: State) -> None:
        q = from_controller_deg(st.joints)
        with self._cond:
            self._previous_position = self._position
            self._position = q
            self.q_actual = q.tolist()
            self._robot = st
            self._state_count += 1
            self.underruns = st.underruns
            self.controller_queued = st.queued
            self._evaluate()

    def _on_ack(self, sock: socket.socket, buffer: bytearray, ack: Ack, q: Joints | None, is_cancel: bool,
                latency: float) -> None:
        with self._cond:
            self._answered(latency)
            self.controller_queued = ack.queued
            if ack.code == 0:
                self._acked_mark = self._state_count
                if is_cancel:
                    self.cancels += 1
                    self._sent = None
                    self._report("stop_sent", "driver: cancel acknowledged by the controller", logging.INFO)
                else:
                    self.packets += 1
                    self._sent = q
                return
            self._refused()
        self._read_for_fault(sock, buffer)
        meaning = ACK_CODES.get(ack.code, "unknown code")
        with self._cond:
            self._report("refused", f"driver: the controller refused a point (code {ack.code}: {meaning})",
                         logging.WARNING)
            self._evaluate("" if is_cancel else f"robot refused a point (code {ack.code}: {meaning})")

    def _read_for_fault(self, sock: socket.socket, buffer: bytearray) -> None:
        """A refused point: read the states of the next moment, they may say why (an
        E-stop is the better error than its consequence)."""
        deadline = time.monotonic() + FAULT_GRACE_S
        while (remaining := deadline - time.monotonic()) > 0:
            with self._cond:
                if self._fault():
                    return
            for message in self._messages(buffer):
                if isinstance(message, Ack):
                    self._garbage(f"driver: an unasked answer for point {message.sequence}")
            if self._select(sock, min(remaining, 0.05)):
                self._receive(sock, buffer, "connection", self.name)
