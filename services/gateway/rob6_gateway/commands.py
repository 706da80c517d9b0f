"""The 78 commands of the rob6server protocol, rob6's own GetCell, and what the gateway does with each.

Every handler gets the parsed-on-demand argument cursor and returns the complete
reply text (all lines, each ending in ``\\n``) or ``None`` for the few commands the
original answers with nothing (``SetAllowedStatus``). Parsing errors use the
original's words (``ERROR: incorrect joints`` + ``false``). A failed service call
gives ``ERROR: <service> unavailable`` (no live instance) or ``ERROR: <service>: no
reply to <command> within <s> s (<what it waited for>)``, followed by ``false`` when
the command's reply can be ``false`` (``value=False`` commands: a value, no ``false``).
Command names are case-sensitive, extra arguments are ignored, as in the original.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import msgspec

from rob6 import logs
from rob6.bus import Bus, BusError, BusTimeout, CallAbandoned
from rob6.messages import (
    OWNER_SERVICES,
    Ack,
    AlterTarget,
    BackwardCalcRequest,
    Cell,
    ClientExchange,
    ConfigChange,
    ConfigReply,
    Empty,
    FkReply,
    FkRequest,
    ForwardCalcReply,
    ForwardCalcRequest,
    GripperCommand,
    GripperReply,
    JointsReply,
    ModeRequest,
    MotionConfig,
    MotionKind,
    MoveReply,
    MoveRequest,
    PingReply,
    PoseCheck,
    SessionEnd,
    SessionEvent,
    SignalRequest,
    Verbosity,
)
from rob6.robots import RobotModel
from rob6.state import JointStateMirror
from rob6.vplus import SignalError, parse_signal

from .args import Args, ParseError
from .framing import Line
from .state import ConfigMirror, Session

log = logging.getLogger("rob6.gateway")

VERSION = "0.1.01"
TRUE, FALSE = "true\n", "false\n"


class ClientGone(Exception):
    """The client's connection closed while it waited for a move (the move is abandoned)."""


class Close(Exception):
    """End the session after sending ``reply`` (Quit, Shutdown)."""

    def __init__(self, reply: str, shutdown: bool = False):
        self.reply = reply
        self.shutdown = shutdown


def fmt(values: Iterable[float]) -> str:
    return " ".join("%f" % v for v in values)


def boolean(ok: bool) -> str:
    return TRUE if ok else FALSE


def error(message: str, with_false: bool = True) -> str:
    return f"ERROR: {message}\n" + (FALSE if with_false else "")


@dataclass
class Options:
    allow_shutdown: bool = False
    allow_direct_adept_cmd: bool = False
    ping_max_count: int = 1000  # bound on PingRobot's n (the command blocks the session)
    ping_max_wait_ms: int = 1000


Handler = Callable[["Gateway", Session, Args], str | None]
COMMANDS: dict[str, Handler] = {}
#: commands whose reply is a value (or nothing), never ``false``: an error is its only line
VALUE_REPLIES: set[str] = set()


def command(*names: str, value: bool = False) -> Callable[[Handler], Handler]:
    """Register a handler; ``value``: the command answers a value, never ``false``."""
    def register(func: Handler) -> Handler:
        for name in names:
            COMMANDS[name] = func
            if value:
                VALUE_REPLIES.add(name)
        return func
    return register


def each(factory: Callable[[str], Handler], *names: str) -> None:
    """Register each of ``names`` with the handler ``factory`` makes for that name."""
    for name in names:
        command(name)(factory(name))


def failure(name: str, exc: BusError) -> str:
    """The text of the ``ERROR:`` line for command ``name`` whose service call failed."""
    if isinstance(exc, BusTimeout):  # the gateway's own call: named by the client's command
        waited = f" ({exc.waiting_for})" if exc.waiting_for else ""
        return f"{exc.service}: no reply to {name} within {exc.seconds:.1f} s{waited}"
    return exc.message


def reached(exc: BusError) -> bool:
    """Did the service take the request that failed? It answered (with an error), or it
    announced what it waited for before it was late."""
    if isinstance(exc, BusTimeout):
        return bool(exc.waiting_for)
    return exc.code != "unavailable"


class Gateway:
    """Global state shared by all sessions (they run one at a time, like the original)."""

    def __init__(self, bus: Bus, robot: RobotModel, options: Options):
        self.bus = bus
        self.robot = robot
        self.options = options
        self.joints = JointStateMirror(bus)
        self.limits = ConfigMirror(bus, robot)
        self.verbosity = 2
        self.alter = False  # EnableAlter succeeded (the planner owns the mode; this is its echo)
        self.shutdown_requested = threading.Event()
        self._ending: threading.Thread | None = None  # the last session's end: its robot stopping
        self._last_end: threading.Thread | None = None  # the last session's end, moving or not
        # a service (re)appearing gets the current verbosity, so all processes agree
        bus.on_liveliness(self._on_liveliness)

    def _on_liveliness(self, service: str, instance: str, alive: bool) -> None:
        if not alive:  # its commands answer "ERROR: <service> unavailable" until it is back
            log.log(logging.WARNING if service in OWNER_SERVICES else logging.INFO,
                    "%s instance %s went away", service, instance)
        elif service != "gateway":
            self.bus.publish("control/verbosity", Verbosity(level=self.verbosity))

    def execute(self, session: Session, line: str) -> str | None:
        name, _, rest = _split_command(line)
        handler = COMMANDS.get(name)
        if handler is None:
            return f"ERROR: {line}\n"
        if self._ending is not None:
            # the last client left with the robot moving: this one starts with it at rest
            self._ending.join()
        try:
            return handler(self, session, Args(rest))
        except ParseError as exc:
            return error(str(exc))
        except BusError as exc:
            log.warning("%s failed: %s (%s)", name, exc.message, exc.code)
            return error(failure(name, exc), with_false=name not in VALUE_REPLIES)

    def call(self, session: Session, service: str, op: str, body: object,
             abandon: Callable[[], bool] | None = None) -> Any:
        """One request on the session's own thread, the reply received where it waits."""
        return self.bus.request(service, op, body, cid=session.cid, abandon=abandon)

    def current(self, session: Session) -> list[float]:
        """Where the robot is (or the virtual robot, while route testing).

        Normally the driver's latest published state; right after a (re)start, before
        the first one arrived, one round trip asks the driver.
        """
        if session.routetest is not None:
            return session.routetest
        state = self.joints.get() or self.call(session, "driver", "state", Empty())
        return state.q

    def record(self, session: Session, received: float, line: Line, reply: str | None) -> None:
        """A copy of the exchange for the recorder, sent after the reply went out, numbered
        (1, 2, ... per session) so a recording shows whether any is missing."""
        session.seq += 1
        self.bus.trace("trace/gateway/session", ClientExchange(
            session=session.number, peer=session.peer, cid=session.cid, t_in=received,
            t_out=time.time(), line=line.text if not line.too_long else f"<{line.too_long} bytes>",
            reply=reply, seq=session.seq))

    def record_event(self, session: Session, event: str, greeting: str = "", reason: str = "") -> None:
        self.bus.trace("trace/gateway/event", SessionEvent(
            session=session.number, event=event, peer=session.peer, t=time.time(), greeting=greeting,
            reason=reason))

    def session_id(self, session: Session) -> str:
        """Names the session across gateway restarts (``SessionEnd.session``)."""
        return f"{self.bus.instance}:{session.number}"

    def end_session(self, session: Session, abandoned: bool = False) -> None:
        """The session ended (Quit, the client's close): whatever it left running stops in
        the background. When the arm may be moving (Alter on, or a move ``abandoned`` by a
        client gone), the next session's commands wait for that."""
        moving = self.alter or abandoned
        self.alter = False
        ending = threading.Thread(target=self._session_end, args=(session,),
                                  name=f"session-{session.number}-end", daemon=True)
        ending.start()
        self._last_end = ending
        if moving:
            self._ending = ending

    def wait_session_end(self, timeout: float) -> None:
        """The gateway stops: the last session's end (the planner's confirmation that what it
        left is at rest) gets up to ``timeout`` to arrive before the bus closes."""
        if self._last_end is not None:
            self._last_end.join(timeout)

    def _session_end(self, session: Session) -> None:
        """The planner stops whatever the client left running (Alter, a move), with the
        ramp, and answers at rest."""
        try:
            reply: Ack = self.call(session, "planner", "session_end", SessionEnd(session=self.session_id(session)))
        except BusError as exc:
            log.warning("planner did not confirm the end of session %d: %s", session.number,
                        failure("the end of the session", exc))
            return
        if not reply.ok:
            log.warning("session %d ended: %s", session.number, reply.reason)


def _split_command(line: str) -> tuple[str, str, str]:
    stripped = line.lstrip(" \t\r\n\v\f")
    for i, ch in enumerate(stripped):
        if ch in " \t\r\n\v\f":
            return stripped[:i], ch, stripped[i + 1:]
    return stripped, "", ""


# ====================================================================== management
@command("GetRobot", value=True)
def get_robot(gw: Gateway, session: Session, args: Args) -> str:
    return gw.robot.name + "\n"


def _identity(predicate: Callable[[RobotModel], bool]) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        return boolean(predicate(gw.robot))
    return handler


command("IsAdept")(_identity(lambda r: r.is_adept))
command("IsKuka")(_identity(lambda r: r.is_kuka))
command("IsKawa")(_identity(lambda r: r.is_kawa))
command("IsKR3")(_identity(lambda r: r.is_kr3))
command("IsKR16")(_identity(lambda r: r.is_kr16))


@command("GetVersion", value=True)
def get_version(gw: Gateway, session: Session, args: Args) -> str:
    return VERSION + "\n"


@command("GetTimestamp", value=True)
def get_timestamp(gw: Gateway, session: Session, args: Args) -> str:
    return "%.3f\n" % time.time()


@command("CM_PING", value=True)
def cm_ping(gw: Gateway, session: Session, args: Args) -> str:
    return "PONG\n"


@command("GetVerbosity", value=True)
def get_verbosity(gw: Gateway, session: Session, args: Args) -> str:
    return f"{gw.verbosity}\n"


@command("SetVerbosity")
def set_verbosity(gw: Gateway, session: Session, args: Args) -> str:
    level = args.index()
    if not 0 <= level <= 4:
        log.error("invalid verbosity level %d", level)
        return FALSE
    gw.verbosity = level
    logs.set_verbosity(level)
    gw.bus.publish("control/verbosity", Verbosity(level=level), reliable=True)
    return TRUE


@command("Quit")
def quit_(gw: Gateway, session: Session, args: Args) -> str:
    raise Close("bye!\n")


@command("Shutdown")
def shutdown(gw: Gateway, session: Session, args: Args) -> str:
    if not gw.options.allow_shutdown:
        return error("Shutdown is disabled on this server (start the gateway with --allow-shutdown)",
                     with_false=False)
    raise Close("bye!\nshutting down ...\n", shutdown=True)


@command("PingRobot", value=True)
def ping_robot(gw: Gateway, session: Session, args: Args) -> str:
    """n round trips gateway -> driver, ``wait`` ms apart (default 10, 0).

    Reply (one line, like the original): mean round trip (s), robot time zero, server
    time zero, and the coefficients c1, c2 of the fit (server - server0) -
    (robot - robot0) = c1 (robot - robot0) + c2 (robot - robot0)^2 (clock drift).
    Arguments that cannot be measured get the original's ``-1``.
    """
    count = args.integer() if not args.at_end() else 10
    wait_ms = args.double() if not args.at_end() else 0.0
    if (count is None or wait_ms is None or not 1 <= count <= gw.options.ping_max_count
            or not 0 <= wait_ms <= gw.options.ping_max_wait_ms):
        log.warning("PingRobot: n must be 1..%d and wait 0..%d ms", gw.options.ping_max_count,
                    gw.options.ping_max_wait_ms)
        return "-1\n"
    samples = []
    for i in range(count):
        if i and wait_ms:
            time.sleep(wait_ms / 1000.0)
        sent = time.time()
        reply: PingReply = gw.call(session, "driver", "ping", Empty())
        received = time.time()
        samples.append((received - sent, reply.robot_time, (sent + received) / 2))
    mean_rtt = sum(s[0] for s in samples) / count
    robot0, server0 = samples[0][1], samples[0][2]
    c1, c2 = _drift_fit([(r - robot0, s - server0) for _, r, s in samples])
    return "%.6f %.10f %.10f %.8g %.8g\n" % (mean_rtt, robot0, server0, c1, c2)


def _drift_fit(points: list[tuple[float, float]]) -> tuple[float, float]:
    """Least squares of d = s - r over c1 r + c2 r^2 (no constant: both start at zero)."""
    s11 = sum(r * r for r, _ in points)
    s12 = sum(r ** 3 for r, _ in points)
    s22 = sum(r ** 4 for r, _ in points)
    b1 = sum(r * (s - r) for r, s in points)
    b2 = sum(r * r * (s - r) for r, s in points)
    det = s11 * s22 - s12 * s12
    if abs(det) < 1e-30:
        return (b1 / s11 if s11 > 1e-30 else 0.0), 0.0
    return (b1 * s22 - b2 * s12) / det, (s11 * b2 - s12 * b1) / det


# ====================================================================== position
@command("GetPositionJoints", value=True)
def get_position_joints(gw: Gateway, session: Session, args: Args) -> str:
    return fmt(gw.current(session)) + "\n"


@command("GetPositionHomRowWise", value=True)
def get_position_hom(gw: Gateway, session: Session, args: Args) -> str:
    reply: FkReply = gw.call(session, "kinematics", "fk", FkRequest(joints=[gw.current(session)]))
    return fmt(reply.poses[0]) + "\n"


@command("GetStatus", value=True)
def get_status(gw: Gateway, session: Session, args: Args) -> str:
    return " ".join(gw.robot.status(gw.current(session))) + "\n"


# ====================================================================== limits and configuration
def _config(gw: Gateway, session: Session) -> MotionConfig:
    """The planner's configuration: mirrored, or asked when the mirror cannot vouch for it."""
    config = gw.limits.current()
    if config is None:
        asked: MotionConfig = gw.call(session, "planner", "config", Empty())
        gw.limits.set(asked)
        return asked
    return config


def _config_getter(field: str) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        return fmt(getattr(_config(gw, session), field)) + "\n"
    return handler


command("GetJointsMaxSpeed", value=True)(_config_getter("speed"))
command("GetJointsMaxAcceleration", value=True)(_config_getter("accel"))
command("GetJointsMaxChange", value=True)(_config_getter("max_change"))
command("GetJointsMaxTurnMax", value=True)(_config_getter("turn_max"))
command("GetJointsMaxTurnMin", value=True)(_config_getter("turn_min"))
command("GetMinChangeWeights", value=True)(_config_getter("weights"))


def _change(gw: Gateway, session: Session, name: str, values: Iterable[float] = (),
            words: Iterable[str] = ()) -> bool:
    reply: ConfigReply = gw.call(session, "planner", "config_change",
                          ConfigChange(command=name, args=list(values), words=list(words)))
    gw.limits.set(reply.config)
    return reply.ok


def _six(name: str) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        return boolean(_change(gw, session, name, args.joints()))
    return handler


def _single(name: str) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        index = args.index()
        value = args.value()
        return boolean(_change(gw, session, name, (index, value)))
    return handler


def _reset(name: str) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        return boolean(_change(gw, session, name))
    return handler


each(_six, "SetJointsMaxSpeed", "SetJointsMaxAcceleration", "SetJointsMaxChange", "SetJointsMaxTurnMax",
     "SetJointsMaxTurnMin", "SetMinChangeWeights")
each(_single, "SetSingleJointMaxSpeed", "SetSingleJointMaxAcceleration", "SetSingleJointMaxChange",
     "SetSingleJointMaxTurnMax", "SetSingleJointMaxTurnMin")
each(_reset, "ResetJointsMaxSpeed", "ResetJointsMaxAcceleration", "ResetJointsMaxChange",
     "ResetJointsMaxTurn", "ResetMinChangeWeights", "ResetAllowedStatus")


@command("GetAllowedStatus", value=True)
def get_allowed_status(gw: Gateway, session: Session, args: Args) -> str:
    return " ".join((_config(gw, session)).allowed) + "\n"


@command("SetAllowedStatus", value=True)
def set_allowed_status(gw: Gateway, session: Session, args: Args) -> str | None:
    try:
        words = args.status()
    except ParseError:
        return error("incorrect status", with_false=False)
    _change(gw, session, "SetAllowedStatus", words=words)
    return None  # the original sends nothing on success; its clients do not read a reply


@command("GetRTSpeedControl", value=True)
def get_rt_speed_control(gw: Gateway, session: Session, args: Args) -> str:
    return f"{(_config(gw, session)).rt_speed_control}\n"


@command("SetRTSpeedControl")
def set_rt_speed_control(gw: Gateway, session: Session, args: Args) -> str:
    return boolean(_change(gw, session, "SetRTSpeedControl", (args.index(),)))


@command("SetKukaRTSpeed")
def set_kuka_rt_speed(gw: Gateway, session: Session, args: Args) -> str:
    if not gw.robot.rt:  # kr16, kr3, ad850, kaw_fs: arguments not even read
        return FALSE
    return boolean(_change(gw, session, "SetKukaRTSpeed", args.joints()))


def _adept_setting(name: str) -> Handler:
    # the original answers true to anything, on every robot type; only the Adept uses them
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        values = args.leading_doubles(2)
        if gw.robot.is_adept and values:
            _change(gw, session, name, values)
        return TRUE
    return handler


each(_adept_setting, "SetAdeptSpeed", "SetAdeptAccel", "SetAdeptFine", "SetAdeptCoarse")


# ====================================================================== kinematics
@command("ForwardCalc")
def forward_calc(gw: Gateway, session: Session, args: Args) -> str:
    numbers = args.leading_doubles(6)
    if not numbers:
        return FALSE
    config = gw.limits.config
    reply: ForwardCalcReply = gw.call(session, "kinematics", "forward_calc", ForwardCalcRequest(
        numbers=numbers, turn_min=config.turn_min, turn_max=config.turn_max))
    if reply.pose is None:
        return FALSE
    return fmt(reply.pose) + "\n" + reply.status + "\n"


def _backward(gw: Gateway, session: Session, args: Args) -> list[float] | None:
    pose = args.matrix()
    pattern = args.status()
    config = gw.limits.config
    reply: JointsReply = gw.call(session, "kinematics", "backward_calc", BackwardCalcRequest(
        pose=pose, pattern=pattern, current=gw.current(session), turn_min=config.turn_min,
        turn_max=config.turn_max, max_change=config.max_change, weights=config.weights))
    return reply.joints


@command("BackwardCalc", "GetJointsRowWise")
def backward_calc(gw: Gateway, session: Session, args: Args) -> str:
    joints = _backward(gw, session, args)
    return FALSE if joints is None else fmt(joints) + "\n"


@command("IsPossible")
def is_possible(gw: Gateway, session: Session, args: Args) -> str:
    """Reachable, and not in the way of the cell's safety zones (the planner checks the pose)."""
    joints = _backward(gw, session, args)
    if joints is None:
        return FALSE
    reply: Ack = gw.call(session, "planner", "pose_check", PoseCheck(joints=joints))
    return error(reply.zone) if reply.zone else boolean(reply.ok)


# ====================================================================== motion
def _move(gw: Gateway, session: Session, kind: MotionKind, **fields: Any) -> str:
    if session.routetest is not None:  # real moves are refused while route testing
        return FALSE
    state = gw.joints.get()  # the planner starts from it rather than follow the state itself
    # the client may leave mid-move: the move is abandoned, the session's end stops the robot
    try:
        reply: MoveReply = gw.call(session, "planner", "move", MoveRequest(
            kind=kind, start=state.q if state is not None else None, session=gw.session_id(session), **fields),
            abandon=session.client_gone)
    except CallAbandoned:
        raise ClientGone(f"the client left during {kind}: the robot stops") from None
    if reply.state is not None:
        gw.joints.update(reply.state)
    if not reply.ok and reply.busy:  # one robot, one motion: a ROS 2 goal runs
        return error(reply.busy)
    if not reply.ok and reply.error:  # the robot failed (not connected, link lost), not the command
        return error(f"driver: {reply.error}")
    if not reply.ok and reply.zone:  # the cell's safety zones: the client is told why
        return error(reply.zone)
    if not reply.ok and reply.reason:
        log.warning("%s refused: %s", kind, reply.reason)
    return boolean(reply.ok)


@command("MovePTPJoints")
def move_ptp_joints(gw: Gateway, session: Session, args: Args) -> str:
    return _move(gw, session, "MovePTPJoints", joints=args.joints())


@command("MovePTPJointsStatus")
def move_ptp_joints_status(gw: Gateway, session: Session, args: Args) -> str:
    joints = args.joints()
    return _move(gw, session, "MovePTPJointsStatus", joints=joints, pattern=args.status())


@command("MovePTPHomRowWise")
def move_ptp_hom(gw: Gateway, session: Session, args: Args) -> str:
    return _move(gw, session, "MovePTPHomRowWise", pose=args.matrix())


def _pose_status_move(kind: MotionKind) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        pose = args.matrix()
        return _move(gw, session, kind, pose=pose, pattern=args.status())
    return handler


command("MovePTPHomRowWiseStatusTurn")(_pose_status_move("MovePTPHomRowWiseStatusTurn"))
command("MoveMinChangeRowWiseStatus")(_pose_status_move("MoveMinChangeRowWiseStatus"))


# ---------------------------------------------------------------------- route test
@command("EnableRoutetest")
def enable_routetest(gw: Gateway, session: Session, args: Args) -> str:
    if session.routetest is not None:
        return FALSE
    session.routetest = list(gw.current(session))
    return TRUE


@command("DisableRoutetest")
def disable_routetest(gw: Gateway, session: Session, args: Args) -> str:
    session.routetest = None
    return TRUE


def _routetest(gw: Gateway, session: Session, request: MoveRequest) -> str:
    request.dry_run, request.start = True, session.routetest
    reply: MoveReply = gw.call(session, "planner", "move", request)
    if reply.ok and reply.joints is not None:
        session.routetest = list(reply.joints)
    return error(reply.zone) if reply.zone else boolean(reply.ok)


@command("RoutetestJoints")
def routetest_joints(gw: Gateway, session: Session, args: Args) -> str:
    if session.routetest is None:
        return FALSE
    return _routetest(gw, session, MoveRequest(kind="MovePTPJoints", joints=args.joints()))


@command("RoutetestRowWiseStatus")
def routetest_row_wise_status(gw: Gateway, session: Session, args: Args) -> str:
    if session.routetest is None:
        return FALSE
    pose = args.matrix()
    return _routetest(gw, session, MoveRequest(
        kind="RoutetestRowWiseStatus", pose=pose, pattern=args.status()))


# ---------------------------------------------------------------------- real-time (Alter) and LIN modes
def _mode(name: str) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        try:
            reply: Ack = gw.call(session, "planner", "mode", ModeRequest(command=name))
        except BusError as exc:
            if name != "DisableAlter" or not reached(exc):
                raise
            gw.alter = False  # the planner turns Alter off before it waits for the arm
            log.warning("%s failed: %s (%s)", name, exc.message, exc.code)
            return error(failure(name, exc) + "; Alter mode is off")
        if name in ("EnableAlter", "EnableAdeptAlter") and reply.ok:
            gw.alter = True
        elif name == "DisableAlter":
            gw.alter = False
        if reply.state is not None:  # at rest: where the next move starts (the publications lag)
            gw.joints.update(reply.state)
        if not reply.ok and reply.busy:  # one robot, one motion: a ROS 2 goal runs
            return error(reply.busy)
        if not reply.ok and reply.error:  # the robot failed (not connected, link lost)
            return error(f"driver: {reply.error}")
        return boolean(reply.ok)
    return handler


each(_mode, "EnableAlter", "DisableAlter", "EnableAdeptAlter", "EnableLin", "DisableLin")


def _alter_move(kind: MotionKind, parse: Callable[[Args], dict[str, Any]]) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        if not gw.alter:  # the original answers false without reading the arguments
            return FALSE
        return _move(gw, session, kind, **parse(args))
    return handler


def _pose_and_status(args: Args) -> dict[str, Any]:
    pose = args.matrix()
    return {"pose": pose, "pattern": args.status()}


def _alter_joints(relative: bool) -> Handler:
    """Joint targets go straight to the driver, one hop on the real-time path; the driver
    checks them (Alter mode, turn limits, max change). Cartesian ones need the planner's IK."""
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        if not gw.alter:  # the original answers false without reading the arguments
            return FALSE
        joints = args.joints()
        if session.routetest is not None:  # real moves are refused while route testing
            return FALSE
        config = _config(gw, session)
        reply: Ack = gw.call(session, "driver", "alter_target", AlterTarget(
            q=joints, synchronized=config.rt_speed_control == 0, relative=relative))
        if not reply.ok and reply.error:  # the robot failed (not connected, link lost)
            return error(f"driver: {reply.error}")
        if not reply.ok and reply.zone:  # the cell's safety zones: the client is told why
            return error(reply.zone)
        if not reply.ok:
            log.warning("Alter target refused: %s", reply.reason)
        return boolean(reply.ok)
    return handler


command("MoveRTJoints")(_alter_joints(relative=False))
command("MoveRTHomRowWise")(_alter_move("MoveRTHomRowWise", lambda a: {"pose": a.matrix()}))
command("MoveRTHomRowWiseStatus")(_alter_move("MoveRTHomRowWiseStatus", _pose_and_status))
command("DoAlterJoint")(_alter_joints(relative=True))
command("DoAlterCart")(_alter_move("DoAlterCart", lambda a: {"pose": a.doubles(6, "joints")}))


@command("MoveLINHomRowWise")
def move_lin(gw: Gateway, session: Session, args: Args) -> str:
    # the planner knows whether LIN mode is on; without it the answer is false
    try:
        pose = args.matrix()
    except ParseError:
        return FALSE  # the original answers false without reading arguments when LIN is off
    return _move(gw, session, "MoveLINHomRowWise", pose=pose)


# ====================================================================== gripper and Adept
#: How many lines each gripper command answers on the Adept, ``true``/``false`` included:
#: the protocol description's examples (section 3.4), which clients written against the
#: original with its serial gripper read as a fixed count (rob-chess reads three lines for
#: GripperGoHome and GripperMoveToPosition and checks the third is ``true``). A failure
#: answers as many lines, the last two being ``ERROR: <reason>`` and ``false``, so such a
#: client never waits for a line that does not come, nor falls a reply behind.
GRIPPER_REPLY_LINES = {"HasGripper": 1, "GripperMove": 2, "GripperGoHome": 3, "GripperMoveToPosition": 3}


def _where(position: float | None) -> str:
    """The informational line saying where the jaws are (never a bare number)."""
    return "Gripper position unknown" if position is None else f"Gripper at {position:.4f} m"


def _gripper_announcement(name: str, value: float | None) -> str:
    """The first line of a successful move: what the gripper was told to do."""
    if name == "GripperMove":
        return f"Start moving with amperage {value:.3f}"  # the original's words (protocol 3.4)
    if name == "GripperGoHome":
        return "Start moving to home position"
    return f"Start moving to position {value:.4f} m"


def _gripper_failure(name: str, reason: str, info: str) -> str:
    """``ERROR: <reason>`` and ``false`` after as many ``info`` lines as make the command's
    line count (GRIPPER_REPLY_LINES)."""
    lines = GRIPPER_REPLY_LINES[name]
    if lines == 1:  # HasGripper: the one line every one-line command gets when a service fails
        return f"ERROR: {reason}\n"
    return "".join(info + "\n" for _ in range(lines - 2)) + error(reason)


def _gripper(name: str, needs_value: bool) -> Handler:
    def handler(gw: Gateway, session: Session, args: Args) -> str:
        if not gw.robot.is_adept:  # the original: false, arguments not read
            return FALSE
        value = None
        if needs_value:
            value = args.double()
            if value is None:
                return _gripper_failure(name, "incorrect value", "Gripper not moved")
        try:
            reply: GripperReply = gw.call(session, "gripper", "command", GripperCommand(command=name, value=value))
        except BusError as exc:
            log.warning("%s failed: %s (%s)", name, exc.message, exc.code)
            return _gripper_failure(name, exc.message, _where(None))
        if name == "HasGripper":
            return boolean(reply.ok)
        if not reply.ok:
            return _gripper_failure(name, reply.reason or f"{name} failed", _where(reply.position))
        lines = [_gripper_announcement(name, value), _where(reply.position)]
        return "".join(line + "\n" for line in lines[:GRIPPER_REPLY_LINES[name] - 1]) + TRUE
    return handler


command("HasGripper")(_gripper("HasGripper", False))
command("GripperGoHome")(_gripper("GripperGoHome", False))
command("GripperMove")(_gripper("GripperMove", True))
command("GripperMoveToPosition")(_gripper("GripperMoveToPosition", True))


@command("DirectAdeptCmd")
def direct_adept_cmd(gw: Gateway, session: Session, args: Args) -> str:
    """The V+ SIGNAL instruction (``signal 5, -6``) reaches the Adept's digital outputs, by
    default: it switches outputs and nothing else, and clients (RobPraktikum's suction cup)
    need it unchanged. Any other V+ instruction has no channel to the controller."""
    if not gw.robot.is_adept:  # the original: false, arguments not read
        return FALSE
    try:
        signals = parse_signal(args.text)
    except SignalError as exc:
        return error(f"DirectAdeptCmd: {exc}; nothing was switched")
    if signals is not None:
        ack: Ack = gw.call(session, "driver", "signal", SignalRequest(signals=signals))
        if not ack.ok:
            return error(f"driver: {ack.error}" if ack.error else f"DirectAdeptCmd: {ack.reason}")
        return TRUE  # the protocol description's reply to a DirectAdeptCmd that ran
    if not gw.options.allow_direct_adept_cmd:
        return error("DirectAdeptCmd is disabled on this server (it forwards raw controller "
                     "commands; start the gateway with --allow-direct-adept-cmd)")
    # neither link has a channel for text: the V+ server program's ports carry trajectory
    # points, state and I/O signals only (deploy/adept/README.md)
    return error("DirectAdeptCmd: raw V+ commands cannot reach the controller (neither the simulation "
                 "nor the simple_message link has a V+ command channel; only SIGNAL is carried); "
                 "nothing was sent")


# ====================================================================== rob6's own
@command("GetCell", value=True)
def get_cell(gw: Gateway, session: Session, args: Args) -> str:
    """The driver's cell (its safety zones, tool and self-collision settings, ``rob6.cell``)
    as one line of JSON: the ``Cell`` message with every field, defaults included, so a
    client needs no knowledge of them; ASCII (``\\u`` escapes), as every reply is latin-1.
    The original has no such command (it answers ``ERROR: GetCell``)."""
    cell: Cell = gw.call(session, "driver", "cell", Empty())
    return json.dumps(_every_field(cell), separators=(",", ":")) + "\n"


def _every_field(value: Any) -> Any:
    """A message as plain JSON values, its fields at their defaults included (the bus's
    encoding leaves those out)."""
    if isinstance(value, msgspec.Struct):
        return {name: _every_field(field) for name, field in msgspec.structs.asdict(value).items()}
    if isinstance(value, list):
        return [_every_field(item) for item in value]
    return value
