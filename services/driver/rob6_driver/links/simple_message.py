"""The simple_message link: drives an Adept Viper s850 (ad850) through the ROS-Industrial V+ server.

The simple_message link: drives an Adept Viper s850 (``ad850``) through the V+ server
program of the ROS-Industrial Adept packages, over ROS-Industrial simple_message.

The controller is the TCP server, rob6 the client on its ports (``ROB6_SM_HOST``):

* motion (11000): rob6 streams JOINT_TRAJ_PT service requests and waits for each
  acknowledgement before it sends the next;
* state (11002): the controller sends JOINT_POSITION and STATUS about every 0.1 s;
* I/O (11001, the program's own protocol, ``adept_io.py``): opened on the first
  ``signal`` (DirectAdeptCmd signal 5, -6), which switches digital outputs.

The clock is the driver's own (like the simulation): every ``robot.cycle_s`` (16 ms) the
motion core steps, and while the robot moves every ``period_s`` (default 48 ms, three
cycles) its setpoint becomes one point, with the time since the previous point as its
``duration`` and the speed that implies as ``velocity`` (fraction of the rated joint
speeds). Every setpoint has passed the core's limit monitor; the link also refuses to
send one outside the controller's joint ranges. A motion's stream

* starts with a *hold point*: the position the robot rests at, lasting one period plus
  a lead (one more period). A controller that honours durations thus runs one lead
  behind rob6, so the next point is always there before the previous one is played out
  (no underrun, however the machine's timing jitters up to a lead);
* ends with the final setpoint as sequence -3 (END_TRAJECTORY) once the core is at rest.

When an acknowledgement comes late the points produced meanwhile are merged into one
(the newest position, the durations summed: the timing is kept; ``late`` counts them).

The Adept's V+ program ignores velocity and duration (``SPEED 100 ALWAYS``): the arm
runs each point at the pendant's monitor speed, one point ahead of the program. It
acknowledges every point at once with code 1 and reports no errors in STATUS (only
drives, E-stop and motion); the simulator ``adept-sm-sim`` can do both ways.

A motion returns ``true`` only when the robot has arrived: all points acknowledged,
the controller reports it at rest, and its JOINT_POSITION is the final setpoint within
``ARRIVAL_TOL_DEG``. Otherwise, and on every fault, the motion ends with ``false`` and an
error the gateway shows as ``ERROR: driver: ...``:

* no connection yet: ``robot not connected (waiting for simple_message at HOST:11000/11002)``;
* a connection lost (closed, no state message for ``state_timeout_s``, no acknowledgement
  for ``ack_timeout_s``): ``simple_message link lost: ...``; rob6 reconnects every
  ``retry_s``;
* STATUS: ``robot reports an E-stop``, ``robot reports drives off``,
  ``robot reports controller error N``;
* a point refused (reply code other than 1), or the robot not at the target when it
  stopped: ``robot refused a point ...`` / ``robot stopped short of the target ...``.

Motion commands meanwhile are refused with the same error. The link resumes once both
connections are up, STATUS is clear and the robot is at rest (two state messages after
the fault, the same position in both): the core continues from the robot's actual
position, never from where an interrupted motion would have been. When the stream was
cut mid-motion the link sends a stop (sequence -4) as soon as it can; the simulator
brakes on it, the V+ program does not (its issued motions, at most two points, run out).

Joints: rob6 (rob6server's convention, degrees) versus the controller's (radians on the
wire), see ``to_controller_deg`` and deploy/adept/README.md.
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
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rob6.messages import LinkEvent, LinkStatus
from rob6.robots import RobotModel

from ..loop import CycleRunner
from ..motion import CoreState, MotionCore
from . import Link, Outputs, Publish
from .adept_io import AdeptIoPort, IoPortError
from .simple_message_codec import (
    BYTE_ORDERS,
    END_TRAJECTORY,
    JOINT_POSITION,
    JOINT_TRAJ_PT,
    SERVICE_REPLY,
    STATUS,
    STOP_TRAJECTORY,
    SUCCESS,
    TS_TRUE,
    Codec,
    JointPosition,
    Message,
    RobotStatus,
    SimpleMessageError,
)
from .streaming import endpoint_name as _name, quantile as _quantile, send_all as _send_all

log = logging.getLogger("rob6.driver")

DEFAULT_HOST = "127.0.0.1"
DEFAULT_MOTION_PORT = 11000
DEFAULT_STATE_PORT = 11002
DEFAULT_IO_PORT = 11001
DEFAULT_BYTE_ORDER = "big"
#: time between streamed points (rounded to whole controller cycles)
DEFAULT_PERIOD_S = 0.048
#: how far (in periods) the controller runs behind rob6 when it honours durations
LEAD_PERIODS = 1
ACK_TIMEOUT_S = 2.0
STATE_TIMEOUT_S = 1.0
RETRY_S = 0.5
CONNECT_TIMEOUT_S = 2.0
#: a connection closed by the controller this soon without a word: probably another client
CLOSED_AT_ONCE_S = 0.5
#: how long a refused point or a closed motion connection waits for STATUS to say why
FAULT_GRACE_S = 0.3
#: arrival: the controller's position within this of the final setpoint (deg)
ARRIVAL_TOL_DEG = 0.05
#: a position that changes less than this between state messages stands still (deg)
REST_TOL_DEG = 1e-3
#: a motion fails when the robot has not moved for this long before arriving
NO_PROGRESS_S = 2.0
#: ... or has not arrived this long after rob6's trajectory ended
SETTLE_MAX_S = 4.0
STOP_WAIT_S = 0.5
LATENCY_WINDOW = 10000

# ---------------------------------------------------------------------- the Viper's joints
#: controller joint (deg) = sign * rob6 joint (deg) + offset. The V+ program moves to
#: ``#PPOINT`` of the wire's values (radians -> degrees, nothing else), i.e. the
#: controller's own joint angles. The controller's J1 turns the other way round (rob6's
#: q1 is positive clockwise seen from above), its J3 = 0 has the forearm pointing up
#: (rob6: stretched forward, hence +90), J4 and J6 turn the other way. Tested by forward
#: kinematics against the ROS-Industrial Viper URDF (tests/driver/test_adept_convention.py).
TO_CONTROLLER_SIGN = np.array([-1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
TO_CONTROLLER_OFFSET_DEG = np.array([0.0, 0.0, 90.0, 0.0, 0.0, 0.0])
#: rated joint speeds of the Viper s850, deg/s (Adept's data sheet): the maximum the
#: points' velocity fraction refers to
RATED_SPEED_DEG_S = np.array([250.0, 250.0, 250.0, 375.0, 375.0, 600.0])
#: decimals (deg) of the positions read from the wire
WIRE_DECIMALS = 4


def to_controller_deg(q_rob6_deg: npt.ArrayLike) -> np.ndarray:
    q: np.ndarray = TO_CONTROLLER_SIGN * np.asarray(q_rob6_deg, float) + TO_CONTROLLER_OFFSET_DEG
    return q


def from_controller_deg(q_ctrl_deg: npt.ArrayLike) -> np.ndarray:
    q: np.ndarray = (np.asarray(q_ctrl_deg, float) - TO_CONTROLLER_OFFSET_DEG) * TO_CONTROLLER_SIGN
    return q


def to_wire(q_rob6_deg: npt.ArrayLike) -> list[float]:
    """rob6 joints (deg) -> the six controller joints on the wire (rad)."""
    joints: list[float] = np.radians(to_controller_deg(q_rob6_deg)).tolist()
    return joints


def from_wire(joints_rad: Sequence[float]) -> np.ndarray:
    """The first six joints of a JOINT_POSITION (rad) -> rob6 joints (deg), rounded to
    1e-4 deg: float32 radians carry no more (1.4e-5 deg at 259 deg), and the controller's
    90 deg then reads as rob6's 0 exactly."""
    q = from_controller_deg(np.degrees(np.asarray(joints_rad[:6], float)))
    return np.round(q, WIRE_DECIMALS) + 0.0  # + 0.0: no -0.0


@dataclass(frozen=True)
class AdeptSettings:
    """Where the controller is and how to talk to it (``ROB6_SM_*``)."""

    host: str = DEFAULT_HOST
    motion_port: int = DEFAULT_MOTION_PORT
    state_port: int = DEFAULT_STATE_PORT
    io_port: int = DEFAULT_IO_PORT
    byte_order: str = DEFAULT_BYTE_ORDER
    period_s: float = DEFAULT_PERIOD_S

    def check(self) -> None:
        """ValueError (one line, naming the setting) when a value cannot work."""
        if not self.host.strip():
            raise ValueError("ROB6_SM_HOST is empty: give the controller's address")
        for name, port in (("ROB6_SM_MOTION_PORT", self.motion_port), ("ROB6_SM_STATE_PORT", self.state_port),
                           ("ROB6_SM_IO_PORT", self.io_port)):
            if not 1 <= int(port) <= 65535:
                raise ValueError(f"{name}={port}: expected a TCP port 1..65535")
        if self.byte_order not in BYTE_ORDERS:
            raise ValueError(f"ROB6_SM_BYTE_ORDER={self.byte_order!r}: expected big or little")
        if not (math.isfinite(self.period_s) and 0 < self.period_s <= 1.0):
            raise ValueError(f"ROB6_SM_PERIOD={self.period_s}: expected seconds, more than 0 and at most 1")


@dataclass
class _Point:
    sequence: int
    q: np.ndarray  # rob6 joints, deg
    duration: float  # s
    end: bool = False


class _Down(Exception):
    """A connection has to be given up (the message says why)."""


class AdeptLink(Link):
    kind = "simple_message"

    def __init__(self, core: MotionCore, robot: RobotModel, settings: AdeptSettings, publish: Publish,
                 on_event: Callable[[LinkEvent], None] | None = None, *,
                 ack_timeout_s: float = ACK_TIMEOUT_S, state_timeout_s: float = STATE_TIMEOUT_S,
                 retry_s: float = RETRY_S, no_progress_s: float = NO_PROGRESS_S,
                 settle_max_s: float = SETTLE_MAX_S) -> None:
        if not robot.is_adept:
            raise ValueError(f"the simple_message link drives the Adept Viper s850 (ad850), not {robot.name}")
        settings.check()
        self.core = core
        self.robot = robot
        self.settings = settings
        self.on_event = on_event
        self.codec = Codec(settings.byte_order)
        self.ack_timeout_s = ack_timeout_s
        self.state_timeout_s = state_timeout_s
        self.retry_s = retry_s
        self.no_progress_s = no_progress_s
        self.settle_max_s = settle_max_s
        self.decimation = max(1, round(settings.period_s / core.dt))
        self.period_s = self.decimation * core.dt
        self.lead_s = LEAD_PERIODS * self.period_s
        self.hw_min = np.array(robot.hw_min, float)
        self.hw_max = np.array(robot.hw_max, float)
        host = settings.host
        self.motion_addr = (host, int(settings.motion_port))
        self.state_addr = (host, int(settings.state_port))
        self.motion_name = _name(self.motion_addr)
        self.state_name = _name(self.state_addr)
        self.runner = CycleRunner(self._cycle, core.dt, publish, name="driver-cycle")
        self.io = AdeptIoPort(host, int(settings.io_port))
        self._outputs = Outputs()
        self._cond = threading.Condition(threading.RLock())
        # the controller, as the connections report it (guarded by _cond)
        self.state = "waiting"
        self.q_actual: list[float] | None = None
        self._motion_up = False
        self._state_up = False
        self._status: RobotStatus | None = None
        self._status_count = 0
        self._position: np.ndarray | None = None
        self._previous_position: np.ndarray | None = None
        self._ready_once = False
        self._lost = ""
        self._online = False
        self._reason = ""
        self._offline_mark = 0  # status count when the link went offline
        # the stream (guarded by _cond)
        self._open = False
        self._since = 0
        self._sequence = 0
        self._rest_q = core.state().q
        self._outbox: deque[_Point] = deque()
        self._inflight = False
        self._stop_pending = False
        self._sent_ctrl: np.ndarray | None = None  # controller joints of the last point acknowledged
        self._acked_mark = 0  # status count at the last acknowledgement
        # statistics
        self.packets = 0  # points acknowledged
        self.late = 0  # points merged into a later one (their acknowledgement came late)
        self.refused = 0
        self.garbage = 0
        self.runs = 0  # motion connections made
        self.stops = 0
        self._latencies: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self._closing = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._connect_errors: dict[str, str] = {}
        self._talked = False  # a request went out on the current motion connection
        self._reports = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self.waiting_reason = (f"robot not connected (waiting for simple_message at "
                               f"{host}:{settings.motion_port}/{settings.state_port})")
        self._reason = self.waiting_reason
        core.offline(self.waiting_reason)

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        self._report("waiting", f"driver: waiting for the robot: simple_message motion port {self.motion_name}, "
                     f"state port {self.state_name} ({self.settings.byte_order}-endian)", logging.WARNING)
        for target, name in ((self._report_loop, "driver-sm-events"), (self._state_loop, "driver-sm-state"),
                             (self._motion_loop, "driver-sm-motion")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        self.runner.start()

    def stop(self) -> None:
        """Stop streaming (a stop request when points are outstanding), then close."""
        with self._cond:
            busy = self._open or bool(self._outbox) or self._inflight
            if busy and self._motion_up:
                self._outbox.clear()
                self._open = False
                self._stop_pending = True
                self._wake()
                self._cond.wait_for(lambda: not self._stop_pending and not self._inflight, STOP_WAIT_S)
        self.runner.stop()
        self._closing.set()
        self._wake()
        for thread in self._threads[1:]:  # the state and motion threads
            thread.join(2.0)
        self._reports.put(None)
        if self._threads:  # the event reporter
            self._threads[0].join(1.0)
        self._wake_r.close()
        self._wake_w.close()
        self.io.close()
        log.info("driver: simple_message link closed: %d points acknowledged, %d merged, %d refused, "
                 "%d connections", self.packets, self.late, self.refused, self.runs)

    # ------------------------------------------------------------------ status
    def status(self, reset: bool = False) -> LinkStatus:
        """``address``: the controller's motion port, ``peer``: its state port; ``packets``:
        points acknowledged, ``late``: points merged because an acknowledgement came late,
        ``runs``: motion connections made, ``latency_us``: point sent -> acknowledged."""
        with self._cond:
            values = sorted(self._latencies)
            if reset:
                self._latencies.clear()
        latency = []
        if values:
            latency = [round(_quantile(values, 0.50) * 1e6, 1), round(_quantile(values, 0.99) * 1e6, 1),
                       round(values[-1] * 1e6, 1)]
        return LinkStatus(link="simple_message", state=self.state, address=self.motion_name, peer=self.state_name,
                          packets=self.packets, late=self.late, missed=self.missed, runs=self.runs,
                          garbage=self.garbage, latency_us=latency)

    # ------------------------------------------------------------------ digital outputs
    def signal(self, signals: list[int]) -> str:
        """SIGNAL each number through the program's I/O port, in order; stops at the first
        the controller does not confirm (the ones before it stay switched)."""
        done: list[int] = []
        for signal in signals:
            try:
                self.io.write(signal)
            except IoPortError as exc:
                before = f"{', '.join(map(str, done))} switched before" if done else "nothing switched"
                log.warning("driver: SIGNAL %d failed: %s (%s)", signal, exc, before)
                return f"{exc} ({before})"
            self._outputs.switched(signal)
            done.append(signal)
        log.info("driver: SIGNAL %s done", ", ".join(map(str, signals)))
        return ""

    def outputs(self) -> list[int]:
        return self._outputs.as_list()

    def signal_bound_s(self, count: int) -> float:
        return self.io.bound_s(count)

    # ------------------------------------------------------------------ arrival
    @property
    def settle_bound_s(self) -> float:
        return self.settle_max_s + self.ack_timeout_s  # stopped short, or the last points never taken

    def settle(self, q_final: npt.ArrayLike, timeout: float | None = None) -> str:
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
                drained = not (self._open or self._outbox or self._inflight or self._stop_pending)
                position, status = self._position, self._status
                if drained and position is not None and status is not None:
                    error = np.abs(position - target)
                    if (self._status_count >= self._acked_mark + 2 and error.max() <= ARRIVAL_TOL_DEG
                            and status.in_motion != TS_TRUE):
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
    def _cycle(self) -> CoreState:
        with self._cond:
            state = self.core.step()
            self._stream(state)
        self.missed = self.runner.stats.missed  # cycles the runner skipped (the machine was too busy)
        return state

    def _stream(self, state: CoreState) -> None:
        """Turn the core's setpoints into points (lock held)."""
        if not self._online:
            self._rest_q = state.q
            return
        if state.moving:
            if not self._open:
                self._open = True
                self._sequence = 0
                self._since = 0
                self._push(self._rest_q, self.period_s + self.lead_s)
            self._since += 1
            if self._since >= self.decimation:
                self._push(state.q, self._since * self.core.dt)
                self._since = 0
        else:
            if self._open:
                self._open = False
                self._push(state.q, max(self._since, 1) * self.core.dt, end=True)
            self._rest_q = state.q

    def _push(self, q: np.ndarray, duration: float, end: bool = False) -> None:
        outside = np.flatnonzero(~((q >= self.hw_min) & (q <= self.hw_max)))
        if outside.size:  # the core's limits allow more than the robot: never send it
            j = int(outside[0])
            self._evaluate(f"refused to send a point outside the robot's range (joint {j + 1} at {q[j]:.3f}, "
                           f"range {self.hw_min[j]:g} .. {self.hw_max[j]:g})")
            return
        sequence = END_TRAJECTORY if end else self._sequence
        self._sequence += 1
        self._outbox.append(_Point(sequence, np.array(q, float), float(duration), end))
        self._wake()

    # ------------------------------------------------------------------ health
    def _fault(self) -> str:
        """Why the robot cannot move right now ("" when it can), lock held."""
        if not (self._motion_up and self._state_up and self._status is not None and self._position is not None):
            if not self._ready_once:
                return self.waiting_reason
            return f"simple_message link lost: {self._lost or 'reconnecting'}"
        st = self._status
        if st.e_stopped == TS_TRUE:
            return "robot reports an E-stop"
        if st.drives_powered == 0:
            return "robot reports drives off"
        if st.in_error == TS_TRUE or st.error_code != 0:
            return f"robot reports controller error {st.error_code}"
        return ""

    def _evaluate(self, hiccup: str = "") -> None:
        """Take the robot offline, or back online at rest (lock taken). ``hiccup``: a
        failure of the current motion that ends it like a fault, cleared at the resync."""
        with self._cond:
            fault = self._fault()
            connected = self._motion_up and self._state_up
            # waiting: never ready yet; connected: both ports up (the robot may report a fault); lost
            self.state = ("connected" if connected else "lost") if self._ready_once else "waiting"
            reason = fault or hiccup
            if reason:
                if self._online or reason != self._reason:
                    was_online = self._online
                    self._online = False
                    self._offline_mark = self._status_count
                    self._cut_stream()
                    self._reason = reason
                    self.core.offline(reason)
                    if was_online or not fault.startswith("robot not connected"):
                        event = "lost" if fault.startswith("simple_message link lost") else "fault"
                        self._report(event, f"driver: {reason}", logging.WARNING if event == "lost" else logging.ERROR)
            elif not self._online and self._at_rest():
                position = self._position
                assert position is not None  # at rest: a position was read
                back = self._reason
                self._online = self._ready_once = True
                self.state = "connected"
                self._reason = ""
                self._sent_ctrl = None
                self._rest_q = position.copy()
                self.core.online(position, reason="resynchronized with the robot")
                pose = " ".join(f"{x:.3f}" for x in position)
                if back == self.waiting_reason:
                    self._report("connected", f"driver: simple_message link up: the robot is at {pose}",
                                 logging.WARNING)
                else:
                    self._report("back", f"driver: the robot is ready again (before: {back}); continuing from "
                                 f"its actual position {pose}", logging.WARNING)
            self._cond.notify_all()

    def _at_rest(self) -> bool:
        """Two state messages since the fault, the latest at rest and where the one before was."""
        if self._status is None or self._position is None or self._previous_position is None:
            return False
        if self._status_count < self._offline_mark + 2 or self._status.in_motion == TS_TRUE:
            return False
        return bool(np.abs(self._position - self._previous_position).max() <= REST_TOL_DEG)

    def _cut_stream(self) -> None:
        """The robot went offline: drop what was not sent; stop what was (lock held)."""
        outstanding = self._open or bool(self._outbox) or self._inflight
        self._outbox.clear()
        self._open = False
        if outstanding and self._motion_up:
            self._stop_pending = True
            self._wake()

    def _wait_for_fault(self) -> None:
        """A refused point or a closed motion connection: give STATUS a moment to say why
        (an E-stop is the better error than its consequence)."""
        with self._cond:
            self._cond.wait_for(lambda: self._fault() != "" and not self._fault().startswith("simple_message"),
                                FAULT_GRACE_S)

    # ------------------------------------------------------------------ the state port
    def _state_loop(self) -> None:
        while not self._closing.is_set():
            sock = self._connect(self.state_addr, "state")
            if sock is None:
                self._closing.wait(self.retry_s)
                continue
            with self._cond:
                self._state_up = True
                self._status = self._position = self._previous_position = None
                self._evaluate()
            try:
                detail = self._read_state(sock)
            finally:
                sock.close()
            if self._closing.is_set():
                break
            with self._cond:
                self._state_up = False
                self._status = None
                self._lost = detail
                self._evaluate()
            self._closing.wait(self.retry_s)

    def _read_state(self, sock: socket.socket) -> str:
        """Read state messages until the connection fails; why it failed."""
        buffer = bytearray()
        connected = heard = time.monotonic()
        sock.settimeout(0.1)
        while not self._closing.is_set():
            try:
                data = sock.recv(4096)
            except TimeoutError:
                if time.monotonic() - heard > self.state_timeout_s:
                    ms = round(self.state_timeout_s * 1000)
                    return f"no state message from the controller at {self.state_name} for {ms} ms"
                continue
            except ConnectionResetError:  # closed with data unread: a reset, still a close
                data = b""
            except OSError as exc:
                return f"the state connection to {self.state_name} failed: {exc.strerror or exc}"
            if not data:
                if heard == connected and time.monotonic() - connected < CLOSED_AT_ONCE_S:
                    return (f"the controller at {self.state_name} closed the state connection at once "
                            "(is another client connected to it?)")
                return f"the controller at {self.state_name} closed the state connection"
            buffer += data
            try:
                payloads = self.codec.split(buffer)
                for payload in payloads:
                    self._on_state(self.codec.decode(payload))
            except SimpleMessageError as exc:
                self._garbage(f"driver: unreadable state message from {self.state_name}: {exc}")
                return f"unreadable state message from {self.state_name} ({exc})"
            if payloads:
                heard = time.monotonic()
        return "closing"

    def _on_state(self, message: Message) -> None:
        kind = message.header.msg_type
        if kind == JOINT_POSITION and isinstance(message.value, JointPosition):
            q = from_wire(message.value.joints)
            with self._cond:
                self._previous_position = self._position
                self._position = q
                self.q_actual = q.tolist()
        elif kind == STATUS and isinstance(message.value, RobotStatus):
            with self._cond:
                self._status = message.value
                self._status_count += 1
                self._evaluate()

    # ------------------------------------------------------------------ the motion port
    def _motion_loop(self) -> None:
        while not self._closing.is_set():
            sock = self._connect(self.motion_addr, "motion")
            if sock is None:
                self._closing.wait(self.retry_s)
                continue
            with self._cond:
                self._motion_up = True
                self._inflight = False
                self._stop_pending = False
                self.runs += 1
                self._evaluate()
            try:
                detail = self._serve_motion(sock)
            except _Down as exc:
                detail = str(exc)
            finally:
                sock.close()
            if self._closing.is_set():
                break
            self._wait_for_fault()
            with self._cond:
                self._motion_up = False
                self._inflight = False
                self._stop_pending = False
                self._lost = detail
                self._evaluate()
            self._closing.wait(self.retry_s)

    def _serve_motion(self, sock: socket.socket) -> str:
        buffer = bytearray()
        connected = time.monotonic()
        self._talked = False
        sock.setblocking(False)
        while not self._closing.is_set():
            with self._cond:
                request = self._next_request()
            if request is None:  # idle: wait for a point, and notice a connection that closes
                readable, _, _ = select.select([sock, self._wake_r], [], [], 0.2)
                if self._wake_r in readable:
                    self._drain_wake()
                if sock in readable:
                    self._receive(sock, buffer, connected)
                    self._skip_unasked(buffer)
                continue
            frame, ctrl, stop = request
            sent = time.perf_counter()
            self._talked = True
            try:
                _send_all(sock, frame, self.ack_timeout_s)
            except OSError as exc:
                raise _Down(f"sending to the controller at {self.motion_name} failed: {exc.strerror or exc}") from None
            code = self._await_reply(sock, buffer, connected)
            latency = time.perf_counter() - sent
            self._on_reply(code, ctrl, stop, latency)
        return "closing"

    def _next_request(self) -> tuple[bytes, np.ndarray | None, bool] | None:
        """(frame, controller joints, is_stop) of the next request, or None (lock held).
        Points waiting since the last acknowledgement are merged into one."""
        if self._stop_pending:
            self._stop_pending = False
            self._inflight = True
            joints = np.radians(self._sent_ctrl).tolist() if self._sent_ctrl is not None else [0.0] * 6
            return self.codec.traj_pt(STOP_TRAJECTORY, joints), None, True
        if not self._outbox:
            return None
        merged = []
        while self._outbox:
            point = self._outbox.popleft()
            merged.append(point)
            if point.end:
                break
        self.late += len(merged) - 1
        last = merged[-1]
        duration = sum(p.duration for p in merged)
        ctrl = to_controller_deg(last.q)
        velocity = 0.0
        if self._sent_ctrl is not None and duration > 0:
            velocity = float(min(1.0, np.max(np.abs(ctrl - self._sent_ctrl) / duration / RATED_SPEED_DEG_S)))
        self._inflight = True
        return self.codec.traj_pt(last.sequence, np.radians(ctrl).tolist(), velocity, duration), ctrl, False

    def _await_reply(self, sock: socket.socket, buffer: bytearray, connected: float) -> int:
        """The reply code of the request just sent (``_Down`` when none comes in time)."""
        deadline = time.monotonic() + self.ack_timeout_s
        while True:
            for payload in self._frames(buffer):
                message = self.codec.decode(payload)
                if message.header.comm_type == SERVICE_REPLY and message.header.msg_type == JOINT_TRAJ_PT:
                    return message.header.reply_code
                self._garbage(f"driver: ignored a message of type {message.header.msg_type} "
                              f"(comm type {message.header.comm_type}) on the motion port")
            remaining = deadline - time.monotonic()
            if self._closing.is_set():
                raise _Down("closing")
            if remaining <= 0:
                ms = round(self.ack_timeout_s * 1000)
                raise _Down(f"no acknowledgement from the controller at {self.motion_name} for {ms} ms")
            readable, _, _ = select.select([sock], [], [], min(remaining, 0.2))
            if readable:
                self._receive(sock, buffer, connected)

    def _on_reply(self, code: int, ctrl: np.ndarray | None, stop: bool, latency: float) -> None:
        with self._cond:
            self._inflight = False
            self._latencies.append(latency)
            self._cond.notify_all()
            if code == SUCCESS:
                self.packets += 1
                self._acked_mark = self._status_count
                if stop:
                    self.stops += 1
                    self._report("stop_sent", "driver: stop (-4) acknowledged by the controller", logging.INFO)
                else:
                    self._sent_ctrl = ctrl
                return
            self.refused += 1
            self._outbox.clear()
            self._open = False
        self._wait_for_fault()
        with self._cond:
            self._report("refused", f"driver: the controller refused a point (reply code {code})", logging.WARNING)
            self._evaluate("" if stop else f"robot refused a point (reply code {code})")

    def _receive(self, sock: socket.socket, buffer: bytearray, connected: float) -> None:
        try:
            data = sock.recv(4096)
        except BlockingIOError:
            return
        except ConnectionResetError:  # closed with data unread: a reset, still a close
            data = b""
        except OSError as exc:
            raise _Down(f"the motion connection to {self.motion_name} failed: {exc.strerror or exc}") from None
        if not data:
            if not self._talked and time.monotonic() - connected < CLOSED_AT_ONCE_S:
                raise _Down(f"the controller at {self.motion_name} closed the motion connection at once "
                            "(is another client connected to it?)")
            raise _Down(f"the controller at {self.motion_name} closed the motion connection")
        buffer += data

    def _frames(self, buffer: bytearray) -> list[bytes]:
        try:
            return self.codec.split(buffer)
        except SimpleMessageError as exc:
            self._garbage(f"driver: unreadable message on the motion port {self.motion_name}: {exc}")
            raise _Down(f"unreadable message from the controller at {self.motion_name} ({exc})") from None

    def _skip_unasked(self, buffer: bytearray) -> None:
        for payload in self._frames(buffer):
            message = self.codec.decode(payload)
            self._garbage(f"driver: ignored an unasked message of type {message.header.msg_type} "
                          f"on the motion port")

    # ------------------------------------------------------------------ connections
    def _connect(self, addr: tuple[str, int], port: str) -> socket.socket | None:
        try:
            sock = socket.create_connection(addr, timeout=CONNECT_TIMEOUT_S)
        except OSError as exc:
            text = exc.strerror or str(exc) or type(exc).__name__
            if self._connect_errors.get(port) != text:
                self._connect_errors[port] = text
                level = logging.WARNING if self._ready_once else logging.INFO
                log.log(level, "driver: cannot reach the controller's %s port %s: %s; retrying every %g s",
                        port, _name(addr), text, self.retry_s)
            return None
        self._connect_errors.pop(port, None)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        log.info("driver: connected to the controller's %s port %s", port, _name(addr))
        return sock

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
            t=time.time(), event=event, message=message.removeprefix("driver: "), link="simple_message",
            cycle=self.core.cycle, late=self.late, q_actual=self.q_actual)))

