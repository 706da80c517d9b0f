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
motion core steps, and while the robot moves each time the plan has run ``period_s``
(default 48 ms, three cycles) its setpoint becomes one point, with the time since the
previous point as its ``duration`` and the speed that implies as ``velocity`` (fraction of
the rated joint speeds). Every setpoint has passed the core's limit monitor; the
controller's own joint ranges (``CONTROLLER_RANGE_DEG``) bound the core's turn limits, so
a motion leaving them is refused before it starts, and the link never sends such a point.
A motion's stream

* starts with a *hold point*: the position the robot rests at, lasting one period plus
  a lead (one more period), for a controller that honours durations;
* ends with the final setpoint as sequence -3 (END_TRAJECTORY) once the core is at rest.

Each point waits for its acknowledgement. The Adept's V+ program reads a point only when
its previous MOVE has begun (one motion runs, the next is planned behind it), so its
acknowledgements come at the arm's pace: the base (``streamed_points.py``) merges what was made meanwhile, never
beyond two periods of the core's full speed nor ``MAX_SEGMENT_DEG`` on any joint (a point
never goes farther than half of that, however fast a client let the core move), and slows
the core (time scaling) when the answers fall behind, so the arm and rob6's setpoints stay
together at any monitor speed.

A motion connection begins with the *opening* (``Codec.opening``): the program discards
the first four bytes of a connection, and the opening reads right whether they are rob6's
or not (deploy/adept/README.md section 4).

The V+ program ignores velocity and duration (``SPEED 100 ALWAYS``): the arm runs each
point at the pendant's monitor speed. It acknowledges every point at once with code 1 and
reports no errors in STATUS (only drives, E-stop and motion); a MOVE it cannot make ends
its motion task, which closes the connection.

A motion returns ``true`` only when the robot has arrived: all points acknowledged,
the controller reports it at rest, and its JOINT_POSITION is the final setpoint within
``ARRIVAL_TOL_DEG``. Otherwise, and on every fault, the motion ends with ``false`` and an
error the gateway shows as ``ERROR: driver: ...``:

* no connection yet: ``robot not connected (waiting for simple_message at HOST:11000/11002)``;
* a connection lost (closed, no state message for ``state_timeout_s``, neither an
  acknowledgement nor the arm moving for ``ack_timeout_s``): ``simple_message link lost:
  ...``; rob6 reconnects every ``retry_s``. The answer to a point comes when the MOVE
  before it has begun, so it may take a whole MOVE of the arm (seconds at a low monitor
  speed, or when the operator lowers it mid-stream): while the state port shows the arm
  moving (STATUS in motion, or its position changing) a late answer is no lost link;
* STATUS: ``robot reports an E-stop``, ``robot reports drives off``,
  ``robot reports controller error N``;
* a point refused (reply code other than 1), or the robot not at the target when it
  stopped: ``robot refused a point ...`` / ``robot stopped short of the target ...``.

Motion commands meanwhile are refused with the same error. The link resumes once both
connections are up, STATUS is clear and the robot is at rest (two state messages after
the fault, the same position in both): the core continues from the robot's actual
position, never from where an interrupted motion would have been. When the stream was
cut mid-motion the link sends a stop (sequence -4) as soon as it can; the V+ program
answers it and halts nothing: the MOVEs it has issued (at most three segments of at most
``MAX_SEGMENT_DEG``) run out.

Joints: rob6 (rob6server's convention, degrees) versus the controller's (radians on the
wire), see ``to_controller_deg`` and deploy/adept/README.md.
"""

from __future__ import annotations

import logging
import math
import select
import socket
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Unpack

import numpy as np
from numpy.typing import ArrayLike

from rob6.messages import LinkEvent, LinkStatus
from rob6.robots import RobotModel

from ..motion import MotionCore
from . import Outputs, Publish
from .adept_io import DEFAULT_OUTPUTS, AdeptIoPort, IoPortError, parse_outputs
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
from .streamed_points import (
    REST_TOL_DEG,
    Joints,
    LinkDown,
    StreamedPointsLink,
    Timeouts,
    check_address,
    check_period,
)
from .streaming import endpoint_name as _name, send_all as _send_all

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
#: a connection closed by the controller this soon without a word: probably another client
CLOSED_AT_ONCE_S = 0.5
#: how long a refused point or a closed motion connection waits for STATUS to say why
FAULT_GRACE_S = 0.3
#: arrival: the controller's position within this of the final setpoint (deg)
ARRIVAL_TOL_DEG = 0.05

# ---------------------------------------------------------------------- the Viper's joints
#: controller joint (deg) = sign * rob6 joint (deg) + offset. The V+ program moves to
#: ``#PPOINT`` of the wire's values (radians -> degrees, nothing else), i.e. the
#: controller's own joint angles. The controller's J1 turns the other way round (rob6's
#: q1 is positive clockwise seen from above), its J3 = 0 has the forearm pointing up
#: (rob6: stretched forward, hence +90), J4 and J6 turn the other way. Tested by forward
#: kinematics against the ROS-Industrial Viper URDF (tests/driver/test_adept_convention.py).
TO_CONTROLLER_SIGN = np.array([-1.0, 1.0, 1.0, -1.0, 1.0, -1.0])
TO_CONTROLLER_OFFSET_DEG = np.array([0.0, 0.0, 90.0, 0.0, 0.0, 0.0])
#: the Viper's joint ranges in the controller's own angles, deg: ``MOVE`` to a point
#: outside them is a V+ error that ends the program's motion task, so none is ever sent.
#: The ROS-Industrial Viper URDF (adept_experimental, ``viper_s650_macro.xacro``, the
#: joints' ``<limit lower upper>`` in rad): J3 reaches 256 deg, not the 259 rob6's own
#: table maps to (deploy/adept/README.md section 5)
CONTROLLER_RANGE_DEG = np.array([(-170.0, 170.0), (-190.0, 45.0), (-29.0, 256.0), (-190.0, 190.0),
                                 (-120.0, 120.0), (-360.0, 360.0)])
#: rated joint speeds of the Viper s850, deg/s (Adept's data sheet): the maximum the
#: points' velocity fraction refers to
RATED_SPEED_DEG_S = np.array([250.0, 250.0, 250.0, 375.0, 375.0, 600.0])
#: the longest segment one point may span, per joint, deg: what rob6's default speeds (a
#: tenth of the rated ones) move in two default periods (96 ms), whatever speed limits a
#: client sets. The program holds up to three MOVEs (running, planned, in the task), and a
#: stop halts none of them: after a client vanishes the arm runs on at most three of these,
#: at any monitor speed (which stretches the time of a stop, never its distance)
MAX_SEGMENT_DEG = np.array([2.4, 2.4, 2.4, 3.6, 3.6, 5.76])
#: decimals (deg) of the positions read from the wire
WIRE_DECIMALS = 4


def to_controller_deg(q_rob6_deg: ArrayLike) -> Joints:
    q: Joints = TO_CONTROLLER_SIGN * np.asarray(q_rob6_deg, float) + TO_CONTROLLER_OFFSET_DEG
    return q


def from_controller_deg(q_ctrl_deg: ArrayLike) -> Joints:
    q: Joints = (np.asarray(q_ctrl_deg, float) - TO_CONTROLLER_OFFSET_DEG) * TO_CONTROLLER_SIGN
    return q


def to_wire(q_rob6_deg: ArrayLike) -> list[float]:
    """rob6 joints (deg) -> the six controller joints on the wire (rad)."""
    wire: list[float] = np.radians(to_controller_deg(q_rob6_deg)).tolist()
    return wire


def from_wire(joints_rad: Sequence[float]) -> Joints:
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
    outputs: str = DEFAULT_OUTPUTS  # the digital outputs the controller has installed

    def check(self) -> None:
        """ValueError (one line, naming the setting) when a value cannot work."""
        check_address("ROB6_SM", self.host, ("MOTION_PORT", self.motion_port), ("STATE_PORT", self.state_port),
                      ("IO_PORT", self.io_port))
        if self.byte_order not in BYTE_ORDERS:
            raise ValueError(f"ROB6_SM_BYTE_ORDER={self.byte_order!r}: expected big or little")
        check_period("ROB6_SM", self.period_s)
        parse_outputs(self.outputs)


class AdeptLink(StreamedPointsLink):
    kind = "simple_message"
    arrival_tol_deg = ARRIVAL_TOL_DEG
    max_segment_deg = MAX_SEGMENT_DEG

    def __init__(self, core: MotionCore, robot: RobotModel, settings: AdeptSettings, publish: Publish,
                 on_event: Callable[[LinkEvent], None] | None = None, **timeouts: Unpack[Timeouts]) -> None:
        if not robot.is_adept:
            raise ValueError(f"the simple_message link drives the Adept Viper s850 (ad850), not {robot.name}")
        settings.check()
        self.settings = settings
        self.codec = Codec(settings.byte_order)
        # the controller's range in rob6's joints (a sign flips a joint's ends)
        ends = np.sort(from_controller_deg(CONTROLLER_RANGE_DEG.T), axis=0)
        self.range_min, self.range_max = ends[0], ends[1]
        host = settings.host
        self.motion_addr = (host, int(settings.motion_port))
        self.state_addr = (host, int(settings.state_port))
        self.motion_name = _name(self.motion_addr)
        self.state_name = _name(self.state_addr)
        self.io = AdeptIoPort(host, int(settings.io_port))
        self.installed = parse_outputs(settings.outputs)
        self._outputs = Outputs()
        # the connections (guarded by _cond)
        self._motion_up = False
        self._state_up = False
        self._robot_status: RobotStatus | None = None
        self._sequence = 0  # the number of the motion's next point
        self._rest_q: Joints = core.state().q
        self._talked = False  # a request went out on the current motion connection
        self._moving_seen = -math.inf  # when the state port last showed the arm moving (monotonic)
        self.stops = 0
        waiting = f"robot not connected (waiting for simple_message at {host}:{settings.motion_port}/{settings.state_port})"
        super().__init__(core, robot, settings, publish, on_event, waiting, **timeouts)
        self.lead_s = LEAD_PERIODS * self.period_s
        core.restrict(self.range_min, self.range_max)  # motions beyond the arm's range are refused up front

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        self._report("waiting", f"driver: waiting for the robot: simple_message motion port {self.motion_name}, "
                     f"state port {self.state_name} ({self.settings.byte_order}-endian)", logging.WARNING)
        self._start_threads(((self._report_loop, "driver-sm-events"), (self._state_loop, "driver-sm-state"),
                             (self._motion_loop, "driver-sm-motion")))

    def _close_extra(self) -> None:
        self.io.close()

    # ------------------------------------------------------------------ status
    def status(self, reset: bool = False) -> LinkStatus:
        """``address``: the controller's motion port, ``peer``: its state port; ``packets``:
        points acknowledged, ``late``: points merged because an acknowledgement came late,
        ``runs``: motion connections made, ``latency_us``: point sent -> acknowledged."""
        return self._status(self.motion_name, self.state_name, reset)

    # ------------------------------------------------------------------ digital outputs
    def signal(self, signals: list[int]) -> str:
        """SIGNAL each number through the program's I/O port, in order; stops at the first
        the controller does not confirm (the ones before it stay switched). Nothing is sent
        when one is not installed (its SIGNAL would end the program's I/O task)."""
        missing = [n for n in signals if not any(abs(n) in r for r in self.installed)]
        if missing:
            return (f"signal {missing[0]} is not installed on the controller (ROB6_SM_OUTPUTS="
                    f"{self.settings.outputs}): SIGNAL of it would end the V+ program's I/O task; nothing was switched")
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

    # ------------------------------------------------------------------ the wire's hooks
    def _link_up(self) -> bool:
        return self._motion_up and self._state_up

    def _sending_up(self) -> bool:
        return self._motion_up

    def _controller_fault(self) -> str | None:
        st = self._robot_status
        if st is None:
            return None
        if st.e_stopped == TS_TRUE:
            return "robot reports an E-stop"
        if st.drives_powered == 0:
            return "robot reports drives off"
        if st.in_error == TS_TRUE or st.error_code != 0:
            return f"robot reports controller error {st.error_code}"
        return ""

    def _controller_moving(self) -> bool | None:
        if self._robot_status is None:
            return None
        return self._robot_status.in_motion == TS_TRUE

    def _outside_range(self, q: Joints) -> str:
        outside = np.flatnonzero(~((q >= self.range_min) & (q <= self.range_max)))
        if not outside.size:
            return ""
        j = int(outside[0])
        return f"joint {j + 1} at {q[j]:.3f}, range {self.range_min[j]:g} .. {self.range_max[j]:g}"

    # ------------------------------------------------------------------ the stream's extras
    def _on_open(self) -> None:
        """A motion starts with a hold point: where the robot rests, one period plus the lead."""
        self._sequence = 0
        self._push(self._rest_q, self.period_s + self.lead_s)

    def _resting(self, q: Joints) -> None:
        self._rest_q = q

    def _number(self, final: bool) -> int:
        sequence = END_TRAJECTORY if final else self._sequence
        self._sequence += 1
        return sequence

    def _on_resync(self, position: Joints) -> None:
        self._rest_q = position.copy()

    def _wait_for_fault(self) -> None:
        """A refused point or a closed motion connection: give STATUS a moment to say why
        (an E-stop is the better error than its consequence)."""
        with self._cond:
            self._cond.wait_for(lambda: self._fault() != "" and not self._fault().startswith(self.kind),
                                FAULT_GRACE_S)

    # ------------------------------------------------------------------ the state port
    def _state_loop(self) -> None:
        self._keep_connected(self.state_addr, "the controller's state port {}", self._read_state,
                             self._state_down, self._state_connected)

    def _state_connected(self) -> None:
        with self._cond:
            self._state_up = True
            self._robot_status = self._position = self._previous_position = None
            self._evaluate()

    def _state_down(self, detail: str) -> None:
        with self._cond:
            self._state_up = False
            self._robot_status = None
            self._lost = detail
            self._evaluate()

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
                if self._position is not None and np.abs(q - self._position).max() > REST_TOL_DEG:
                    self._moving_seen = time.monotonic()
                self._previous_position = self._position
                self._position = q
                self.q_actual = q.tolist()
        elif kind == STATUS and isinstance(message.value, RobotStatus):
            with self._cond:
                if message.value.in_motion == TS_TRUE:
                    self._moving_seen = time.monotonic()
                self._robot_status = message.value
                self._state_count += 1
                self._evaluate()

    # ------------------------------------------------------------------ the motion port
    def _motion_loop(self) -> None:
        self._keep_connected(self.motion_addr, "the controller's motion port {}", self._serve_motion,
                             self._motion_down)

    def _motion_connected(self) -> None:
        with self._cond:
            self._motion_up = True
            self._inflight = False
            self._stop_pending = False
            self.runs += 1
            self._evaluate()

    def _motion_down(self, detail: str) -> None:
        self._wait_for_fault()
        with self._cond:
            self._motion_up = False
            self._inflight = False
            self._stop_pending = False
            self._lost = detail
            self._evaluate()

    def _serve_motion(self, sock: socket.socket) -> str:
        buffer = bytearray()
        connected = time.monotonic()
        self._talked = False
        sock.setblocking(False)
        if not self._open_motion(sock, buffer, connected):
            return "closing"
        self._motion_connected()
        while not self._closing.is_set():
            with self._cond:
                request = self._next_request()
            if request is None:  # idle: wait for a point, and notice a connection that closes
                readable, _, _ = select.select([sock, self._wake_r], [], [], 0.2)
                if self._wake_r in readable:
                    self._drain_wake()
                if sock in readable:
                    self._receive_motion(sock, buffer, connected)
                    self._skip_unasked(buffer)
                continue
            frame, ctrl, stop = request
            sent = time.perf_counter()
            self._talked = True
            self._send(sock, frame)
            code, _sequence = self._await_reply(sock, buffer, connected)
            latency = time.perf_counter() - sent
            self._on_reply(code, ctrl, stop, latency)
        return "closing"

    def _open_motion(self, sock: socket.socket, buffer: bytearray, connected: float) -> bool:
        """Begin a motion connection with the opening (``Codec.opening``) once the arm can
        take it and is at rest (drives on, no E-stop, two state messages at the same position
        and not in motion: the opening may be a MOVE to where it stands, queued behind any
        MOVE still running, so a position taken while it moves would send it back), with its
        latest position, and its rest when it was read from its first byte; False when the
        link closes meanwhile. ``LinkDown`` when the controller closes or does not answer."""
        while True:
            with self._cond:
                ready = self._state_up and self._controller_fault() == "" and self._at_rest()
                here = self._position
            if self._closing.is_set():
                return False
            if ready and here is not None:
                break
            if select.select([sock], [], [], 0.1)[0]:
                self._receive_motion(sock, buffer, connected)
                self._skip_unasked(buffer)
        self._talked = True
        self._send(sock, self.codec.opening(to_wire(here)))
        _code, sequence = self._await_reply(sock, buffer, connected)
        if sequence == STOP_TRAJECTORY:  # read from its first byte: the second stop completes it
            self._send(sock, self.codec.opening_rest())
            self._await_reply(sock, buffer, connected)
        log.info("driver: the controller at %s read the opening from byte %d", self.motion_name,
                 0 if sequence == STOP_TRAJECTORY else 4)
        return True

    def _send(self, sock: socket.socket, data: bytes) -> None:
        try:
            _send_all(sock, data, self.ack_timeout_s)
        except OSError as exc:
            raise LinkDown(f"sending to the controller at {self.motion_name} failed: "
                           f"{exc.strerror or exc}") from None

    def _next_request(self) -> tuple[bytes, Joints | None, bool] | None:
        """(frame, controller joints, is_stop) of the next request, or None (lock held).
        Points waiting since the last acknowledgement are merged into one."""
        if self._stop_pending:
            self._stop_pending = False
            self._inflight = True
            joints: list[float] = np.radians(self._sent).tolist() if self._sent is not None else [0.0] * 6
            return self.codec.traj_pt(STOP_TRAJECTORY, joints), None, True
        if not self._outbox:
            return None
        last, duration, _ = self._merge()
        ctrl = to_controller_deg(last.q)
        velocity = 0.0
        if self._sent is not None and duration > 0:
            velocity = float(min(1.0, np.max(np.abs(ctrl - self._sent) / duration / RATED_SPEED_DEG_S)))
        return self.codec.traj_pt(last.sequence, np.radians(ctrl).tolist(), velocity, duration), ctrl, False

    def _await_reply(self, sock: socket.socket, buffer: bytearray, connected: float) -> tuple[int, int | None]:
        """The reply code of the request just sent and the sequence its body carries
        (``LinkDown`` when for ``ack_timeout_s`` neither it came nor the arm moved)."""
        sent = time.monotonic()
        while True:
            for payload in self._frames(buffer):
                message = self.codec.decode(payload)
                if message.header.comm_type == SERVICE_REPLY and message.header.msg_type == JOINT_TRAJ_PT:
                    return message.header.reply_code, self.codec.reply_sequence(message.body)
                self._garbage(f"driver: ignored a message of type {message.header.msg_type} "
                              f"(comm type {message.header.comm_type}) on the motion port")
            with self._cond:
                deadline = max(sent, self._moving_seen) + self.ack_timeout_s
            remaining = deadline - time.monotonic()
            if self._closing.is_set():
                raise LinkDown("closing")
            if remaining <= 0:
                ms = round(self.ack_timeout_s * 1000)
                raise LinkDown(f"no acknowledgement from the controller at {self.motion_name} for {ms} ms")
            readable, _, _ = select.select([sock], [], [], min(remaining, 0.2))
            if readable:
                self._receive_motion(sock, buffer, connected)

    def _on_reply(self, code: int, ctrl: Joints | None, stop: bool, latency: float) -> None:
        with self._cond:
            self._answered(latency)
            if code == SUCCESS:
                self.packets += 1
                self._acked_mark = self._state_count
                if stop:
                    self.stops += 1
                    self._report("stop_sent", "driver: stop (-4) acknowledged by the controller", logging.INFO)
                else:
                    self._sent = ctrl
                return
            self._refused()
        self._wait_for_fault()
        with self._cond:
            self._report("refused", f"driver: the controller refused a point (reply code {code})", logging.WARNING)
            self._evaluate("" if stop else f"robot refused a point (reply code {code})")

    def _receive_motion(self, sock: socket.socket, buffer: bytearray, connected: float) -> None:
        at_once = not self._talked and time.monotonic() - connected < CLOSED_AT_ONCE_S
        self._receive(sock, buffer, "motion connection", self.motion_name, closed_at_once=at_once)

    def _frames(self, buffer: bytearray) -> list[bytes]:
        try:
            return self.codec.split(buffer)
        except SimpleMessageError as exc:
            self._garbage(f"driver: unreadable message on the motion port {self.motion_name}: {exc}")
            raise LinkDown(f"unreadable message from the controller at {self.motion_name} ({exc})") from None

    def _skip_unasked(self, buffer: bytearray) -> None:
        for payload in self._frames(buffer):
            message = self.codec.decode(payload)
            self._garbage(f"driver: ignored an unasked message of type {message.header.msg_type} "
                          f"on the motion port")
