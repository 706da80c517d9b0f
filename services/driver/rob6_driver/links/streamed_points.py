"""The base of the links that stream acknowledged points over TCP (simple_message, kawasaki).

What the simple_message (Adept) and kawasaki links share; their wire is left to subclasses.

The clock is the driver's own: every ``core.dt`` the motion core steps, and while the
robot moves its setpoint becomes one point each time the plan has run ``period_s`` (whole
cycles; longer when the core is slowed), with the time since the previous point as its
duration; the last point of a motion is final.
Each point waits for its answer before the next goes out; points made meanwhile are
merged into one (the newest position, durations summed; ``late`` counts them), but never
into a segment longer than what the core moves at its full speed in ``MAX_SEGMENT_PERIODS``
periods: what a controller has taken runs out even after a stop, so no segment may be long.
A link may also bound segments in degrees per joint (``max_segment_deg``), whatever speed
limits a client set: a point then goes no farther than its share of that bound (the cycle's
move split along its line when the core runs fast), and points merge only within it.

Pacing: a controller that answers only when its arm is ready for more (the Adept's V+
program reads the next point when its previous MOVE has begun) holds rob6 back by its
answers. The link measures how long its stream has been waiting for the controller
(``ahead_s``: the age of the oldest point not yet answered, plus what the controller says
it still holds beyond its design lead, ``_held_s`` and ``pace_lead_s``) and slows the
motion core (``core.set_feed``, time scaling along the same path) from full pace at
``PACE_FULL_PERIODS`` to a halt at ``PACE_HALT_PERIODS``: the arm and rob6's setpoints
stay together, whatever speed the arm runs at.

The base keeps the controller's health: offline (``core.offline``) while a connection
is down or the controller reports a fault, back online (``core.online`` at the robot's
actual position) once connected, the state clear and the robot at rest (two state
messages after the fault, the same position in both). It checks arrival (``settle``),
cuts a stream the robot went offline in (a stop request when points are outstanding),
keeps a connection up (reconnecting every ``retry_s``) and reports events.

A subclass supplies the wire: the connections and their messages, the controller's
joint ranges and what its state says (``_link_up``, ``_sending_up``, ``_controller_fault``,
``_controller_moving``, ``_outside_range``) and, optionally, the stream's extras
(``_on_open``, ``_resting``, ``_number``, ``_on_resync``, ``_controller_missed``,
``_close_extra``), and what it knows of the points the controller has taken but its arm
has not run (``_held_s``, with ``pace_lead_s`` of them held by design). A subclass takes
the next point to send from ``_merge`` and reports its answer with ``_answered``.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import math
import queue
import socket
import threading
import time
from abc import abstractmethod
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, TypedDict, Unpack

import numpy as np
import numpy.typing as npt

from rob6.messages import LinkEvent, LinkStatus
from rob6.robots import RobotModel

from ..loop import CycleRunner
from ..motion import CoreState, MotionCore
from . import Link, Publish
from .streaming import endpoint_name, quantile

log = logging.getLogger("rob6.driver")

Joints = npt.NDArray[np.float64]

ACK_TIMEOUT_S = 2.0
STATE_TIMEOUT_S = 1.0
RETRY_S = 0.5
CONNECT_TIMEOUT_S = 2.0
#: a motion fails when the robot has not moved for this long before arriving
NO_PROGRESS_S = 2.0
#: ... or has not arrived this long after rob6's trajectory ended, or after it last came nearer
SETTLE_MAX_S = 4.0
#: ... and in any case this long after
SETTLE_CAP_S = 60.0
#: a longer wait is told to the caller when it has grown by this much
REANNOUNCE_S = 0.5
#: a position that changes less than this between state messages stands still (deg)
REST_TOL_DEG = 1e-3
STOP_WAIT_S = 0.5
LATENCY_WINDOW = 10000
#: the longest segment one point may span: what the core moves at its full speed in this
#: many periods (points merged while answers are late)
MAX_SEGMENT_PERIODS = 2
#: pacing: full pace while the stream has waited for the controller at most this many
#: periods, then slower, to a halt at the second
PACE_FULL_PERIODS = 1.5
PACE_HALT_PERIODS = 4.0


class StreamSettings(Protocol):
    """What the base reads of a link's settings."""

    @property
    def period_s(self) -> float: ...


class Timeouts(TypedDict, total=False):
    """How long a link waits, seconds (the defaults above): for an acknowledgement, a state
    message, the next connection attempt, the robot to move on and to arrive."""

    ack_timeout_s: float
    state_timeout_s: float
    retry_s: float
    no_progress_s: float
    settle_max_s: float


def check_address(prefix: str, host: str, *ports: tuple[str, int]) -> None:
    """ValueError (one line, naming the setting ``<prefix>_<name>``) when the controller's
    host is empty or a port (name, number) is not a TCP port."""
    if not host.strip():
        raise ValueError(f"{prefix}_HOST is empty: give the controller's address")
    for name, port in ports:
        if not 1 <= int(port) <= 65535:
            raise ValueError(f"{prefix}_{name}={port}: expected a TCP port 1..65535")


def check_period(prefix: str, period_s: float) -> None:
    """ValueError (one line, naming ``<prefix>_PERIOD``) when the time between points cannot work."""
    if not (math.isfinite(period_s) and 0 < period_s <= 1.0):
        raise ValueError(f"{prefix}_PERIOD={period_s}: expected seconds, more than 0 and at most 1")


@dataclass
class StreamedPoint:
    """One point waiting to be sent."""

    q: Joints  # rob6 joints, deg
    duration: float  # s
    final: bool = False
    sequence: int = 0  # the wire's number, when the link numbers points as they are made
    made_t: float = 0.0  # the core's clock when it was made (s)
    span: float = 0.0  # how far it goes: seconds of the core's full speed (its duration, less when slowed)
    plan_s: float = 0.0  # the plan's seconds it covers: its duration at full feed (the core slowed: less)


class LinkDown(Exception):
    """A connection has to be given up (the message says why)."""


class StreamedPointsLink(Link):
    """The controller's health, the stream of points and the connections' upkeep."""

    #: arrival: the controller's position within this of the final setpoint (deg)
    arrival_tol_deg = 0.0
    #: the longest segment per joint in degrees (rob6 joints), None: bounded in time only
    max_segment_deg: Joints | None = None

    def __init__(self, core: MotionCore, robot: RobotModel, settings: StreamSettings, publish: Publish,
                 on_event: Callable[[LinkEvent], None] | None, waiting_reason: str,
                 **timeouts: Unpack[Timeouts]) -> None:
        self.core = core
        self.robot = robot
        self.on_event = on_event
        self.ack_timeout_s = timeouts.get("ack_timeout_s", ACK_TIMEOUT_S)
        self.state_timeout_s = timeouts.get("state_timeout_s", STATE_TIMEOUT_S)
        self.retry_s = timeouts.get("retry_s", RETRY_S)
        self.no_progress_s = timeouts.get("no_progress_s", NO_PROGRESS_S)
        self.settle_max_s = timeouts.get("settle_max_s", SETTLE_MAX_S)
        self.decimation = max(1, round(settings.period_s / core.dt))
        self.period_s = self.decimation * core.dt
        self.runner: CycleRunner[CoreState] = CycleRunner(self._cycle, core.dt, publish, name="driver-cycle")
        self._cond = threading.Condition(threading.RLock())
        # the controller, as the connections report it (guarded by _cond)
        self.state = "waiting"
        self.q_actual: list[float] | None = None
        self._state_count = 0  # state messages that carried the controller's status
        self._position: Joints | None = None
        self._previous_position: Joints | None = None
        self._ready_once = False
        self._lost = ""
        self._online = False
        self._offline_mark = 0  # state count when the link went offline
        # the stream (guarded by _cond)
        self._open = False
        self._since = 0
        self._paced = 0.0  # plan seconds the core has run since the last point (its feed, summed)
        self._span = 0.0  # ... and what it moved meanwhile, in seconds of its full speed
        self._outbox: deque[StreamedPoint] = deque()
        self._pushed_q: Joints | None = None  # the last point made
        self._taken_q: Joints | None = None  # the last point _merge gave out
        self._inflight = False
        self._stop_pending = False
        self._sent: Joints | None = None  # the last point the controller took (the subclass's joints)
        self._acked_mark = 0  # state count at the last acknowledgement
        self._inflight_made_t = 0.0  # the core's clock when the (oldest) point in flight was made
        # statistics
        self.packets = 0  # points acknowledged
        self.late = 0  # points merged into a later one (their answer came late)
        self.longest_segment_s = 0.0  # the longest segment sent, in seconds of the core's full speed
        self.refused = 0
        self.garbage = 0
        self.runs = 0  # (motion) connections made
        self._latencies: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self._closing = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._connect_errors: dict[str, str] = {}
        self._reports: queue.SimpleQueue[tuple[int, LinkEvent] | None] = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self.waiting_reason = waiting_reason
        self._reason = waiting_reason
        self.max_segment_s = MAX_SEGMENT_PERIODS * self.period_s
        #: the points the controller holds by design before its arm runs them (seconds of stream)
        self.pace_lead_s = 0.0
        core.offline(waiting_reason)

    # ------------------------------------------------------------------ the wire's hooks
    @abstractmethod
    def _link_up(self) -> bool:
        """Every connection is up (lock held)."""

    @abstractmethod
    def _sending_up(self) -> bool:
        """The connection points go out on is up (lock held)."""

    @abstractmethod
    def _controller_fault(self) -> str | None:
        """What the controller's last state reports ("" nothing), None before one came (lock held)."""

    @abstractmethod
    def _controller_moving(self) -> bool | None:
        """The controller's last state says the robot moves; None before one came (lock held)."""

    @abstractmethod
    def _outside_range(self, q: Joints) -> str:
        """Why ``q`` (rob6 joints, deg) is outside the controller's joint ranges, "" when it is not."""

    def _on_open(self) -> None:
        """A motion's stream begins (lock held)."""

    def _resting(self, q: Joints) -> None:
        """The core is at rest (or offline) at ``q`` this cycle (lock held)."""

    def _number(self, final: bool) -> int:
        """The number a new point gets (lock held); 0 when the wire numbers points when sent."""
        return 0

    def _on_resync(self, position: Joints) -> None:
        """The link went back online at ``position`` (lock held)."""

    def _controller_missed(self) -> int:
        """Cycles the controller ran without a point (as it reports them)."""
        return 0

    def _held_s(self) -> float:
        """Seconds of stream the controller has taken but its arm not yet run, as far as it
        says (lock held); 0 when its answers already wait for the arm."""
        return 0.0

    def _close_extra(self) -> None:
        """Release what the subclass holds besides the connections."""

    # ------------------------------------------------------------------ life cycle
    def _start_threads(self, loops: Sequence[tuple[Callable[[], None], str]]) -> None:
        """Start the event reporter, then the connection loops, then the cycle."""
        for target, name in loops:
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        self.runner.start()

    def stop(self) -> None:
        """Stop streaming (a stop request when points are outstanding), then close."""
        with self._cond:
            busy = self._open or bool(self._outbox) or self._inflight
            if busy and self._sending_up():
                self._outbox.clear()
                self._open = False
                self._stop_pending = True
                self._wake()
                self._cond.wait_for(lambda: not self._stop_pending and not self._inflight, STOP_WAIT_S)
        self.runner.stop()
        self._closing.set()
        self._wake()
        for thread in self._threads[1:]:  # the connection threads
            thread.join(2.0)
        self._reports.put(None)
        if self._threads:  # the event reporter
            self._threads[0].join(1.0)
        self._wake_r.close()
        self._wake_w.close()
        self._close_extra()
        log.info("driver: %s link closed: %d points acknowledged, %d merged, %d refused, %d connections",
                 self.kind, self.packets, self.late, self.refused, self.runs)

    # ------------------------------------------------------------------ status
    def _status(self, address: str, peer: str, reset: bool) -> LinkStatus:
        """The status report; ``latency_us``: point sent -> answered (p50, p99, max)."""
        with self._cond:
            values = sorted(self._latencies)
            if reset:
                self._latencies.clear()
        latency: list[float] = []
        if values:
            latency = [round(quantile(values, 0.50) * 1e6, 1), round(quantile(values, 0.99) * 1e6, 1),
                       round(values[-1] * 1e6, 1)]
        return LinkStatus(link=self.kind, state=self.state, address=address, peer=peer,
                          packets=self.packets, late=self.late, missed=self.missed, runs=self.runs,
                          garbage=self.garbage, latency_us=latency)

    # ------------------------------------------------------------------ arrival
    @property
    def settle_bound_s(self) -> float:
        return self.settle_max_s + self.ack_timeout_s  # stopped short, or the last points never taken

    def settle(self, q_final: npt.ArrayLike, timeout: float | None = None,
               waiting: Callable[[float, str], None] | None = None) -> str:
        """Wait until the robot has arrived at ``q_final`` (deg); "" or why it did not. While
        the controller says its arm still comes nearer (its queue of slowed segments: a low
        monitor speed), the wait goes on ``settle_max_s`` from its latest step nearer, up to
        ``SETTLE_CAP_S``, and ``waiting`` is told the new bound."""
        target = np.asarray(q_final, float)
        began = time.monotonic()
        deadline = began + (self.settle_max_s if timeout is None else timeout)
        with self._cond:
            moved_at: float | None = None
            last: Joints | None = None
            nearest = math.inf  # the least error so far
            while True:
                if not self._online:
                    return self._reason or self.core.offline_reason or "the robot went offline"
                now = time.monotonic()
                drained = not (self._open or self._outbox or self._inflight or self._stop_pending)
                position, moving = self._position, self._controller_moving()
                if drained and position is not None and moving is not None:
                    error = np.abs(position - target)
                    if (self._state_count >= self._acked_mark + 2 and error.max() <= self.arrival_tol_deg
                            and not moving):
                        return ""
                    if moving and timeout is None and error.max() < nearest - REST_TOL_DEG:
                        nearest = float(error.max())
                        later = min(began + SETTLE_CAP_S, now + self.settle_max_s)
                        if later >= deadline + REANNOUNCE_S and waiting is not None:
                            waiting(later - now + self.ack_timeout_s, "waiting for the robot to arrive")
                        deadline = max(deadline, later)
                    if moved_at is None or last is None or np.abs(position - last).max() > REST_TOL_DEG:
                        moved_at, last = now, position
                    # still, and the controller says so (a slow final approach, at a low monitor
                    # speed, moves less than REST_TOL_DEG a state), or out of time
                    if (now - moved_at > self.no_progress_s and not moving) or now > deadline:
                        j = int(np.argmax(error))
                        reason = (f"robot stopped short of the target (joint {j + 1} at {position[j]:.3f}, "
                                  f"target {target[j]:.3f})")
                        self._evaluate(reason)
                        return reason
                elif moving and timeout is None:  # points still out, the arm running them (slowly)
                    deadline = max(deadline, min(began + SETTLE_CAP_S, now + self.settle_max_s))
                elif now > deadline + self.ack_timeout_s:
                    reason = "the robot did not take the motion's last points in time"
                    self._evaluate(reason)
                    return reason
                self._cond.wait(0.02)

    # ------------------------------------------------------------------ the cycle
    def _cycle(self) -> CoreState:
        with self._cond:
            state = self.core.step()
            self._stream(state)
            self.core.set_feed(self._pace())
        # cycles the runner skipped (the machine was too busy), and the controller's own
        self.missed = self.runner.stats.missed + self._controller_missed()
        return state

    def _stream(self, state: CoreState) -> None:
        """Turn the core's setpoints into points (lock held)."""
        if not self._online:
            self._resting(state.q)
            return
        if state.moving:
            if not self._open:
                self._open = True
                self._since = 0
                self._paced = self._span = 0.0
                self._on_open()
            self._since += 1
            self._paced += self.core.feed * self.core.dt
            self._span += self.core.speed_share() * self.core.dt
            # a period of the plan (slowed, the points come less often), or as far as it goes in one
            if max(self._paced, self._span) >= self.period_s - 1e-9:
                self._push(state.q, self._since * self.core.dt)
                self._since = 0
        else:
            if self._open:
                self._open = False
                self._span += self.core.speed_share() * self.core.dt
                self._paced += self.core.feed * self.core.dt
                self._push(state.q, max(self._since, 1) * self.core.dt, final=True)
            self._resting(state.q)

    def _push(self, q: Joints, duration: float, final: bool = False) -> None:
        """A point to ``q``; with ``max_segment_deg``, split along the line from the last
        point into pieces of at most ``max_segment_deg / MAX_SEGMENT_PERIODS`` per joint."""
        last, bound = self._pushed_q, self.max_segment_deg
        pieces = 1
        if bound is not None and last is not None:
            pieces = max(1, math.ceil(float(np.max(np.abs(q - last) / (bound / MAX_SEGMENT_PERIODS))) - 1e-9))
        span, paced = self._span / pieces, self._paced / pieces
        for k in range(1, pieces + 1):
            at = q if k == pieces or last is None else last + (q - last) * (k / pieces)
            self._span, self._paced = span, paced
            self._push_one(at, duration / pieces, final and k == pieces)

    def _push_one(self, q: Joints, duration: float, final: bool) -> None:
        why = self._outside_range(q)
        if why:  # the core's limits allow more than the controller: never send it
            self._evaluate(f"refused to send a point outside the robot's range ({why})")
            return
        self._outbox.append(StreamedPoint(np.array(q, float), float(duration), final, self._number(final),
                                          self.core.t, self._span, self._paced))
        self._pushed_q = self._outbox[-1].q
        self._paced = self._span = 0.0
        self._wake()

    def _merge(self) -> tuple[StreamedPoint, float, float]:
        """The points waiting since the last answer, up to a final one, as one, never going
        further than the core's full speed in ``max_segment_s``: the last of them, their summed
        duration and their summed plan seconds (what a controller that times its segments, and
        scales them by its monitor speed, must be given: the core's own slowing is already
        the arm's pace) (lock held, the outbox not empty). It is in flight from now on."""
        merged = [self._outbox.popleft()]
        span = merged[0].span
        start = merged[0].q if self._taken_q is None else self._taken_q
        while self._outbox and not merged[-1].final and span + self._outbox[0].span <= self.max_segment_s + 1e-9:
            if self.max_segment_deg is not None and np.any(
                    np.abs(self._outbox[0].q - start) > self.max_segment_deg + 1e-9):
                break
            p = self._outbox.popleft()
            merged.append(p)
            span += p.span
        self._taken_q = merged[-1].q
        self.late += len(merged) - 1
        self.longest_segment_s = max(self.longest_segment_s, span)
        self._inflight = True
        self._inflight_made_t = merged[0].made_t
        return merged[-1], sum(p.duration for p in merged), sum(p.plan_s for p in merged)

    def ahead_s(self) -> float:
        """How long rob6's stream has been waiting for the controller, seconds of the core's
        clock (lock held): the age of the oldest point it has not taken, plus what it says it
        holds beyond its design lead."""
        if self._inflight:
            oldest = self._inflight_made_t
        elif self._outbox:
            oldest = self._outbox[0].made_t
        else:
            oldest = self.core.t
        return max(0.0, self.core.t - oldest) + max(0.0, self._held_s() - self.pace_lead_s)

    def _pace(self) -> float:
        """The feed for the core (lock held): 1 up to ``PACE_FULL_PERIODS`` ahead, 0 at
        ``PACE_HALT_PERIODS``, linear between."""
        ahead = self.ahead_s() / self.period_s
        return min(1.0, max(0.0, (PACE_HALT_PERIODS - ahead) / (PACE_HALT_PERIODS - PACE_FULL_PERIODS)))

    # ------------------------------------------------------------------ health
    def _fault(self) -> str:
        """Why the robot cannot move right now ("" when it can), lock held."""
        fault = self._controller_fault() if self._position is not None else None
        if fault:  # the controller's own word first: a connection it closed may be its consequence
            return fault
        if fault is None or not self._link_up():
            if not self._ready_once:
                return self.waiting_reason
            return f"{self.kind} link lost: {self._lost or 'reconnecting'}"
        return fault

    def _at_rest(self) -> bool:
        """Two state messages since the fault, the latest at rest and where the one before was."""
        moving = self._controller_moving()
        if moving is None or self._position is None or self._previous_position is None:
            return False
        if self._state_count < self._offline_mark + 2 or moving:
            return False
        return bool(np.abs(self._position - self._previous_position).max() <= REST_TOL_DEG)

    def _evaluate(self, hiccup: str = "") -> None:
        """Take the robot offline, or back online at rest (lock taken). ``hiccup``: a
        failure of the current motion that ends it like a fault, cleared at the resync."""
        with self._cond:
            fault = self._fault()
            # waiting: never ready yet; connected: all connections up (the robot may report a fault); lost
            self.state = ("connected" if self._link_up() else "lost") if self._ready_once else "waiting"
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
                        event = "lost" if fault.startswith(f"{self.kind} link lost") else "fault"
                        self._report(event, f"driver: {reason}", logging.WARNING if event == "lost" else logging.ERROR)
            elif not self._online and self._at_rest():
                position = self._position
                assert position is not None  # at rest: a position was read
                back = self._reason
                self._online = self._ready_once = True
                self.state = "connected"
                self._reason = ""
                self._sent = None
                self._pushed_q = self._taken_q = None
                self._on_resync(position)
                self.core.online(position, reason="resynchronized with the robot")
                pose = " ".join(f"{x:.3f}" for x in position)
                if back == self.waiting_reason:
                    self._report("connected", f"driver: {self.kind} link up: the robot is at {pose}", logging.WARNING)
                else:
                    self._report("back", f"driver: the robot is ready again (before: {back}); continuing from "
                                 f"its actual position {pose}", logging.WARNING)
            self._cond.notify_all()

    def _cut_stream(self) -> None:
        """The robot went offline: drop what was not sent; stop what was (lock held)."""
        outstanding = self._open or bool(self._outbox) or self._inflight
        self._outbox.clear()
        self._open = False
        self._pushed_q = self._taken_q = None
        if outstanding and self._sending_up():
            self._stop_pending = True
            self._wake()

    def _answered(self, latency: float) -> None:
        """The request in flight got its answer after ``latency`` seconds (lock held)."""
        self._inflight = False
        self._latencies.append(latency)
        self._cond.notify_all()

    def _refused(self) -> None:
        """The controller refused a point: nothing more of this motion goes out (lock held)."""
        self.refused += 1
        self._outbox.clear()
        self._open = False

    # ------------------------------------------------------------------ connections
    def _keep_connected(self, addr: tuple[str, int], what: str, serve: Callable[[socket.socket], str],
                        down: Callable[[str], None], up: Callable[[], None] | None = None) -> None:
        """Connect to ``addr``, ``up()``, ``serve`` the connection until it fails, ``down(why)``,
        and again every ``retry_s`` until the link closes."""
        while not self._closing.is_set():
            sock = self._connect(addr, what)
            if sock is None:
                self._closing.wait(self.retry_s)
                continue
            if up is not None:
                up()
            try:
                detail = serve(sock)
            except LinkDown as exc:
                detail = str(exc)
            finally:
                sock.close()
            if self._closing.is_set():
                break
            down(detail)
            self._closing.wait(self.retry_s)

    def _connect(self, addr: tuple[str, int], what: str) -> socket.socket | None:
        """A connection to ``addr`` (``what``: how the log names it), or None (logged once per error)."""
        where = what.format(endpoint_name(addr))
        try:
            sock = socket.create_connection(addr, timeout=CONNECT_TIMEOUT_S)
            if sock.getsockname() == sock.getpeername():
                # nothing listened on a port of the local ephemeral range and the connection
                # got it as its own port (a TCP self-connect): it would hold the port forever
                sock.close()
                raise ConnectionRefusedError(errno.ECONNREFUSED, "nothing listens there (the connection met itself)")
        except OSError as exc:
            text = exc.strerror or str(exc) or type(exc).__name__
            if self._connect_errors.get(where) != text:
                self._connect_errors[where] = text
                level = logging.WARNING if self._ready_once else logging.INFO
                log.log(level, "driver: cannot reach %s: %s; retrying every %g s", where, text, self.retry_s)
            return None
        self._connect_errors.pop(where, None)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        log.info("driver: connected to %s", where)
        return sock

    def _receive(self, sock: socket.socket, buffer: bytearray, connection: str, name: str,
                 closed_at_once: bool = False) -> None:
        """Append what ``sock`` has to ``buffer``; ``LinkDown`` when it failed or closed
        (``closed_at_once``: before a word, probably because another client is connected)."""
        try:
            data = sock.recv(4096)
        except BlockingIOError:
            return
        except ConnectionResetError:  # closed with data unread: a reset, still a close
            data = b""
        except OSError as exc:
            raise LinkDown(f"the {connection} to {name} failed: {exc.strerror or exc}") from None
        if not data:
            if closed_at_once:
                raise LinkDown(f"the controller at {name} closed the {connection} at once "
                               "(is another client connected to it?)")
            raise LinkDown(f"the controller at {name} closed the {connection}")
        buffer += data

    def _wake(self) -> None:
        with contextlib.suppress(OSError):  # full (the thread will look anyway) or closed
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
            t=time.time(), event=event, message=message.removeprefix("driver: "), link=self.kind,
            cycle=self.core.cycle, late=self.late, q_actual=self.q_actual)))
