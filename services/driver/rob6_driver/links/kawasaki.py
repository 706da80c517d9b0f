"""The kawasaki link: drives a Kawasaki FS03N (``kaw_fs``) through rob6's AS program pair on
the controller (deploy/kawasaki), one TCP connection to its PC program (``ROB6_KAS_HOST``,
``ROB6_KAS_PORT``), in the protocol of ``kawasaki_codec.py``.

The clock is the driver's own: every ``robot.cycle_s`` (16 ms) the motion core steps,
and while the robot moves every ``period_s`` (default 48 ms, three cycles) its setpoint
becomes one point ``P`` with the time since the previous point as its duration; the last
point of a motion is marked final (the arm stops exactly there; the others blend, CP ON).
Each point waits for its answer ``A`` before the next goes out; points made meanwhile are
merged into one (the newest position, durations summed; ``late`` counts them). The
controller's robot program waits for three points (or a final one) before it starts a
motion, so it runs two periods behind rob6 and a point may come up to two periods late
before the arm would run dry (an underrun).

Every setpoint has passed the core's limit monitor; the link also refuses to send one
outside the controller's joint ranges (they and rob6's differ, see kawasaki_codec).

A motion returns ``true`` only when the robot has arrived: every point answered, the
controller reports it at rest and its joints are the final setpoint within
``ARRIVAL_TOL_DEG``. Otherwise, and on every fault, the motion ends with ``false`` and an
error the gateway shows as ``ERROR: driver: ...``:

* no connection yet: ``robot not connected (waiting for the Kawasaki AS program at HOST:PORT)``;
* the connection lost (closed, no state for ``state_timeout_s``, no answer for
  ``ack_timeout_s``): ``kawasaki link lost: ...``; rob6 reconnects every ``retry_s``;
* the state: ``robot reports an E-stop``, ``robot reports motor power off``,
  ``robot reports teach mode``, ``robot reports controller error N``;
* a point refused: ``robot refused a point (code N: ...)``; the robot not at the target
  when it stopped: ``robot stopped short of the target ...``.

Motion commands meanwhile get the same error. The link resumes once connected, the state
clear and the robot at rest (two states after the fault, the same position in both): the
core continues from the robot's actual position, never from where an interrupted motion
would have been. A stream cut mid-motion is cancelled (``C``): the controller drops its
queue and the arm stops after the point under way.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import select
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rob6.messages import LinkEvent, LinkStatus
from rob6.robots import RobotModel

from ..loop import CycleRunner
from ..motion import MotionCore
from . import Link, Publish
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
from .streaming import endpoint_name, quantile, send_all

log = logging.getLogger("rob6.driver")

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 49200
DEFAULT_PERIOD_S = 0.048
ACK_TIMEOUT_S = 2.0
STATE_TIMEOUT_S = 1.0
HELLO_TIMEOUT_S = 2.0
RETRY_S = 0.5
CONNECT_TIMEOUT_S = 2.0
FAULT_GRACE_S = 0.3
ARRIVAL_TOL_DEG = 0.002  # the wire carries 1e-3 deg
REST_TOL_DEG = 1e-3
NO_PROGRESS_S = 2.0
SETTLE_MAX_S = 4.0
STOP_WAIT_S = 0.5
LATENCY_WINDOW = 10000


@dataclass(frozen=True)
class KawasakiSettings:
    """Where the controller's PC program listens (``ROB6_KAS_*``)."""

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    period_s: float = DEFAULT_PERIOD_S

    def check(self) -> None:
        """ValueError (one line, naming the setting) when a value cannot work."""
        if not self.host.strip():
            raise ValueError("ROB6_KAS_HOST is empty: give the controller's address")
        if not 1 <= int(self.port) <= 65535:
            raise ValueError(f"ROB6_KAS_PORT={self.port}: expected a TCP port 1..65535")
        if not (math.isfinite(self.period_s) and 0 < self.period_s <= 1.0):
            raise ValueError(f"ROB6_KAS_PERIOD={self.period_s}: expected seconds, more than 0 and at most 1")


@dataclass
class _Point:
    q: np.ndarray  # rob6 joints, deg
    duration: float  # s
    final: bool = False


class _Down(Exception):
    """The connection has to be given up (the message says why)."""


class KawasakiLink(Link):
    kind = "kawasaki"

    def __init__(self, core: MotionCore, robot: RobotModel, settings: KawasakiSettings, publish: Publish,
                 on_event: Callable[[LinkEvent], None] | None = None, *,
                 ack_timeout_s: float = ACK_TIMEOUT_S, state_timeout_s: float = STATE_TIMEOUT_S,
                 retry_s: float = RETRY_S, no_progress_s: float = NO_PROGRESS_S,
                 settle_max_s: float = SETTLE_MAX_S):
        if not robot.is_kawa:
            raise ValueError(f"the kawasaki link drives the Kawasaki FS03N (kaw_fs), not {robot.name}")
        settings.check()
        self.core = core
        self.robot = robot
        self.settings = settings
        self.on_event = on_event
        self.ack_timeout_s = ack_timeout_s
        self.state_timeout_s = state_timeout_s
        self.retry_s = retry_s
        self.no_progress_s = no_progress_s
        self.settle_max_s = settle_max_s
        self.decimation = max(1, round(settings.period_s / core.dt))
        self.period_s = self.decimation * core.dt
        self.addr = (settings.host, int(settings.port))
        self.name = endpoint_name(self.addr)
        self.runner = CycleRunner(self._cycle, core.dt, publish, name="driver-cycle")
        self._cond = threading.Condition(threading.RLock())
        # the controller, as the connection reports it (guarded by _cond)
        self.state = "waiting"
        self.q_actual: list[float] | None = None
        self._up = False
        self._robot: State | None = None
        self._state_count = 0
        self._position: np.ndarray | None = None
        self._previous_position: np.ndarray | None = None
        self._ready_once = False
        self._lost = ""
        self._online = False
        self._reason = ""
        self._offline_mark = 0
        # the stream (guarded by _cond)
        self._open = False
        self._since = 0
        self._sequence = 0
        self._outbox: deque[_Point] = deque()
        self._inflight = False
        self._cancel_pending = False
        self._sent_q: np.ndarray | None = None  # rob6 joints of the last point the controller took
        self._acked_mark = 0
        # statistics
        self.packets = 0  # points answered with 0
        self.late = 0  # points merged into a later one
        self.refused = 0
        self.garbage = 0
        self.runs = 0  # connections made
        self.cancels = 0
        self.underruns = 0  # as the controller last reported them
        self._latencies: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self._closing = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._connect_error = ""
        self._reports = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self.waiting_reason = f"robot not connected (waiting for the Kawasaki AS program at {self.name})"
        self._reason = self.waiting_reason
        core.offline(self.waiting_reason)

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        self._report("waiting", f"driver: waiting for the robot: the Kawasaki AS program at {self.name}",
                     logging.WARNING)
        for target, name in ((self._report_loop, "driver-kas-events"), (self._connection_loop, "driver-kas")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        self.runner.start()

    def stop(self) -> None:
        """Cancel what is queued on the controller, then close."""
        with self._cond:
            busy = self._open or bool(self._outbox) or self._inflight
            if busy and self._up:
                self._outbox.clear()
                self._open = False
                self._cancel_pending = True
                self._wake()
                self._cond.wait_for(lambda: not self._cancel_pending and not self._inflight, STOP_WAIT_S)
        self.runner.stop()
        self._closing.set()
        self._wake()
        for thread in self._threads[1:]:
            thread.join(2.0)
        self._reports.put(None)
        if self._threads:
            self._threads[0].join(1.0)
        self._wake_r.close()
        self._wake_w.close()
        log.info("driver: kawasaki link closed: %d points acknowledged, %d merged, %d refused, %d connections",
                 self.packets, self.late, self.refused, self.runs)

    # ------------------------------------------------------------------ status
    def status(self, reset: bool = False) -> LinkStatus:
        """``address``: the controller's port; ``packets``: points acknowledged, ``late``: points
        merged because an answer came late, ``runs``: connections made, ``missed``: the
        controller's queue underruns plus driver cycles skipped, ``latency_us``: point
        sent -> answered (p50, p99, max)."""
        with self._cond:
            values = sorted(self._latencies)
            if reset:
                self._latencies.clear()
        latency = []
        if values:
            latency = [round(quantile(values, 0.50) * 1e6, 1), round(quantile(values, 0.99) * 1e6, 1),
                       round(values[-1] * 1e6, 1)]
        return LinkStatus(link="kawasaki", state=self.state, address=self.name, peer=self.name,
                          packets=self.packets, late=self.late, missed=self.missed, runs=self.runs,
                          garbage=self.garbage, latency_us=latency)

    # ------------------------------------------------------------------ arrival
    @property
    def settle_bound_s(self) -> float:
        return self.settle_max_s + self.ack_timeout_s

    def settle(self, q_final, timeout: float | None = None) -> str:
        """Wait until the robot has arrived at ``q_final`` (deg); "" or why it did not."""
        target = np.asarray(q_final, float)
        deadline = time.monotonic() + (self.settle_max_s if timeout is None else timeout)
        with self._cond:
            moved_at = None
            last = None
            while True:
                if not self._online:
                    return self._reason or self.core.offline_reason or "the robot went offline"
                now = time.monotonic()
                drained = not (self._open or self._outbox or self._inflight or self._cancel_pending)
                position, robot = self._position, self._robot
                if drained and position is not None and robot is not None:
                    error = np.abs(position - target)
                    if (self._state_count >= self._acked_mark + 2 and error.max() <= ARRIVAL_TOL_DEG
                            and not robot.moving and robot.queued == 0):
                        return ""
                    if moved_at is None or last is None or np.abs(position - last).max() > REST_TOL_DEG:
                        moved_at, last = now, position
                    if now - moved_at > self.no_progress_s or now > deadline:
                        j = int(np.argmax(error))
                        reason = (f"robot stopped short of the target (joint {j + 1} at {position[j]:.3f}, "
                                  f"target {target[j]:.3f})")
                        self._evaluate(reason)
                        return reason
                elif now > deadline + self.ack_timeout_s:
                    reason = "the robot did not take the motion's last points in time"
                    self._evaluate(reason)
                    return reason
                self._cond.wait(0.02)

    # ------------------------------------------------------------------ the cycle
    def _cycle(self):
        with self._cond:
            state = self.core.step()
            self._stream(state)
        self.missed = self.runner.stats.missed + self.underruns
        return state

    def _stream(self, state) -> None:
        """Turn the core's setpoints into points (lock held)."""
        if not self._online:
            return
        if state.moving:
            if not self._open:
                self._open = True
                self._since = 0
            self._since += 1
            if self._since >= self.decimation:
                self._push(state.q, self._since * self.core.dt)
                self._since = 0
        elif self._open:
            self._open = False
            self._push(state.q, max(self._since, 1) * self.core.dt, final=True)

    def _push(self, q: np.ndarray, duration: float, final: bool = False) -> None:
        why = outside_controller_range(q)
        if why:  # rob6's limits allow more than the controller: never send it
            self._evaluate(f"refused to send a point outside the robot's range ({why})")
            return
        self._outbox.append(_Point(np.array(q, float), float(duration), final))
        self._wake()

    # ------------------------------------------------------------------ health
    def _fault(self) -> str:
        """Why the robot cannot move right now ("" when it can), lock held."""
        if not (self._up and self._robot is not None and self._position is not None):
            if not self._ready_once:
                return self.waiting_reason
            return f"kawasaki link lost: {self._lost or 'reconnecting'}"
        st = self._robot
        if st.estop:
            return "robot reports an E-stop"
        if st.teach:
            return "robot reports teach mode"
        if not st.motor:
            return "robot reports motor power off"
        if st.error:
            return f"robot reports controller error {st.error}"
        return ""

    def _at_rest(self) -> bool:
        """Two states since the fault, the latest at rest and where the one before was."""
        if self._robot is None or self._position is None or self._previous_position is None:
            return False
        if self._state_count < self._offline_mark + 2 or self._robot.moving or self._robot.queued:
            return False
        return bool(np.abs(self._position - self._previous_position).max() <= REST_TOL_DEG)

    def _evaluate(self, hiccup: str = "") -> None:
        """Take the robot offline, or back online at rest (lock taken)."""
        with self._cond:
            fault = self._fault()
            self.state = ("connected" if self._up else "lost") if self._ready_once else "waiting"
            reason = fault or hiccup
            if reason:
                if self._online or reason != self._reason:
                    was_online = self._online
                    self._online = False
                    self._offline_mark = self._state_count
                    self._cut_stream()
                    self._reason = reason
                    self.core.offline(reason)
                    if was_online or not fault.startswith("robot not connected"):
                        event = "lost" if fault.startswith("kawasaki link lost") else "fault"
                        self._report(event, f"driver: {reason}", logging.WARNING if event == "lost" else logging.ERROR)
            elif not self._online and self._at_rest():
                position = self._position
                assert position is not None
                back = self._reason
                self._online = self._ready_once = True
                self.state = "connected"
                self._reason = ""
                self._sent_q = None
                self.core.online(position, reason="resynchronized with the robot")
                pose = " ".join(f"{x:.3f}" for x in position)
                if back == self.waiting_reason:
                    self._report("connected", f"driver: kawasaki link up: the robot is at {pose}", logging.WARNING)
                else:
                    self._report("back", f"driver: the robot is ready again (before: {back}); continuing from "
                                 f"its actual position {pose}", logging.WARNING)
            self._cond.notify_all()

    def _cut_stream(self) -> None:
        """The robot went offline: drop what was not sent; cancel what was (lock held)."""
        outstanding = self._open or bool(self._outbox) or self._inflight
        self._outbox.clear()
        self._open = False
        if outstanding and self._up:
            self._cancel_pending = True
            self._wake()

    # ------------------------------------------------------------------ the connection
    def _connection_loop(self) -> None:
        while not self._closing.is_set():
            sock = self._connect()
            if sock is None:
                self._closing.wait(self.retry_s)
                continue
            try:
                detail = self._serve(sock)
            except _Down as exc:
                detail = str(exc)
            finally:
                sock.close()
            if self._closing.is_set():
                break
            with self._cond:
                self._up = False
                self._inflight = False
                self._cancel_pending = False
                self._robot = None
                self._lost = detail
                self._evaluate()
            self._closing.wait(self.retry_s)

    def _serve(self, sock: socket.socket) -> str:
        buffer = bytearray()
        sock.setblocking(False)
        hello = self._await(sock, buffer, Hello, HELLO_TIMEOUT_S, "no hello")
        assert isinstance(hello, Hello)
        with self._cond:
            self._up = True
            self._inflight = False
            self._cancel_pending = False
            self._sequence = 0
            self._robot = self._position = self._previous_position = None
            self.runs += 1
            self._evaluate()
        heard = time.monotonic()
        while not self._closing.is_set():
            with self._cond:
                request = self._next_request()
            if request is None:
                readable, _, _ = select.select([sock, self._wake_r], [], [], 0.1)
                if self._wake_r in readable:
                    self._drain_wake()
                if sock in readable:
                    self._receive(sock, buffer)
                    for message in self._messages(buffer):
                        heard = time.monotonic()
                        if isinstance(message, Ack):
                            self._garbage(f"driver: an unasked answer for point {message.sequence}")
                if time.monotonic() - heard > self.state_timeout_s:
                    ms = round(self.state_timeout_s * 1000)
                    raise _Down(f"no state message from the controller at {self.name} for {ms} ms")
                continue
            frame, sequence, q, is_cancel = request
            sent = time.perf_counter()
            try:
                send_all(sock, frame, self.ack_timeout_s)
            except OSError as exc:
                raise _Down(f"sending to the controller at {self.name} failed: {exc.strerror or exc}") from None
            ack = self._await(sock, buffer, Ack, self.ack_timeout_s, "no acknowledgement", sequence)
            assert isinstance(ack, Ack)
            heard = time.monotonic()
            self._on_ack(sock, buffer, ack, q, is_cancel, time.perf_counter() - sent)
        return "closing"

    def _next_request(self):
        """(frame, sequence, rob6 joints, is_cancel) of the next message, or None (lock held)."""
        if self._cancel_pending:
            self._cancel_pending = False
            self._inflight = True
            self._sequence = self._sequence % MAX_SEQUENCE + 1
            return cancel(self._sequence), self._sequence, None, True
        if not self._outbox:
            return None
        merged = []
        while self._outbox:
            p = self._outbox.popleft()
            merged.append(p)
            if p.final:
                break
        self.late += len(merged) - 1
        last = merged[-1]
        duration = sum(p.duration for p in merged)
        self._inflight = True
        self._sequence = self._sequence % MAX_SEQUENCE + 1
        return point(self._sequence, last.q, duration, last.final), self._sequence, last.q, False

    def _await(self, sock: socket.socket, buffer: bytearray, kind: type, timeout: float, what: str,
               sequence: int | None = None):
        """The next message of ``kind`` (the answer to ``sequence``), states handled meanwhile."""
        deadline = time.monotonic() + timeout
        while True:
            for message in self._messages(buffer, until=kind):
                if isinstance(message, kind):
                    if isinstance(message, Ack) and message.sequence != sequence:
                        raise _Down(f"the controller at {self.name} answered point {message.sequence}, "
                                    f"expected {sequence}")
                    return message
            remaining = deadline - time.monotonic()
            if self._closing.is_set():
                raise _Down("closing")
            if remaining <= 0:
                ms = round(timeout * 1000)
                extra = " (is it rob6's AS program?)" if kind is Hello else ""
                raise _Down(f"{what} from the controller at {self.name} for {ms} ms{extra}")
            readable, _, _ = select.select([sock], [], [], min(remaining, 0.1))
            if readable:
                self._receive(sock, buffer)

    def _messages(self, buffer: bytearray, until: type | None = None) -> list:
        """Parse the complete lines in ``buffer``; states are taken in at once. Stops after
        the first message of type ``until`` (the rest stays in the buffer)."""
        out: list[Hello | Ack | State] = []
        while True:
            end = buffer.find(b"\n")
            if end < 0:
                if len(buffer) > MAX_LINE:
                    raise _Down(f"unreadable data from the controller at {self.name} "
                                f"(no line end in {len(buffer)} bytes)")
                return out
            line = bytes(buffer[:end])
            del buffer[:end + 1]
            try:
                message = parse(line)
            except KasError as exc:
                self._garbage(f"driver: unreadable message from {self.name}: {exc}")
                raise _Down(f"unreadable message from the controller at {self.name} ({exc})") from None
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
            self._evaluate()

    def _on_ack(self, sock: socket.socket, buffer: bytearray, ack: Ack, q, is_cancel: bool,
                latency: float) -> None:
        with self._cond:
            self._inflight = False
            self._latencies.append(latency)
            self._cond.notify_all()
            if ack.code == 0:
                self._acked_mark = self._state_count
                if is_cancel:
                    self.cancels += 1
                    self._sent_q = None
                    self._report("stop_sent", "driver: cancel acknowledged by the controller", logging.INFO)
                else:
                    self.packets += 1
                    self._sent_q = q
                return
            self.refused += 1
            self._outbox.clear()
            self._open = False
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
            readable, _, _ = select.select([sock], [], [], min(remaining, 0.05))
            if readable:
                self._receive(sock, buffer)

    def _receive(self, sock: socket.socket, buffer: bytearray) -> None:
        try:
            data = sock.recv(4096)
        except BlockingIOError:
            return
        except ConnectionResetError:
            data = b""
        except OSError as exc:
            raise _Down(f"the connection to {self.name} failed: {exc.strerror or exc}") from None
        if not data:
            raise _Down(f"the controller at {self.name} closed the connection")
        buffer += data

    def _connect(self) -> socket.socket | None:
        try:
            sock = socket.create_connection(self.addr, timeout=CONNECT_TIMEOUT_S)
        except OSError as exc:
            text = exc.strerror or str(exc) or type(exc).__name__
            if self._connect_error != text:
                self._connect_error = text
                level = logging.WARNING if self._ready_once else logging.INFO
                log.log(level, "driver: cannot reach the Kawasaki AS program at %s: %s; retrying every %g s",
                        self.name, text, self.retry_s)
            return None
        self._connect_error = ""
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        log.info("driver: connected to the Kawasaki AS program at %s", self.name)
        return sock

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            self._wake_w.send(b"\0")

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except OSError:
            pass

    # ------------------------------------------------------------------ events
    def _garbage(self, message: str) -> None:
        self.garbage += 1
        if self.garbage <= 10 or self.garbage % 1000 == 0:
            self._report("garbage", message, logging.WARNING)

    def _report(self, event: str, message: str, level: int) -> None:
        self._reports.put((level, LinkEvent(
            t=time.time(), event=event, message=message.removeprefix("driver: "), link="kawasaki",
            cycle=self.core.cycle, late=self.late, q_actual=self.q_actual)))
