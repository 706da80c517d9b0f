"""The planner service: owns the motion configuration, plans every motion and hands it to the driver.

The motion planner service: owns the motion configuration, validates and plans every
motion with Ruckig, and hands sampled trajectories (or Alter targets) to the driver.

Configuration choice for Cartesian targets is the kinematics service's ``select``
(the original's rule); this service computes no inverse kinematics itself. It checks every
sampled path against the driver's cell (safety zones, ``zones.PathCheck``) before it hands
the path over: a path that would enter a zone is refused, naming the zone, and nothing moves.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Sequence
from typing import Literal

import numpy as np

from rob6.bus import Bus, BusError, Context
from rob6.deadlines import PLAN_LIN_S, QUICK_S
from rob6.errors import RefusedError
from rob6.messages import (
    Ack,
    AlterMode,
    AlterTarget,
    ConfigChange,
    ConfigReply,
    Empty,
    ExecuteReply,
    ExecuteRequest,
    FkReply,
    FkRequest,
    FollowRequest,
    IkBatchReply,
    IkBatchRequest,
    JointsReply,
    JointState,
    LimitsUpdate,
    ModeRequest,
    MotionConfig,
    MotionKind,
    MoveReply,
    MoveRequest,
    PoseCheck,
    SelectRequest,
    SessionEnd,
    Trajectory,
)
from rob6.robots import RobotModel
from rob6.status import NO_TOGGLE_ALL as KEEP_CONFIGURATION, PTP_HOM_PATTERN

from .config import MotionSettings
from .follow import FollowRefused, sample
from .lin_planner import plan_lin
from .trajectory import JointLimits, SampledTrajectory, TrajectoryPlanner
from .zones import CellUnknown, PathCheck

log = logging.getLogger("rob6.planner")

POSE_MOVES: frozenset[MotionKind] = frozenset({
    "MovePTPHomRowWise", "MovePTPHomRowWiseStatusTurn", "MoveMinChangeRowWiseStatus", "RoutetestRowWiseStatus"})
JOINT_MOVES: frozenset[MotionKind] = frozenset({"MovePTPJoints", "MovePTPJointsStatus"})
ALTER_MOVES: frozenset[MotionKind] = frozenset({
    "MoveRTJoints", "MoveRTHomRowWise", "MoveRTHomRowWiseStatus", "DoAlterJoint", "DoAlterCart"})
ADEPT_SETTINGS = {"SetAdeptSpeed", "SetAdeptAccel", "SetAdeptFine", "SetAdeptCoarse"}
#: one robot, one motion: who owns the motion in progress (a client of the text protocol, or
#: a ROS 2 FollowJointTrajectory goal); the other kind is refused with these words
CLIENT, ROS = "client", "ros"
BUSY = {
    ROS: "the arm is executing a ROS 2 FollowJointTrajectory goal; wait for it to end (or cancel it)",
    CLIENT: "the arm is moving for a client of the rob6 protocol (port 5005); a ROS 2 goal waits until it ends",
}
LIMIT_FIELDS: tuple[Literal["speed", "accel", "turn_min", "turn_max", "max_change"], ...] = ("speed", "accel", "turn_min", "turn_max", "max_change")


class MotionRefused(RefusedError):
    """A motion refused before it started (the client gets ``false``)."""


def _given(value: list[float] | None, what: str, kind: str) -> list[float]:
    """A field the motion needs (the gateway always sends it with that kind)."""
    if value is None:
        raise MotionRefused(f"{kind} without {what}")
    return value


class PlannerService:
    def __init__(self, bus: Bus, robot: RobotModel, alter_timeout_s: float = 0.5):
        self.bus = bus
        self.robot = robot
        self.config = MotionSettings(robot)
        self.planner = TrajectoryPlanner(robot)
        self.alter = False
        self.lin = False
        self.alter_timeout_s = alter_timeout_s
        # Adept V+ settings (ad850): speed and accelerations in percent of the maximum
        self.adept = {"speed": 100.0, "accel": 100.0, "decel": 100.0, "fine": 100.0, "coarse": 100.0}
        self._lock = threading.Lock()  # one motion at a time; the planner reuses its Ruckig buffers
        # a motion of a session whose client left (session_end) never starts, and the stop
        # for it reaches the driver only after a motion being handed over has started
        self._handover = threading.Condition()
        self._ended: deque[str] = deque(maxlen=64)  # the last sessions that ended
        self._handing_over = False
        self._version = 0  # of the configuration, for the gateway's mirror
        self._owner_lock = threading.Lock()
        self._owner: str | None = None  # CLIENT or ROS while a motion of that kind runs
        self._owner_count = 0
        self._follow_stopped = threading.Event()  # follow_stop asked for the running goal
        self.cell = PathCheck(bus, robot)
        bus.on_liveliness(self._on_liveliness)

    # ------------------------------------------------------------------ configuration
    def _message(self) -> MotionConfig:
        return MotionConfig(**self.config.to_dict(), version=self._version)

    def get_config(self, _req: Empty, _ctx: Context) -> MotionConfig:
        return self._message()

    def config_change(self, req: ConfigChange, ctx: Context) -> ConfigReply:
        if req.command in ADEPT_SETTINGS:
            return ConfigReply(ok=self._adept_setting(req.command, req.args), config=self._message())
        before = self.config.to_dict()
        ok = self.config.apply(req.command, req.args, req.words)
        after = self.config.to_dict()
        if after != before:
            self._version += 1
            self.bus.publish("planner/config", self._message(), reliable=True)
            if any(before[f] != after[f] for f in LIMIT_FIELDS):
                self._push_limits(ctx.cid)
        return ConfigReply(ok=ok, config=self._message())

    def _adept_setting(self, command: str, values: list[float]) -> bool:
        """The original answers true to these on every type; only the Adept uses them."""
        if not self.robot.is_adept or not values:
            return True
        if command == "SetAdeptSpeed":
            self.adept["speed"] = min(max(values[0], 0.0), 120.0)
        elif command == "SetAdeptAccel":
            self.adept["accel"] = min(max(values[0], 0.0), 120.0)
            self.adept["decel"] = min(max(values[1] if len(values) > 1 else values[0], 0.0), 120.0)
        else:  # fine/coarse positioning tolerance: the simulated robot is exact
            self.adept["fine" if command == "SetAdeptFine" else "coarse"] = values[0]
        return True

    def _push_limits(self, cid: str | None = None) -> None:
        """The driver enforces the limits on its own; keep its copy current."""
        c = self.config
        try:
            self.bus.request("driver", "limits", LimitsUpdate(
                turn_min=list(c.turn_min), turn_max=list(c.turn_max), max_speed=list(c.speed),
                max_accel=list(c.accel), max_change=list(c.max_change)), cid=cid)
        except BusError as exc:
            log.warning("could not update the driver's limits: %s", exc.message)

    def _on_liveliness(self, service: str, _instance: str, alive: bool) -> None:
        if service == "driver" and alive:  # a (re)started driver gets the current limits; its cell is asked
            threading.Thread(target=self._driver_appeared, daemon=True).start()
        if service == "gateway" and alive:
            self.bus.publish("planner/config", self._message(), reliable=True)

    def _driver_appeared(self) -> None:
        self._push_limits()
        self.cell.fetch()

    def _planning_config(self, start: Sequence[float] | None = None) -> MotionSettings:
        """The configuration with the Adept's speed/acceleration percentages applied, and,
        for a motion from ``start`` where a part is within a zone's margin, the slow speed
        of a way out (``rob6.cell.guard.ESCAPE_SPEED_MM_S``)."""
        share = self._escape_share(start) if start is not None else 1.0
        if not self.robot.is_adept and share == 1.0:
            return self.config
        scaled = self.config.copy()
        if self.robot.is_adept:
            scaled.speed = [v * self.adept["speed"] / 100.0 for v in scaled.speed]
            scaled.accel = [a * min(self.adept["accel"], self.adept["decel"]) / 100.0 for a in scaled.accel]
        if share < 1.0:
            log.info("a part is within a zone's margin: the way out runs at %.1f %% of the speed limits", 100 * share)
            scaled.speed = [v * share for v in scaled.speed]
        return scaled

    def _escape_share(self, start: Sequence[float]) -> float:
        try:
            return self.cell.escape_share(start, JointLimits.from_config(self.config))
        except CellUnknown as exc:
            raise MotionRefused(str(exc)) from None

    # ------------------------------------------------------------------ modes
    def mode(self, req: ModeRequest, ctx: Context) -> Ack:
        command = req.command
        if command == "EnableAdeptAlter" and not self.robot.is_adept:
            return Ack(ok=False, reason="EnableAdeptAlter is for the Adept only")
        if command in ("EnableAlter", "EnableAdeptAlter"):  # waits for a stop in progress
            with self._owner_lock:
                if self._owner == ROS:
                    return Ack(ok=False, reason=BUSY[ROS], busy=BUSY[ROS])
            reply: Ack = self.bus.request("driver", "alter_mode", AlterMode(
                enable=True, synchronized=self.config.rt_speed_control == 0,
                timeout_s=self.alter_timeout_s), cid=ctx.cid, waiting=ctx.waiting)
            self.alter = reply.ok
            return reply
        if command == "DisableAlter":
            if not self.alter:
                return Ack(ok=True)  # already off: the original answers true as well
            self.alter = False  # answered once the robot is at rest
            off: Ack = self.bus.request("driver", "alter_mode", AlterMode(enable=False), cid=ctx.cid,
                                        waiting=ctx.waiting)
            return off
        if command in ("EnableLin", "DisableLin"):
            self.lin = command == "EnableLin"
            return Ack(ok=True)
        return Ack(ok=False, reason=f"unknown mode command {command}")

    def session_end(self, req: SessionEnd, ctx: Context) -> Ack:
        """The client left: no motion goes on without it (Alter, or a move it left during,
        or one of its moves still being planned). The driver stops what a client runs,
        with its ramp; answered at rest. A ROS 2 goal is not a client's, and goes on."""
        with self._owner_lock:
            owner = self._owner
        with self._handover:
            self._ended.append(req.session)
            alter, self.alter = self.alter, False
            if owner != CLIENT and not alter:  # nothing of a client's runs: nothing to stop
                return Ack(ok=True)
            if self._handing_over:  # the stop must come after the driver took the motion
                ctx.waiting(QUICK_S, "waiting for the driver to take a motion")
                self._handover.wait_for(lambda: not self._handing_over, QUICK_S)
        reply: Ack = self.bus.request("driver", "stop", Empty(), cid=ctx.cid, waiting=ctx.waiting)
        return reply

    def _handed_over(self) -> None:
        with self._handover:
            self._handing_over = False
            self._handover.notify_all()

    # ------------------------------------------------------------------ one robot, one motion
    def _claim(self, who: str) -> str:
        """Take the motion for ``who``; the reason it belongs to the other kind, or ""."""
        with self._owner_lock:
            if self._owner is not None and self._owner != who:
                return BUSY[self._owner]
            self._owner = who
            self._owner_count += 1
            return ""

    def _release(self) -> None:
        with self._owner_lock:
            self._owner_count -= 1
            if self._owner_count == 0:
                self._owner = None

    # ------------------------------------------------------------------ motion
    def move(self, req: MoveRequest, ctx: Context) -> MoveReply:
        real = not req.dry_run
        if real:
            busy = self._claim(CLIENT)
            if busy:
                log.info("%s refused: %s", req.kind, busy)
                return MoveReply(ok=False, reason=busy, busy=busy)
        try:
            if req.kind == "MoveLINHomRowWise":  # longer than the caller waits unannounced
                ctx.waiting(PLAN_LIN_S, "planning the straight line")
            # a point-to-point plan fits in what the caller waits before any announcement
            # (PLAN_PTP_S <= ANNOUNCE_S): announcing it would cost a message on every move
            if req.kind in ALTER_MOVES:
                return self._alter_move(req, ctx.cid)
            with self._lock:
                return self._move(req, ctx)
        except MotionRefused as exc:
            log.info("%s refused: %s", req.kind, exc)
            return MoveReply(ok=False, reason=str(exc))
        finally:
            if real:
                self._release()

    # ------------------------------------------------------------------ ROS 2 trajectories
    def follow(self, req: FollowRequest, ctx: Context) -> MoveReply:
        """Follow a time-parameterised trajectory (a ROS 2 FollowJointTrajectory goal): checked
        against every limit and sampled here, executed by the driver like any motion."""
        busy = self._claim(ROS) if not req.dry_run else ""
        if busy:
            return MoveReply(ok=False, reason=busy, busy=busy, invalid=True)
        try:
            if self.alter:
                return MoveReply(ok=False, reason="Alter mode is on: a client streams targets to the arm",
                                 busy="Alter mode is on: a client streams targets to the arm", invalid=True)
            if not self._lock.acquire(blocking=False):
                return MoveReply(ok=False, reason=BUSY[CLIENT], busy=BUSY[CLIENT], invalid=True)
            try:
                state: JointState = self.bus.request("driver", "state", Empty(), cid=ctx.cid)
                # the driver's mode, as its own check of a trajectory (``state.moving`` stays
                # true for the cycle after a stop ends, from its last step: a goal right after
                # a cancel was refused)
                if state.mode != "idle":
                    return MoveReply(ok=False, reason=BUSY[CLIENT], busy=BUSY[CLIENT], invalid=True)
                c = self._planning_config()
                limits = JointLimits.from_config(c)  # the protocol's units in deg/s, deg/s^2
                try:
                    trajectory = sample(req.t, req.q, req.qd, req.qdd, current=state.q, dt=self.planner.dt,
                                        turn_min=c.turn_min, turn_max=c.turn_max, speed=limits.vmax.tolist(),
                                        accel=limits.amax.tolist(), start_tolerance=req.start_tolerance)
                except FollowRefused as exc:
                    log.info("trajectory refused: %s", exc)
                    return MoveReply(ok=False, reason=str(exc), invalid=True, state=state)
                zone = self._zone(trajectory)
                if zone:
                    log.info("trajectory refused: %s", zone)
                    return MoveReply(ok=False, reason=zone, zone=zone, invalid=True, state=state)
                if req.dry_run:
                    return MoveReply(ok=True, joints=trajectory.q[-1].tolist(), state=state)
                self._follow_stopped.clear()
                reply = self._execute(trajectory, "", ctx)
                if not reply.ok and self._follow_stopped.is_set():
                    reply.reason = "canceled: the arm stopped on its jerk-limited ramp"
                return reply
            finally:
                self._lock.release()
        finally:
            if not req.dry_run:
                self._release()

    def follow_stop(self, _req: Empty, ctx: Context) -> Ack:
        """Cancel the running goal: the driver stops the arm on its ramp; answered at rest."""
        with self._owner_lock:
            if self._owner != ROS:
                return Ack(ok=True, reason="no ROS 2 goal is running")
            self._follow_stopped.set()
        reply: Ack = self.bus.request("driver", "stop", Empty(), cid=ctx.cid, waiting=ctx.waiting)
        return reply

    def _current(self, req: MoveRequest) -> list[float]:
        """Where the motion starts: what the gateway sent (its copy of the driver's state,
        or the route test's position), else the driver's state asked now. The planner does
        not follow the driver's 250 Hz state itself (idle CPU, issue 13); the driver
        refuses a trajectory that does not start where the robot is."""
        if req.start is not None:
            return list(req.start)
        return list(self.bus.request("driver", "state", Empty()).q)

    def _move(self, req: MoveRequest, ctx: Context) -> MoveReply:
        cid = ctx.cid
        start = self._current(req)
        if self.alter and not req.dry_run:
            raise MotionRefused("Alter mode is on (DisableAlter first)")
        if req.kind == "MoveLINHomRowWise":
            return self._lin(req, start, ctx)
        if self.lin and not req.dry_run:
            raise MotionRefused("LIN mode is on: point-to-point moves are refused (DisableLin first)")
        if req.kind in JOINT_MOVES:
            target = list(_given(req.joints, "joints", req.kind))
        elif req.kind in POSE_MOVES:
            pattern = PTP_HOM_PATTERN if req.kind == "MovePTPHomRowWise" else req.pattern
            # the gateway always sends them with these kinds (as before, a request without
            # them fails as an internal error)
            assert req.pose is not None and pattern is not None
            target = self._select(req.pose, pattern, start, cid)
        else:
            raise MotionRefused(f"unknown motion {req.kind}")
        pattern = req.pattern if req.kind == "MovePTPJointsStatus" else None
        plan = self.planner.plan_ptp(start, target, self._planning_config(start), pattern=pattern)
        if not plan.ok:
            raise MotionRefused(plan.reason)
        assert plan.trajectory is not None  # a sampled plan that is ok has one
        zone = self._zone(plan.trajectory)  # route tests too: a route through a zone is no route
        if zone:
            log.info("%s refused: %s", req.kind, zone)
            return MoveReply(ok=False, reason=zone, zone=zone)
        if req.dry_run:
            return MoveReply(ok=True, joints=target)
        return self._execute(plan.trajectory, req.session, ctx)

    def _zone(self, trajectory: SampledTrajectory) -> str:
        """Why the cell's safety zones refuse ``trajectory`` (the limits the driver brakes
        with are the configuration's own, without the Adept's percentages), or ""."""
        try:
            return self.cell.path(trajectory, JointLimits.from_config(self.config))
        except CellUnknown as exc:
            raise MotionRefused(str(exc)) from None

    def _select(self, pose: Sequence[float], pattern: Sequence[str], current: list[float], cid: str) -> list[float]:
        c = self.config
        reply: JointsReply = self.bus.request("kinematics", "select", SelectRequest(
            pose=list(pose), pattern=list(pattern), current=current, turn_min=list(c.turn_min),
            turn_max=list(c.turn_max), max_change=list(c.max_change), weights=list(c.weights),
            allowed=list(c.allowed)), cid=cid)
        if reply.joints is None:
            raise MotionRefused("no admissible solution for that pose and status")
        return reply.joints

    def _execute(self, trajectory: SampledTrajectory, session: str, ctx: Context) -> MoveReply:
        """Hand the motion to the driver and wait for its end, as long as the driver says
        (its announcement also says it took the motion: a stop sent now stops it)."""
        request = ExecuteRequest(trajectory=Trajectory(
            dt=trajectory.dt, q=trajectory.q.tolist(), qd=trajectory.qd.tolist(), qdd=trajectory.qdd.tolist()))
        with self._handover:
            if session and session in self._ended:
                raise MotionRefused("the client left before the motion started")
            self._handing_over = True

        def started(seconds: float, what: str) -> None:
            self._handed_over()
            ctx.waiting(seconds, what)

        try:
            reply: ExecuteReply = self.bus.request("driver", "execute", request, cid=ctx.cid, waiting=started)
        finally:
            self._handed_over()
        joints = reply.state.q if reply.state is not None else None
        return MoveReply(ok=reply.ok, joints=joints, reason=reply.reason, error=reply.error, state=reply.state,
                         zone=reply.zone)

    def _lin(self, req: MoveRequest, start: list[float], ctx: Context) -> MoveReply:
        cid = ctx.cid
        if not self.lin:
            raise MotionRefused("LIN mode is off (EnableLin first)")
        if req.dry_run:
            raise MotionRefused("route test of LIN moves is not supported")
        fk: FkReply = self.bus.request("kinematics", "fk", FkRequest(joints=[start]), cid=cid)
        branch = " ".join(self.robot.status(start))
        pose0 = np.asarray(fk.poses[0], float).reshape(3, 4)

        def ik_fn(poses: np.ndarray) -> np.ndarray:
            reply: IkBatchReply = self.bus.request("kinematics", "ik_batch", IkBatchRequest(
                poses=np.asarray(poses, float).reshape(-1, 12).tolist()), cid=cid)
            index = reply.branches.index(branch)
            return np.array([[np.nan] * 6 if s[index] is None else s[index] for s in reply.solutions])

        plan = plan_lin(self.planner, start, pose0, np.asarray(req.pose, float).reshape(3, 4),
                        self._planning_config(start), ik_fn)
        if not plan.ok:
            raise MotionRefused(plan.reason)
        assert plan.trajectory is not None  # a LIN plan that is ok has one
        zone = self._zone(plan.trajectory)
        if zone:
            log.info("MoveLINHomRowWise refused: %s", zone)
            return MoveReply(ok=False, reason=zone, zone=zone)
        return self._execute(plan.trajectory, req.session, ctx)

    def _alter_move(self, req: MoveRequest, cid: str) -> MoveReply:
        """Alter targets; the driver checks them (Alter mode, turn limits, max change), since
        the gateway streams joint targets (MoveRTJoints, DoAlterJoint) to it directly."""
        if not self.alter:
            raise MotionRefused("Alter mode is off (EnableAlter first)")
        relative = req.kind == "DoAlterJoint"
        if req.kind in ("MoveRTJoints", "DoAlterJoint"):
            target = list(_given(req.joints, "joints", req.kind))
        else:
            current = self._current(req)
            # the gateway always sends a pose with these kinds (as before, a request
            # without one fails as an internal error)
            assert req.pose is not None
            if req.kind == "DoAlterCart":
                pose = _shifted_pose(self._pose(current, cid), req.pose)
                target = self._select(pose, KEEP_CONFIGURATION, current, cid)
            else:  # MoveRTHomRowWise keeps the configuration, ...Status chooses by its pattern
                pattern = req.pattern if req.kind == "MoveRTHomRowWiseStatus" else KEEP_CONFIGURATION
                assert pattern is not None  # the gateway always sends it with MoveRTHomRowWiseStatus
                target = self._select(req.pose, pattern, current, cid)
        reply: Ack = self.bus.request("driver", "alter_target", AlterTarget(
            q=target, synchronized=self.config.rt_speed_control == 0, relative=relative), cid=cid)
        return MoveReply(ok=reply.ok, joints=None if relative else target, reason=reply.reason, error=reply.error,
                         zone=reply.zone)

    def pose_check(self, req: PoseCheck, _ctx: Context) -> Ack:
        """IsPossible: may the arm be at ``req.joints`` (the cell's zones and margin)?"""
        try:
            zone = self.cell.pose(req.joints)
        except CellUnknown as exc:
            return Ack(ok=False, reason=str(exc), zone=str(exc))
        return Ack(ok=not zone, reason=zone, zone=zone)

    def _pose(self, joints: list[float], cid: str) -> list[float]:
        reply: FkReply = self.bus.request("kinematics", "fk", FkRequest(joints=[joints]), cid=cid)
        return reply.poses[0]

    def serve(self) -> None:
        self.bus.serve({"config": self.get_config, "config_change": self.config_change, "move": self.move,
                        "mode": self.mode, "session_end": self.session_end, "follow": self.follow,
                        "follow_stop": self.follow_stop, "pose_check": self.pose_check}, workers=4)
        self.bus.publish("planner/config", self._message(), reliable=True)
        if self.bus.instances("driver"):  # otherwise the driver's token arriving triggers it
            threading.Thread(target=self._driver_appeared, daemon=True).start()


def _shifted_pose(pose12: Sequence[float], step: Sequence[float]) -> list[float]:
    """DoAlterCart: translate by (dx, dy, dz) mm and rotate by (rx, ry, rz) deg about the
    base axes (applied in x, y, z order), both in the robot's base frame."""
    T = np.asarray(pose12, float).reshape(3, 4)
    rx, ry, rz = np.radians(step[3:6])
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx @ T[:, :3]
    p = T[:, 3] + np.asarray(step[:3], float)
    return np.hstack([R, p[:, None]]).reshape(12).tolist()
