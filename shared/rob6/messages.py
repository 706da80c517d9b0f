"""Typed message schemas of the rob6 bus (JSON payloads, schema version 1).

Every request and reply travels in an envelope that carries the schema version and
the correlation id (``cid``) of the client command that caused it, so one client
command can be followed through every inner request (and in the recordings).

``OPS`` lists every request/reply operation: ``(service, operation) -> (request
type, reply type)``. The bus validates both directions against these types, so a
malformed payload is refused at the boundary with a structured error instead of
surfacing as a traceback somewhere else.

Units are the protocol's: millimetres, degrees, speeds in degrees per 12 ms cycle.
A pose is the 3x4 matrix row-wise (12 numbers), a status pattern is three words in
hand/elbow/arm order (explicit, ``toggle…`` or ``noToggle…``).
"""

from __future__ import annotations

from typing import Generic, Literal, NamedTuple, TypeVar, get_args

import msgspec

from .deadlines import ANNOUNCE_S, CONFIG_CHANGE_S, IK_BATCH_S, QUICK_S, REMOTE_POSE_S

SCHEMA_VERSION = 1

T = TypeVar("T")

Joints = list[float]  # 6 values, degrees
Pose = list[float]  # 12 values, row-wise 3x4
Pattern = list[str]  # 3 words, hand/elbow/arm

#: A failed request's ``code``: no live instance, no answer in time, a bad argument, a
#: refusal, a crash in the handler, an operation the service does not have, a payload that
#: does not fit the schema, an answer from an instance that was not asked.
ErrorCode = Literal["unavailable", "timeout", "invalid", "rejected", "internal", "unknown_op", "schema",
                    "foreign"]

#: ``MoveRequest.kind``: the protocol command of a motion (RoutetestJoints travels as a
#: dry-run MovePTPJoints). The decoder refuses any other word, so a typo fails at once.
MotionKind = Literal[
    "MovePTPJoints",
    "MovePTPJointsStatus",
    "MovePTPHomRowWise",
    "MovePTPHomRowWiseStatusTurn",
    "MoveMinChangeRowWiseStatus",
    "RoutetestRowWiseStatus",
    "MoveLINHomRowWise",
    "MoveRTJoints",
    "MoveRTHomRowWise",
    "MoveRTHomRowWiseStatus",
    "DoAlterJoint",
    "DoAlterCart",
]
MOTION_KINDS: tuple[MotionKind, ...] = get_args(MotionKind)


class Struct(msgspec.Struct, kw_only=True, omit_defaults=True):
    """Base of every message body."""


# ---------------------------------------------------------------- envelopes
class ErrorBody(Struct):
    code: ErrorCode
    message: str


class RequestEnvelope(msgspec.Struct, Generic[T]):
    v: int
    cid: str
    body: T


class ReplyEnvelope(msgspec.Struct, Generic[T], omit_defaults=True):
    v: int
    cid: str
    ok: bool
    instance: str = ""  # who answered: the caller checks it is the instance it asked
    body: T | None = None
    error: ErrorBody | None = None


# ---------------------------------------------------------------- common
class Empty(Struct):
    pass


class Waiting(Struct):
    """An interim reply (``rob6.bus.Context.waiting``): the final one will take up to
    ``seconds`` more, because the service waits for ``what`` (the arm to stop...)."""

    seconds: float
    what: str


class Ack(Struct):
    ok: bool = True
    reason: str = ""  # why ok is False, for logs and recordings
    error: str = ""  # the plant failed, not the command (robot not connected, link lost): shown to the client
    #: the driver's state at rest, from an operation that waited for the arm to stop
    #: (DisableAlter, stop): where the next motion starts, newer than any publication before
    state: JointState | None = None
    #: refused because another kind of client owns the motion (a ROS 2 goal runs): shown to the client
    busy: str = ""
    #: refused or stopped by the cell's safety zones (rob6.cell): shown to the client
    zone: str = ""


# ---------------------------------------------------------------- driver
class PingReply(Struct):
    robot_time: float  # driver (robot controller) clock, seconds
    wall_time: float  # driver host epoch time, seconds


class JointState(Struct):
    """Published by the driver on ``rob6/<id>/driver/state`` every controller cycle; at rest
    (nothing but ``t`` and ``cycle`` changed) every ``REST_STATE_PERIOD_S`` (100 ms)."""

    t: float  # driver clock, seconds
    cycle: int
    q: Joints
    qd: Joints  # degrees per second
    moving: bool = False
    mode: str = "idle"  # idle | trajectory | alter | stopping | fault
    missed: int = 0  # controller cycles missed so far (the cycle came too late to run)
    link: str = "connected"  # the plant: connected | lost | waiting (the simulation is always connected)
    late: int = 0  # packets the robot controller counted late so far (RSI's Delay, summed over runs)
    q_actual: Joints | None = None  # where the robot reports it is (RSI's AIPos); None: the simulation
    instance: str = ""  # the driver instance that published it (one robot, one owner)
    #: the Adept's digital outputs switched so far, V+ SIGNAL style, by number: 5 on, -6 off
    outputs: list[int] = []


class Trajectory(Struct):
    """Positions sampled at the driver cycle (the planner's output); row 0 = the start."""

    dt: float  # sample period, seconds
    q: list[Joints]
    qd: list[Joints] | None = None  # deg/s: lets the driver stop from the exact state
    qdd: list[Joints] | None = None  # deg/s^2


class ExecuteRequest(Struct):
    trajectory: Trajectory
    wait: bool = True  # reply only after the robot arrived


class ExecuteReply(Struct):
    ok: bool
    reason: str = ""
    error: str = ""  # the plant failed, not the command (robot not connected, link lost)
    state: JointState | None = None  # at the end of the motion (or where it stopped)
    zone: str = ""  # stopped by the cell's safety zones (rob6.cell): shown to the client


class LimitsUpdate(Struct):
    """Limits the driver enforces on its own (defence in depth)."""

    turn_min: Joints
    turn_max: Joints
    max_speed: Joints  # deg per 12 ms cycle
    max_accel: Joints  # deg per cycle^2
    max_change: Joints  # deg: how far one Alter target may be from where the robot is


class AlterTarget(Struct):
    """A real-time (Alter) target; the driver checks it: Alter mode on, strictly inside the
    turn limits, at most max change from where the robot is."""

    q: Joints
    synchronized: bool = False  # RTSpeedControl 0: axes arrive together
    relative: bool = False  # DoAlterJoint: q is an offset from where the robot is


class AlterMode(Struct):
    enable: bool
    synchronized: bool = False  # RTSpeedControl 0: axes arrive together
    timeout_s: float = 0.5  # stop if no target arrives for this long


class SignalRequest(Struct):
    """Switch the Adept's digital outputs as V+ ``SIGNAL 5, -6`` does (rob6.vplus): a
    positive number on, a negative one off, in this order."""

    signals: list[int]


class LinkQuery(Struct):
    reset: bool = False  # start the latency statistics afresh after this answer


class LinkStatus(Struct):
    """The driver's link to the robot (``driver/link`` operation)."""

    link: str  # sim | rsi
    state: str  # connected | lost | waiting | stopped (rsi: RSI switched off after the driver's Stop) | refused
    # (rsi: the run's cycle is not the robot's; the driver answers Stop)
    address: str = ""  # where the driver listens (rsi: udp HOST:PORT)
    peer: str = ""  # the controller's address
    packets: int = 0  # cycles the plant ran (rsi: packets answered)
    late: int = 0  # packets the controller counted late, all runs
    missed: int = 0  # controller cycles without a packet/cycle in the driver
    runs: int = 0  # RSI runs seen (each RSI_ON is one)
    garbage: int = 0  # packets that could not be parsed (not answered)
    start_pose: Joints | None = None  # ASPos of the current run
    latency_us: list[float] = []  # packet in -> reply out since the last reset: p50, p99, max
    realtime: bool = False  # the link's thread runs with real-time scheduling


class LinkEvent(Struct):
    """A link event of the driver (``rob6/<id>/driver/link``), recorded."""

    t: float  # wall time, epoch seconds
    event: str  # waiting | run_start | restart | late | lost | back | trip | stop_sent | stopped | garbage
    # | wrong_cycle (rsi: a run refused, its packets faster than the robot's cycle)
    message: str
    link: str = "rsi"
    cycle: int = 0  # the driver cycle it happened at
    late: int = 0  # late packets so far (all runs)
    start_pose: Joints | None = None  # ASPos (run_start, restart)
    q_actual: Joints | None = None  # AIPos at the event


# ---------------------------------------------------------------- the cell (safety zones)
class HalfSpace(Struct):
    """Everything on one side of a plane (robot base frame, mm)."""

    point: list[float]  # a point of the plane
    normal: list[float]  # unit normal, pointing to the side the arm may be in


class Box(Struct):
    """A box: its corners before the rotation (robot base frame, mm), turned about its centre
    (the middle of ``min`` and ``max``) by ``rpy_deg`` = [r, p, y] degrees, URDF's roll, pitch,
    yaw: about the base frame's x by r, then its y by p, then its z by y (fixed axes), the
    rotation ``Rz(y) @ Ry(p) @ Rx(r)``; ``rob6.cell.file`` says it in full."""

    min: list[float]
    max: list[float]
    rpy_deg: list[float] = msgspec.field(default_factory=lambda: [0.0, 0.0, 0.0])


class Zone(Struct):
    """A safety zone: ``keep`` "out" (no part of the arm or tool may enter it) or "in" (none
    may leave it); one shape. ``ignore``: parts never checked against it (the first link
    stands on the floor)."""

    name: str
    keep: Literal["out", "in"]
    half_space: HalfSpace | None = None
    box: Box | None = None
    ignore: list[str] = []
    #: more room than the cell's ``margin_mm`` kept from this zone (mm; never less): e.g. the
    #: controller's own stopping distance from the vendor's data. None: the cell's margin
    margin_mm: float | None = None


class ToolShape(Struct):
    """One shape of the tool, in the flange frame (mm): a sphere (centre ``a``) or a capsule
    (the segment ``a``-``b``), of ``radius``."""

    name: str
    radius: float
    a: list[float]
    b: list[float] | None = None


class Cell(Struct):
    """The robot's cell (``rob6.cell``): what the planner checks every path against and the
    driver every setpoint. The driver loads it (``ROB6_CELL``) and serves it."""

    source: str  # the file it was read from, or "default <robot>"
    margin_mm: float  # kept clear of every zone, and between parts of the arm
    zones: list[Zone] = []
    tool: list[ToolShape] = []
    self_collision: bool = True
    arm_padding_mm: float = 0.0  # added around every shape of the arm (cables, covers); the default of every part
    arm_padding_parts: dict[str, float] = {}  # a part's own padding, where the file gives one (mm)
    allowed_pairs: list[list[str]] = []  # pairs of parts that may touch, beyond the adjacent ones
    #: the lab's own (ROB6_CELL), not the default: IsPossible then checks poses against it too
    #: (with the default it answers as the original, whose transcripts ask about poses below the floor)
    from_file: bool = True
    #: SHA-256 of the file's bytes (hex; the default cell's file too): a changed cell shows in
    #: the driver's log, GetCell and every recording. "": a recording made before it was carried
    sha256: str = ""
    #: the pairs of parts not measured, each with why (near in the chain, allowed by the file,
    #: touching at the zero position): filled by the driver from its model
    unchecked: list[str] = []


class Clearance(Struct):
    """How near the arm is to the cell's zones and to itself: the closest pair, published by
    the driver on ``rob6/<id>/driver/clearance`` while the arm moves (at most 10 Hz)."""

    t: float  # driver clock, seconds
    distance_mm: float  # < 0: inside
    part: str  # a part of the arm or the tool
    other: str  # the zone's name, or the other part (self-collision)
    zone: bool = True  # other is a zone (False: a part of the arm)


# ---------------------------------------------------------------- kinematics
class FkRequest(Struct):
    joints: list[Joints]


class FkReply(Struct):
    poses: list[Pose]
    status: list[str]


class ForwardCalcRequest(Struct):
    numbers: list[float]  # 0..6 leading numbers as the client gave them
    turn_min: Joints
    turn_max: Joints


class ForwardCalcReply(Struct):
    pose: Pose | None = None
    status: str = ""


class BackwardCalcRequest(Struct):
    pose: Pose
    pattern: Pattern
    current: Joints
    turn_min: Joints
    turn_max: Joints
    max_change: Joints
    weights: Joints  # MinChangeWeights: which admissible branch toggle words pick


class JointsReply(Struct):
    joints: Joints | None = None  # None: no admissible solution ("false")


class IkBatchRequest(Struct):
    poses: list[Pose]


class IkBatchReply(Struct):
    branches: list[str]  # the 8 status labels, in the order of each solution list
    solutions: list[list[Joints | None]]  # per pose, per branch


class SelectRequest(BackwardCalcRequest):
    """Configuration choice for a Cartesian move (the original's min-change rule): BackwardCalc's
    question, the same fields in the same order, restricted to the ``allowed`` status."""

    allowed: Pattern


# ---------------------------------------------------------------- planner
class ConfigChange(Struct):
    """A Set*/Reset* protocol command with its parsed arguments."""

    command: str
    args: list[float] = []
    words: list[str] = []


class MotionConfig(Struct):
    speed: Joints
    accel: Joints
    max_change: Joints
    turn_max: Joints
    turn_min: Joints
    weights: Joints
    allowed: Pattern
    rt_speed_control: int
    version: int = 0  # counts the planner's changes: a mirror never goes back to an older one


class ConfigReply(Struct):
    ok: bool
    config: MotionConfig


class MoveRequest(Struct):
    """A motion command. ``kind`` is the protocol command name."""

    kind: MotionKind
    joints: Joints | None = None
    pose: Pose | None = None
    pattern: Pattern | None = None
    dry_run: bool = False  # route test: check and plan only, from ``start``
    #: where the motion starts: the gateway's copy of the driver's state (the route test's
    #: position for a dry run); None: the planner asks the driver
    start: Joints | None = None
    session: str = ""  # the client session (SessionEnd.session): none of its motions starts after it ended


class PoseCheck(Struct):
    """IsPossible's question to the planner: may the arm be at these joints (the cell's zones)?"""

    joints: Joints


class SessionEnd(Struct):
    """The client left: its motion stops, and none of its motions starts any more."""

    session: str = ""  # the gateway instance and the session's number


class MoveReply(Struct):
    ok: bool
    joints: Joints | None = None  # where the robot is (or would be, dry run) afterwards
    reason: str = ""
    error: str = ""  # the driver's plant failed (robot not connected, link lost): the client sees it
    state: JointState | None = None  # the driver's state when the move ended
    #: refused because another kind of client owns the motion (one robot, one motion): the
    #: client sees it as ``ERROR: <busy>``
    busy: str = ""
    invalid: bool = False  # follow: the trajectory was refused before anything moved (``reason`` says why)
    #: refused (its path enters a zone) or stopped by the cell's safety zones (rob6.cell):
    #: the client sees ``ERROR: <zone>`` and ``false``
    zone: str = ""


class FollowRequest(Struct):
    """A time-parameterised joint trajectory to follow (ROS 2's FollowJointTrajectory), in
    rob6's joint order and units (degrees, seconds). The planner checks it against the
    limits and samples it at the driver's cycle (quintic between points with velocities and
    accelerations, cubic with velocities only, velocities estimated when absent)."""

    t: list[float]  # time of each point from the start, strictly increasing, >= 0
    q: list[Joints]
    qd: list[Joints] | None = None  # deg/s at each point
    qdd: list[Joints] | None = None  # deg/s^2 at each point
    #: how far (degrees) a point at t = 0 may be from where the arm is
    start_tolerance: float = 1.0
    dry_run: bool = False  # check only


class ModeRequest(Struct):
    command: str  # EnableAlter, DisableAlter, EnableLin, ...


# ---------------------------------------------------------------- gripper
class GripperCommand(Struct):
    command: str  # HasGripper | GripperGoHome | GripperMove | GripperMoveToPosition
    value: float | None = None


class GripperReply(Struct):
    """What the gripper did; the gateway turns it into the protocol's reply lines."""

    ok: bool
    reason: str = ""  # why ok is False (one sentence, shown to the client as ERROR: <reason>)
    position: float | None = None  # m, the opening afterwards, when the gripper told it


class GripperState(Struct):
    position: float  # m
    velocity: float  # m/s
    current: float  # A
    mode: str  # idle | moving | gripping | error
    error: str = ""


# ---------------------------------------------------------------- control topics
class Verbosity(Struct):
    level: int  # the protocol's 0..4


class LogRecord(Struct):
    t: float
    service: str
    instance: str
    level: str
    name: str
    message: str


class ClientExchange(Struct):
    """One client line and the gateway's reply (``rob6/<id>/trace/gateway/session``)."""

    session: int
    peer: str
    cid: str
    t_in: float
    t_out: float
    line: str  # latin-1 text, terminator removed
    reply: str | None  # None: no reply (empty line, SetAllowedStatus)
    seq: int = 0  # 1, 2, ... per session, in the order of the lines: a gap is a lost record


class SessionEvent(Struct):
    """A client session opening or closing (``rob6/<id>/trace/gateway/event``)."""

    session: int
    event: str  # open | close
    peer: str
    t: float
    greeting: str = ""
    reason: str = ""  # why a session closed other than by Quit or the client's close between commands


class Op(NamedTuple):
    request: type
    reply: type
    #: how long the caller waits (rob6.deadlines): ``QUICK_S``, or the bound of the
    #: service's own work; for a waiting operation (``waits``, ``ANNOUNCE_S``) until the
    #: service announces what it waits for, which moves the deadline
    timeout: float = QUICK_S
    #: a second copy goes to another replica when the first has not answered after
    #: ``rob6.bus.HEDGE_DELAY_S`` (idempotent services only, never an owner service)
    hedged: bool = False
    #: the reply may wait for the arm, the gripper or the link: the service announces how
    #: long (``rob6.bus.Context.waiting``) and the caller's deadline follows
    waits: bool = False


#: Every request/reply operation on the bus.
OPS: dict[tuple[str, str], Op] = {
    ("driver", "ping"): Op(Empty, PingReply),
    ("driver", "state"): Op(Empty, JointState),
    ("driver", "execute"): Op(ExecuteRequest, ExecuteReply, timeout=ANNOUNCE_S, waits=True),
    ("driver", "limits"): Op(LimitsUpdate, Ack),
    ("driver", "alter_mode"): Op(AlterMode, Ack, timeout=ANNOUNCE_S, waits=True),
    ("driver", "alter_target"): Op(AlterTarget, Ack),
    ("driver", "stop"): Op(Empty, Ack, timeout=ANNOUNCE_S, waits=True),
    ("driver", "link"): Op(LinkQuery, LinkStatus),
    ("driver", "signal"): Op(SignalRequest, Ack, timeout=ANNOUNCE_S, waits=True),
    ("driver", "cell"): Op(Empty, Cell),
    ("kinematics", "fk"): Op(FkRequest, FkReply, timeout=REMOTE_POSE_S, hedged=True),
    ("kinematics", "forward_calc"): Op(ForwardCalcRequest, ForwardCalcReply, timeout=REMOTE_POSE_S, hedged=True),
    ("kinematics", "backward_calc"): Op(BackwardCalcRequest, JointsReply, timeout=REMOTE_POSE_S, hedged=True),
    ("kinematics", "ik_batch"): Op(IkBatchRequest, IkBatchReply, timeout=IK_BATCH_S),
    ("kinematics", "select"): Op(SelectRequest, JointsReply, timeout=REMOTE_POSE_S, hedged=True),
    ("planner", "config"): Op(Empty, MotionConfig),
    ("planner", "config_change"): Op(ConfigChange, ConfigReply, timeout=CONFIG_CHANGE_S),
    ("planner", "move"): Op(MoveRequest, MoveReply, timeout=ANNOUNCE_S, waits=True),
    ("planner", "mode"): Op(ModeRequest, Ack, timeout=ANNOUNCE_S, waits=True),
    ("planner", "session_end"): Op(SessionEnd, Ack, timeout=ANNOUNCE_S, waits=True),
    ("planner", "follow"): Op(FollowRequest, MoveReply, timeout=ANNOUNCE_S, waits=True),
    ("planner", "follow_stop"): Op(Empty, Ack, timeout=ANNOUNCE_S, waits=True),
    ("planner", "pose_check"): Op(PoseCheck, Ack),
    ("gripper", "command"): Op(GripperCommand, GripperReply, timeout=ANNOUNCE_S, waits=True),
    ("gripper", "state"): Op(Empty, GripperState),
}

#: Services whose operations have no side effects: a failed call may be retried on
#: another replica.
IDEMPOTENT_SERVICES = frozenset({"kinematics"})

#: Services a robot id has exactly one of (see rob6.ownership): callers follow that one
#: instance, never a second one that should not be there.
OWNER_SERVICES = frozenset({"driver", "planner", "gripper", "gateway", "ros"})

SERVICES = ("gateway", "kinematics", "planner", "driver", "gripper", "recorder", "ros")
