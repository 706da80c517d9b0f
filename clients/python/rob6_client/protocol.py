"""The rob6server protocol without I/O: argument encoding, the command table, reply parsing.

A command's exchange is a generator that yields what it needs from the connection
(``Send``, ``READ``, ``MAYBE_FALSE``, ``Pause``) and returns the parsed value. The
blocking ``Robot``, the asyncio ``AsyncRobot`` and ``parse_reply`` (recorded replies)
drive the very same generators, so only the I/O differs between them.

Wire format (rob6server 0.1.01): one command per line, numbers and words separated by
blanks; every reply line ends in ``\\n``; a pose is the upper 3x4 of the homogeneous
matrix, row by row (``r11 r12 r13 x r21 ... z``), millimetres; joints in degrees.
"""

from __future__ import annotations

import inspect
import json
import logging
import math
import operator
import re
from collections.abc import Callable, Generator, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, TypeVar

from .errors import Rob6ConnectionError, Rob6Error, Rob6ProtocolError

log = logging.getLogger("rob6_client")

# ---------------------------------------------------------------------------- values

Joints = tuple[float, float, float, float, float, float]
"""Six joint values (degrees, or per-joint limits), as the server printed them."""

PoseLike = Sequence[float] | Sequence[Sequence[float]]
"""12 numbers row by row, 3 rows of 4, or a 4x4 homogeneous matrix (e.g. a numpy array)."""

StatusLike = str | Sequence[str]
"""``"noflip up lefty"`` or its words; 1-3 words, one per category, the rest toggle."""


class Pose(NamedTuple):
    """The 3x4 upper part of a homogeneous matrix, row by row, as on the wire (mm)."""

    r11: float
    r12: float
    r13: float
    x: float
    r21: float
    r22: float
    r23: float
    y: float
    r31: float
    r32: float
    r33: float
    z: float

    @property
    def rows(self) -> tuple[tuple[float, ...], ...]:
        return self[0:4], self[4:8], self[8:12]

    @property
    def position(self) -> tuple[float, float, float]:
        return self.x, self.y, self.z


class Status(NamedTuple):
    """A configuration (``noflip up lefty``) or a pattern that may contain toggle words."""

    hand: str
    elbow: str
    arm: str

    def __str__(self) -> str:
        return " ".join(self)


class PingResult(NamedTuple):
    """``PingRobot``: mean round trip (s), robot and server time zero, drift fit c1, c2."""

    mean_rtt: float
    robot_t0: float
    server_t0: float
    c1: float
    c2: float


HAND = ("flip", "noflip", "toggleHand", "noToggleHand")
ELBOW = ("up", "down", "toggleElbow", "noToggleElbow")
ARM = ("lefty", "righty", "toggleArm", "noToggleArm")
CATEGORIES = (HAND, ELBOW, ARM)
ANY_STATUS = Status("toggleHand", "toggleElbow", "toggleArm")


def normalize_status(status: StatusLike) -> Status:
    """1-3 status words in any order -> hand, elbow, arm; a missing category is toggle...
    (what the server does with them, REFERENCE.md 5.3)."""
    words = status.split() if isinstance(status, str) else list(status)
    if not 1 <= len(words) <= 3:
        raise ValueError(f"a status has 1 to 3 words, got {words!r}")
    chosen: dict[int, str] = {}
    for word in words:
        category = next((i for i, vocab in enumerate(CATEGORIES) if word in vocab), None)
        if category is None:
            raise ValueError(f"unknown status word {word!r}; one of {' '.join(HAND + ELBOW + ARM)}")
        if category in chosen:
            raise ValueError(f"two status words of one category: {chosen[category]!r} and {word!r}")
        chosen[category] = word
    return Status(*(chosen.get(i, ANY_STATUS[i]) for i in range(3)))


def pose_values(pose: PoseLike) -> list[float]:
    """12 floats from a flat pose, 3 rows of 4 or a 4x4 homogeneous matrix."""
    if isinstance(pose, (str, bytes)):
        raise TypeError("a pose is 12 numbers or a 3x4/4x4 matrix, not a string")
    items: list[Any] = list(pose)
    if items and _iterable(items[0]):
        rows = [[_finite(v) for v in row] for row in items]
        if len(rows) == 4 and [round(v, 9) for v in rows[3]] == [0.0, 0.0, 0.0, 1.0]:
            rows = rows[:3]
        if len(rows) != 3 or any(len(row) != 4 for row in rows):
            raise ValueError("a pose matrix has 3 rows of 4 (or 4 rows, the last 0 0 0 1)")
        return [v for row in rows for v in row]
    if len(items) != 12:
        raise ValueError(f"a pose has 12 numbers (row by row), got {len(items)}")
    return [_finite(v) for v in items]


def _iterable(value: Any) -> bool:
    try:
        iter(value)
    except TypeError:
        return False
    return True


def _finite(value: Any) -> float:
    if isinstance(value, (str, bytes)):
        raise TypeError(f"expected a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"numbers must be finite, got {number}")
    return number


def _numbers(values: Iterable[float], count: int) -> list[float]:
    if isinstance(values, (str, bytes)):
        raise TypeError(f"expected {count} numbers, not a string")
    numbers = [_finite(v) for v in values]
    if len(numbers) != count:
        raise ValueError(f"expected {count} numbers, got {len(numbers)}")
    return numbers


def _text(value: str) -> str:
    if not isinstance(value, str) or not value.strip() or any(c in value for c in "\r\n\0"):
        raise ValueError("a non-empty single line of text is needed")
    return value


# repr() is the shortest exact form and parses as C++ `istream >> double` does (1e-05, -0.0)
ENCODERS: dict[str, tuple[Callable[[Any], str], str]] = {  # kind -> (encoder, annotation)
    "joints": (lambda v: " ".join(map(repr, _numbers(v, 6))), "Sequence[float]"),
    "pose": (lambda v: " ".join(map(repr, pose_values(v))), "PoseLike"),
    "status": (lambda v: str(normalize_status(v)), "StatusLike"),
    "int": (lambda v: str(operator.index(v)), "int"),
    "float": (lambda v: repr(_finite(v)), "float"),
    "text": (_text, "str"),
}

# ---------------------------------------------------------------------------- exchanges


@dataclass(frozen=True)
class Send:
    line: str  # without the "\n"


@dataclass(frozen=True)
class Pause:
    seconds: float


class _Read:
    """Wait for the next reply line (without its "\\n")."""


class _MaybeFalse:
    """Consume a ``false`` line if one is already there or arrives within a moment."""


READ, MAYBE_FALSE = _Read(), _MaybeFalse()
MAYBE_FALSE_GRACE_S = 0.05  # rob6 writes a reply in one go: a following `false` is already there
ALLOWED_STATUS_PAUSE_S = 0.02  # lets the original read SetAllowedStatus before the next write

R = TypeVar("R")
#: one command's exchange: yields actions (READ, Send, Pause, MAYBE_FALSE), is sent what each
#: produced (a line, a bool, None) and returns the reply's value, of type R
ExchangeOf = Generator[Any, Any, R]
Exchange = ExchangeOf[Any]  # the value's type is the command's (``Reply.returns``, _methods.pyi)

# the parse errors the original sends with a `false` line after them (REFERENCE.md 4)
_PARSE_ERRORS = {"incorrect joints", "incorrect matrix", "incorrect status", "incorrect value"}


def _line(name: str) -> Exchange:
    """The next line; ``ERROR: ...`` (and its ``false``) becomes Rob6Error."""
    line = yield READ
    if not line.startswith("ERROR:"):
        return line
    message = line[6:].removeprefix(" ")
    if message in _PARSE_ERRORS:
        if (yield READ) != "false":
            raise Rob6ProtocolError(f"{name}: `ERROR: {message}` without its `false` line")
    else:
        # rob6's own errors: `<service> unavailable` has no `false`, a gripper failure has one
        yield MAYBE_FALSE
    raise Rob6Error(name, message)


def _unexpected(name: str, line: str) -> Rob6ProtocolError:
    return Rob6ProtocolError(f"{name}: unexpected reply {line!r}")


def _floats(name: str, line: str, count: int) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in line.split())
    except ValueError:
        raise _unexpected(name, line) from None
    if len(values) != count:
        raise _unexpected(name, line)
    return values


def _status(name: str, line: str) -> Status:
    words = line.split()
    if len(words) != 3 or any(w not in vocab for w, vocab in zip(words, CATEGORIES, strict=True)):
        raise _unexpected(name, line)
    return Status(*words)


def _bool(name: str, line: str) -> bool:
    if line not in ("true", "false"):
        raise _unexpected(name, line)
    return line == "true"


def _scalar(convert: Callable[[str], object]) -> Callable[[str], Exchange]:
    def parse(name: str) -> Exchange:
        line = yield from _line(name)
        try:
            return convert(line)
        except ValueError:
            raise _unexpected(name, line) from None
    return parse


def parse_bool(name: str) -> Exchange:
    return _bool(name, (yield from _line(name)))


def parse_bool_after_info(name: str) -> Exchange:
    """Gripper commands: lines such as ``Start moving with amperage -1.000`` or ``Gripper at
    0.0400 m`` (logged), then true/false; on a failure ``ERROR: <reason>`` and ``false``."""
    while True:
        line = yield from _line(name)
        if line in ("true", "false"):
            return line == "true"
        log.info("%s: %s", name, line)


def parse_joints(name: str) -> Exchange:
    return _floats(name, (yield from _line(name)), 6)


def parse_joints_or_none(name: str) -> Exchange:
    line = yield from _line(name)
    return None if line == "false" else _floats(name, line, 6)


def parse_pose(name: str) -> Exchange:
    return Pose(*_floats(name, (yield from _line(name)), 12))


def parse_status(name: str) -> Exchange:
    return _status(name, (yield from _line(name)))


def parse_forward(name: str) -> Exchange:
    """Two lines (matrix, status), or ``false`` outside the limits."""
    line = yield from _line(name)
    if line == "false":
        return None
    pose = Pose(*_floats(name, line, 12))
    return pose, _status(name, (yield READ))


def parse_ping(name: str) -> Exchange:
    line = yield from _line(name)
    return None if line == "-1" else PingResult(*_floats(name, line, 5))


def parse_json_object(name: str) -> Exchange:
    """One line of JSON, an object (rob6's ``GetCell``)."""
    line = yield from _line(name)
    try:
        value = json.loads(line)
    except ValueError:
        raise _unexpected(name, line) from None
    if not isinstance(value, dict):
        raise _unexpected(name, line)
    return value


def parse_set_allowed_status(name: str) -> Exchange:
    """The server answers nothing on success and only ``ERROR: incorrect status`` on failure,
    so a CM_PING after it tells the two apart: lines before the ``PONG`` are its error."""
    yield Pause(ALLOWED_STATUS_PAUSE_S)
    yield Send("CM_PING")
    error = None
    while (line := (yield READ)) != "PONG":
        if line.startswith("ERROR:"):
            error = error or line[6:].removeprefix(" ")
        elif line != "false":
            raise _unexpected(name, line)
    if error is not None:
        raise Rob6Error(name, error)


def _parse_bye(*expected: str) -> Callable[[str], Exchange]:
    def parse(name: str) -> Exchange:
        line = yield from _line(name)
        for i, text in enumerate(expected):
            if i:
                line = yield READ
            if line != text:
                raise _unexpected(name, line)
    return parse


@dataclass(frozen=True)
class Reply:
    parse: Callable[[str], Exchange]
    returns: str  # annotation of the method's result
    closes: bool = False  # the server closes the connection after it


BOOL = Reply(parse_bool, "bool")
BOOL_INFO = Reply(parse_bool_after_info, "bool")
TEXT = Reply(_scalar(str), "str")
INT = Reply(_scalar(int), "int")
FLOAT = Reply(_scalar(float), "float")
JOINTS = Reply(parse_joints, "Joints")
JOINTS_OR_NONE = Reply(parse_joints_or_none, "Joints | None")
POSE = Reply(parse_pose, "Pose")
STATUS = Reply(parse_status, "Status")
FORWARD = Reply(parse_forward, "tuple[Pose, Status] | None")
PING = Reply(parse_ping, "PingResult | None")
JSON_OBJECT = Reply(parse_json_object, "dict[str, Any]")
ALLOWED = Reply(parse_set_allowed_status, "None")
BYE = Reply(_parse_bye("bye!"), "None", closes=True)
SHUTDOWN = Reply(_parse_bye("bye!", "shutting down ..."), "None", closes=True)


def handshake() -> ExchangeOf[str]:
    """Greeting, ``Hello Robot``, ``accepted``; returns the greeting."""
    greeting: str = yield READ
    if greeting.startswith("ERROR:"):  # rob6: server busy, access denied
        raise Rob6ConnectionError(f"the server refused the connection: {greeting[6:].strip()}")
    if not greeting.startswith("welcome to rob6server"):
        raise Rob6ProtocolError(f"not a rob6server greeting: {greeting!r}")
    yield Send("Hello Robot")
    reply = yield READ
    if reply != "accepted":
        raise Rob6ConnectionError(f"handshake failed: the server answered {reply!r} to 'Hello Robot'")
    return greeting


# ---------------------------------------------------------------------------- the command table


class Param(NamedTuple):
    name: str
    kind: str
    default: Any = inspect.Parameter.empty


@dataclass(frozen=True)
class Command:
    name: str  # on the wire
    params: tuple[Param, ...]
    reply: Reply
    doc: str
    long: bool = False  # waits for a motion: the Robot's move_timeout applies

    @property
    def method(self) -> str:
        return re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", self.name).lower()

    def encode(self, values: Sequence[Any]) -> str:
        """The command line (without "\\n"); raises ValueError/TypeError on bad arguments, so
        the original never sees a command missing arguments (it would wait for them)."""
        parts = [self.name]
        for param, value in zip(self.params, values, strict=True):
            try:
                parts.append(ENCODERS[param.kind][0](value))
            except (TypeError, ValueError) as exc:
                raise type(exc)(f"{self.method}({param.name}=...): {exc}") from None
        return " ".join(parts)

    def exchange(self, line: str) -> Exchange:
        yield Send(line)
        return (yield from self.reply.parse(self.name))


def _params(spec: str) -> tuple[Param, ...]:
    params = []
    for item in spec.split():
        name, _, kind = item.partition(":")
        kind, _, default = kind.partition("=")
        params.append(Param(name, kind, inspect.Parameter.empty if not default else
                            (int(default) if kind == "int" else float(default))))
    return tuple(params)


def _table(*rows: tuple[str, str, Reply, str] | tuple[str, str, Reply, str, bool]) -> dict[str, Command]:
    commands = {}
    for name, params, reply, doc, *long in rows:
        commands[name] = Command(name, _params(params), reply, doc, bool(long and long[0]))
    return commands


LONG = True  # the command answers when the motion is over
# name, parameters (name:kind[=default]), reply, doc[, LONG]: one row per protocol command
COMMANDS: dict[str, Command] = _table(
    # management
    ("GetRobot", "", TEXT, "The robot type: ad850, kaw_fs, kr3, kr3rt, kr16 or kr16rt."),
    ("IsAdept", "", BOOL, "Whether the robot is an Adept (ad850)."),
    ("IsKuka", "", BOOL, "Whether the robot is a KUKA (kr3, kr3rt, kr16, kr16rt)."),
    ("IsKawa", "", BOOL, "Whether the robot is a Kawasaki (kaw_fs)."),
    ("IsKR3", "", BOOL, "Whether the robot is a KUKA KR3 (kr3, kr3rt)."),
    ("IsKR16", "", BOOL, "Whether the robot is a KUKA KR16 (kr16, kr16rt)."),
    ("GetVersion", "", TEXT, "The server's version (``0.1.01``)."),
    ("GetTimestamp", "", FLOAT, "The server's clock, seconds since the epoch (ms resolution)."),
    ("CM_PING", "", TEXT, "A round trip to the server: returns ``PONG``."),
    ("GetVerbosity", "", INT, "The server's log level 0-4."),
    ("SetVerbosity", "level:int", BOOL, "Set the server's log level 0-4; False out of range."),
    ("Quit", "", BYE, "End the session (the server says ``bye!`` and closes the connection)."),
    ("Shutdown", "", SHUTDOWN, "End the session and stop the server."),
    ("PingRobot", "n:int=10 wait_ms:float=0", PING,
     "n round trips server -> robot, wait_ms apart: PingResult, or None (``-1``).", LONG),
    # position
    ("GetPositionJoints", "", JOINTS, "The current joint angles (degrees)."),
    ("GetPositionHomRowWise", "", POSE, "The current pose (forward kinematics of the joints)."),
    ("GetStatus", "", STATUS, "The current configuration, e.g. ``noflip up lefty``."),
    # limits: speeds in degrees per 12 ms cycle, accelerations per cycle squared
    ("GetJointsMaxSpeed", "", JOINTS, "Maximum joint speeds (degrees per 12 ms cycle)."),
    ("GetJointsMaxAcceleration", "", JOINTS, "Maximum joint accelerations (degrees per cycle²)."),
    ("GetJointsMaxChange", "", JOINTS, "Largest joint change one move may make (degrees)."),
    ("GetJointsMaxTurnMax", "", JOINTS, "Upper joint limits (degrees, strict)."),
    ("GetJointsMaxTurnMin", "", JOINTS, "Lower joint limits (degrees, strict)."),
    ("GetMinChangeWeights", "", JOINTS, "Per-joint weights of the min-change configuration choice."),
    ("SetJointsMaxSpeed", "values:joints", BOOL,
     "Set the maximum speeds (0..10x default); False on an invalid value (joints before it are set)."),
    ("SetJointsMaxAcceleration", "values:joints", BOOL,
     "Set the maximum accelerations (0..0.02); False on an invalid value (joints before it are set)."),
    ("SetJointsMaxChange", "values:joints", BOOL, "Set the max change per move (>= 0); False: nothing set."),
    ("SetJointsMaxTurnMax", "values:joints", BOOL, "Set the upper joint limits (not checked)."),
    ("SetJointsMaxTurnMin", "values:joints", BOOL, "Set the lower joint limits (not checked)."),
    ("SetMinChangeWeights", "values:joints", BOOL, "Set the min-change weights (> 0); False: nothing set."),
    ("SetSingleJointMaxSpeed", "joint:int value:float", BOOL, "Set one joint's (1-6) maximum speed."),
    ("SetSingleJointMaxAcceleration", "joint:int value:float", BOOL,
     "Set one joint's (1-6) maximum acceleration."),
    ("SetSingleJointMaxChange", "joint:int value:float", BOOL, "Set one joint's (1-6) max change (> 0)."),
    ("SetSingleJointMaxTurnMax", "joint:int value:float", BOOL, "Set one joint's (1-6) upper limit."),
    ("SetSingleJointMaxTurnMin", "joint:int value:float", BOOL, "Set one joint's (1-6) lower limit."),
    ("ResetJointsMaxSpeed", "", BOOL, "Restore the default maximum speeds."),
    ("ResetJointsMaxAcceleration", "", BOOL, "Restore the default maximum accelerations."),
    ("ResetJointsMaxChange", "", BOOL, "Restore the start-up max changes."),
    ("ResetJointsMaxTurn", "", BOOL, "Restore both joint limit sets."),
    ("ResetMinChangeWeights", "", BOOL, "Restore the min-change weights (4 1 1 1 1 1)."),
    ("ResetAllowedStatus", "", BOOL, "Allow every configuration again (toggle words)."),
    ("GetAllowedStatus", "", STATUS, "The configurations moves may end in, e.g. ``noflip toggleElbow toggleArm``."),
    ("SetAllowedStatus", "status:status", ALLOWED,
     "Restrict every move to configurations matching status; raises Rob6Error if refused."),
    ("GetRTSpeedControl", "", INT, "1: real-time moves ramp their speed; 0: joints arrive together."),
    ("SetRTSpeedControl", "on:int", BOOL, "Set RTSpeedControl (0 or 1); False otherwise."),
    ("SetKukaRTSpeed", "values:joints", BOOL, "Joint speeds of the KUKA RT interface (kr3rt, kr16rt)."),
    ("SetAdeptSpeed", "percent:float", BOOL, "Adept speed in percent of the maximum (up to 120)."),
    ("SetAdeptAccel", "accel:float decel:float", BOOL, "Adept acceleration and deceleration in percent."),
    ("SetAdeptFine", "percent:float", BOOL, "Adept fine positioning with percent of the default accuracy."),
    ("SetAdeptCoarse", "percent:float", BOOL, "Adept coarse positioning with percent of the default accuracy."),
    # kinematics
    ("ForwardCalc", "q:joints", FORWARD,
     "Forward kinematics: (pose, status), or None when q is not strictly inside the joint limits."),
    ("BackwardCalc", "pose:pose status:status", JOINTS_OR_NONE,
     "Inverse kinematics for the configuration status: joints, or None (unreachable, limits, max change "
     "from the current position)."),
    ("GetJointsRowWise", "pose:pose status:status", JOINTS_OR_NONE, "The same as backward_calc."),
    ("IsPossible", "pose:pose status:status", BOOL, "Whether backward_calc has a solution."),
    # motion
    ("MovePTPJoints", "q:joints", BOOL,
     "Point-to-point move to q; False when refused (limits, max change, allowed status, route test, "
     "Alter or LIN mode).", LONG),
    ("MovePTPJointsStatus", "q:joints status:status", BOOL,
     "Point-to-point move to q if its configuration matches status.", LONG),
    ("MovePTPHomRowWise", "pose:pose", BOOL,
     "Point-to-point move to a pose in a configuration the allowed status admits.", LONG),
    ("MovePTPHomRowWiseStatusTurn", "pose:pose status:status", BOOL,
     "Point-to-point move to a pose in the configuration status.", LONG),
    ("MoveMinChangeRowWiseStatus", "pose:pose status:status", BOOL,
     "Point-to-point move to a pose: of the configurations status admits, the least joint change.", LONG),
    ("EnableRoutetest", "", BOOL, "Route test: moves go to a virtual position; False if already on."),
    ("DisableRoutetest", "", BOOL, "End the route test (positions are real again)."),
    ("RoutetestJoints", "q:joints", BOOL, "Route test move to q (checks only)."),
    ("RoutetestRowWiseStatus", "pose:pose status:status", BOOL, "Route test move to a pose (checks only)."),
    ("EnableAlter", "", BOOL, "Alter (real-time) mode; prefer the alter() context manager."),
    ("DisableAlter", "", BOOL, "Leave Alter mode."),
    ("EnableAdeptAlter", "", BOOL, "Hard real-time Alter mode of the Adept (serveralter)."),
    ("EnableLin", "", BOOL, "LIN mode: move_lin_hom_row_wise moves on straight lines."),
    ("DisableLin", "", BOOL, "Leave LIN mode."),
    ("MoveRTJoints", "q:joints", BOOL, "Alter mode: new joint target; answers at once."),
    ("MoveRTHomRowWise", "pose:pose", BOOL, "Alter mode: new pose target in the current configuration."),
    ("MoveRTHomRowWiseStatus", "pose:pose status:status", BOOL, "Alter mode: new pose target in status."),
    ("DoAlterJoint", "delta:joints", BOOL, "Alter mode: target = current joints + delta."),
    ("DoAlterCart", "delta:joints", BOOL,
     "Alter mode: shift the current pose by dx dy dz (mm) and rotate by rx ry rz (deg, base axes)."),
    ("MoveLINHomRowWise", "pose:pose", BOOL, "LIN mode: straight-line move to a pose.", LONG),
    # gripper and Adept
    ("HasGripper", "", BOOL, "Whether the Adept's serial gripper is connected and working."),
    ("GripperGoHome", "", BOOL_INFO, "Move the gripper to its reference position (about 4 cm open).", LONG),
    ("GripperMove", "current:float", BOOL_INFO,
     "Move the gripper with this current (A): negative closes, positive opens.", LONG),
    ("GripperMoveToPosition", "position:float", BOOL_INFO, "Move the gripper to an opening (m).", LONG),
    ("DirectAdeptCmd", "command:text", BOOL_INFO,
     "Run a V+ command on the Adept controller (rob6: only ``signal 5, -6``, V+ SIGNAL).", LONG),
    # rob6's own (ROB6_ONLY)
    ("GetCell", "", JSON_OBJECT,
     "The robot's cell, what rob6 guards every motion against: ``margin_mm``, ``zones`` (each with "
     "``name``, ``keep`` out/in, a ``half_space`` {point, normal} or a ``box`` {min, max, rpy_deg}, "
     "``ignore``, its own ``margin_mm`` or None), the ``tool``'s spheres and capsules on the flange "
     "(``name``, ``radius``, ``a``, ``b``; out of the flange along -z), ``self_collision``, "
     "``arm_padding_mm``, ``allowed_pairs``, the ``source`` file, ``from_file`` (false: the default "
     "cell) and ``sha256`` (of the file's bytes: compare it to know the cell changed); lengths in mm, "
     "robot base frame."),
)
#: the commands rob6 has and the original rob6server has not
ROB6_ONLY = frozenset({"GetCell"})

# Where the original rob6server 0.1.01 (REFERENCE.md) differs from rob6 (docs/COMPATIBILITY.md)
ORIGINAL: dict[str, str] = {
    "GetRobot": "kaw_fs answers ``no robot``.",
    "Shutdown": "Always allowed. rob6 allows it only with --allow-shutdown, otherwise Rob6Error.",
    "PingRobot": "Always ``-1`` (None) in dummy mode; rob6 measures the round trip to its driver.",
    "SetAllowedStatus": "Sends nothing on success, so this method sends CM_PING after a short pause "
                        "to learn the outcome; over a slow network both may reach the original in "
                        "one read, it then runs only the first and the call times out.",
    "SetKukaRTSpeed": "Always False (kr3rt/kr16rt check the values, then answer False too).",
    "SetAdeptSpeed": "True for anything, no effect in dummy mode.",
    "EnableAlter": "kr16: no reply and the server process dies about 1.2 s later (Rob6Timeout or "
                   "ConnectionError); other types: False in dummy mode. rob6: True on every type.",
    "EnableAdeptAlter": "False. rob6: True on ad850.",
    "EnableLin": "kr16: True, but the next move crashes the server. rob6: LIN moves work.",
    "MoveLINHomRowWise": "False (kr16: crash after EnableLin).",
    "MoveRTJoints": "False unless Alter mode is on, which the original never granted in dummy mode.",
    "GripperGoHome": "ad850 in dummy mode never answers, nor anything after it: Rob6Timeout.",
    "DirectAdeptCmd": "ad850 in dummy mode never answers (Rob6Timeout). rob6 switches digital outputs "
                      "with ``signal n[, m ...]`` (True) and refuses every other V+ command with Rob6Error.",
    "GetCell": "An unknown command: it answers ``ERROR: GetCell`` (Rob6Error).",
}
for _name in ("MoveRTHomRowWise", "MoveRTHomRowWiseStatus", "DoAlterJoint", "DoAlterCart"):
    ORIGINAL[_name] = ORIGINAL["MoveRTJoints"]
for _name in ("GripperMove", "GripperMoveToPosition"):
    ORIGINAL[_name] = ORIGINAL["GripperGoHome"]
for _name in ("SetAdeptAccel", "SetAdeptFine", "SetAdeptCoarse"):
    ORIGINAL[_name] = ORIGINAL["SetAdeptSpeed"]


def docstring(command: Command) -> str:
    doc = command.doc
    if command.name in ORIGINAL:
        doc += "\n\nOriginal rob6server: " + ORIGINAL[command.name]
    return doc + f"\n\nProtocol: ``{command.name}``."


# ---------------------------------------------------------------------------- offline parsing


def parse_reply(command: str, reply: str) -> Any:
    """Parse a complete reply text (lines ending in "\\n") as ``command``'s, the way Robot does.

    Raises Rob6Error for an ``ERROR:`` reply and Rob6ProtocolError when the text is not a
    complete reply of ``command`` or has lines left over. For SetAllowedStatus the text
    includes the ``PONG`` of the CM_PING the library sends after it.
    """
    spec = COMMANDS[command]
    if reply and not reply.endswith("\n"):
        raise Rob6ProtocolError(f"{command}: the reply's last line is not complete")
    return run_offline(command, spec.reply.parse(spec.name), reply.split("\n")[:-1])


def run_offline(name: str, exchange: Exchange, lines: list[str]) -> Any:
    """Drive an exchange with reply lines given in advance (sending nothing)."""
    lines = list(lines)
    error = None
    value: Any = None
    try:
        action = next(exchange)
        while True:
            if action is READ:
                if not lines:
                    raise Rob6ProtocolError(f"{name}: the reply is incomplete")
                action = exchange.send(lines.pop(0))
            elif action is MAYBE_FALSE:
                consumed = bool(lines) and lines[0] == "false"
                del lines[:consumed]
                action = exchange.send(consumed)
            else:  # Send, Pause: nothing to do offline
                action = exchange.send(None)
    except StopIteration as stop:
        value = stop.value
    except Rob6Error as exc:
        error = exc
    if lines:
        raise Rob6ProtocolError(f"{name}: lines left over: {lines!r}")
    if error is not None:
        raise error
    return value
