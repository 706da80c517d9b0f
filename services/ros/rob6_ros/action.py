"""The FollowJointTrajectory action server: goals checked, then executed by rob6's planner and driver.

As ros2_control's joint_trajectory_controller offers it, under ``<namespace>/<name>``
(``follow_joint_trajectory`` by default): the services ``_action/send_goal``,
``_action/cancel_goal``, ``_action/get_result`` and the topics ``_action/feedback`` and
``_action/status`` (transient local, depth 1), in rmw_zenoh's format.

A goal is accepted when it is well formed; one rob6 cannot follow ends at once, ABORTED,
nothing moved, with a result code and an error string saying why:

* ``INVALID_JOINTS``: the joint names are not exactly the URDF's six (any order), or the goal
  has multi-DOF joints;
* ``INVALID_GOAL``: no points, points without 6 positions, a point or the path between points
  outside the turn limits, speeds or accelerations over rob6's limits, a first point at
  t = 0 further than the start tolerance from where the arm is, a last point not at rest,
  or the arm busy (an old client moves it, or Alter mode is on: one robot, one motion).

A goal goes to the planner's ``follow`` (checked and sampled at the driver's cycle there,
and checked again by the driver's limit monitor); send_goal answers once the driver has
taken the motion (from then on an old client's motion command is refused) or the goal has
ended. It runs with feedback every 50 ms (actual:
the driver's state; desired: the goal's positions interpolated linearly at the elapsed
time). It SUCCEEDS when the driver reports the arm arrived, ABORTS with
``PATH_TOLERANCE_VIOLATED`` and the driver's words when the motion fails (link lost, limit
monitor), and a cancel stops the arm on the driver's jerk-limited ramp (CANCELED). The
goal's path and goal tolerances are not used: rob6 follows its samples exactly or stops.
One goal at a time: a goal while another runs is rejected (not accepted).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rob6.bus import Bus, BusError
from rob6.errors import RefusedError
from rob6.messages import Ack, Empty, FollowRequest, JointState, MoveReply

from .rmw import TRANSIENT_LOCAL, Node, Qos, Respond

log = logging.getLogger("rob6.ros")

ACTION = "control_msgs/action/FollowJointTrajectory"
# action_msgs/GoalStatus
UNKNOWN, ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = range(7)
TERMINAL = (SUCCEEDED, CANCELED, ABORTED)
# control_msgs/FollowJointTrajectory_Result
SUCCESSFUL, INVALID_GOAL, INVALID_JOINTS, OLD_HEADER_TIMESTAMP, PATH_TOLERANCE_VIOLATED = 0, -1, -2, -3, -4
# action_msgs/CancelGoal_Response
CANCEL_OK, CANCEL_REJECTED, CANCEL_UNKNOWN_GOAL, CANCEL_TERMINATED = 0, 1, 2, 3
#: rcl_action's status topic: reliable, transient local, depth 1
STATUS_QOS = Qos(durability=TRANSIENT_LOCAL, depth=1)
FEEDBACK_PERIOD_S = 0.05
KEPT_GOALS = 32  # finished goals whose results can still be asked for
#: send_goal answers at the latest after this long (the planner's checks and the driver's
#: taking the motion take milliseconds; a planner that does not answer ends the goal anyway)
START_WAIT_S = 5.0
DEFAULT_START_TOLERANCE_DEG = 1.0


def _stamp(seconds: float) -> dict[str, int]:
    sec = math.floor(seconds)
    return {"sec": int(sec), "nanosec": int((seconds - sec) * 1e9) % 1_000_000_000}


def _seconds(duration: dict[str, Any]) -> float:
    return float(duration.get("sec", 0)) + float(duration.get("nanosec", 0)) * 1e-9


class GoalError(RefusedError):
    """A goal rob6 does not follow: ``code`` is the FollowJointTrajectory result code."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code


@dataclass
class Goal:
    goal_id: bytes
    stamp: dict[str, int]
    status: int = ACCEPTED
    result: dict[str, Any] | None = None
    waiters: list[Respond] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    q: list[list[float]] = field(default_factory=list)  # degrees, rob6's joint order
    started: float = 0.0
    cancel: bool = False


class FollowJointTrajectoryServer:
    def __init__(self, node: Node, bus: Bus, joint_names: list[str], state: Callable[[], JointState | None], *,
                 name: str = "follow_joint_trajectory", start_tolerance: float = DEFAULT_START_TOLERANCE_DEG):
        self.node, self.bus, self.joint_names, self.state = node, bus, joint_names, state
        self.start_tolerance = start_tolerance
        self._lock = threading.Lock()
        self._goals: OrderedDict[bytes, Goal] = OrderedDict()
        base = f"{name.rstrip('/')}/_action"
        self.status = node.publisher(f"{base}/status", "action_msgs/msg/GoalStatusArray", STATUS_QOS)
        self.feedback = node.publisher(f"{base}/feedback", f"{ACTION}_FeedbackMessage")
        node.service(f"{base}/send_goal", f"{ACTION}_SendGoal", self._on_send_goal)
        node.service(f"{base}/cancel_goal", "action_msgs/srv/CancelGoal", self._on_cancel)
        node.service(f"{base}/get_result", f"{ACTION}_GetResult", self._on_get_result)
        self._publish_status()

    # ------------------------------------------------------------------ services
    def _on_send_goal(self, request: dict[str, Any], respond: Respond) -> None:
        """Answered from a thread: the checks ask the planner, and Zenoh's callback threads
        must not wait for the bus."""
        threading.Thread(target=lambda: respond(self._send_goal(request)), name="ros-send-goal", daemon=True).start()

    def _send_goal(self, request: dict[str, Any]) -> dict[str, Any]:
        goal_id = bytes(request["goal_id"]["uuid"])
        now = _stamp(time.time())
        with self._lock:
            if goal_id in self._goals:
                log.warning("goal %s sent twice: rejected", goal_id.hex())
                return {"accepted": False, "stamp": now}
            running = [g for g in self._goals.values() if g.status not in TERMINAL]
            if running:
                log.warning("goal %s rejected: goal %s still runs (one goal at a time)", goal_id.hex(),
                            running[0].goal_id.hex())
                return {"accepted": False, "stamp": now}
            goal = self._goals[goal_id] = Goal(goal_id, now)
            while len(self._goals) > KEPT_GOALS:
                self._goals.popitem(last=False)
        try:
            follow = self._follow_request(request["goal"])
        except GoalError as exc:
            log.info("goal %s aborted: %s", goal_id.hex(), exc)
            self._finish(goal, ABORTED, exc.code, str(exc))
            return {"accepted": True, "stamp": now}
        goal.t, goal.q = follow.t, follow.q
        # answered once the planner has checked the goal and the driver took the motion (so an
        # old client's command after this answer is refused), or the goal has ended (refused)
        started = threading.Event()
        threading.Thread(target=self._execute, args=(goal, follow, started), name="ros-goal", daemon=True).start()
        started.wait(START_WAIT_S)
        return {"accepted": True, "stamp": now}

    def _on_get_result(self, request: dict[str, Any], respond: Respond) -> dict[str, Any] | None:
        goal_id = bytes(request["goal_id"]["uuid"])
        with self._lock:
            goal = self._goals.get(goal_id)
            if goal is None:
                return {"status": UNKNOWN, "result": {}}
            if goal.result is None:
                goal.waiters.append(respond)  # answered when the goal ends
                return None
            return {"status": goal.status, "result": goal.result}

    def _on_cancel(self, request: dict[str, Any], _respond: Respond) -> dict[str, Any]:
        info = request["goal_info"]
        goal_id = bytes(info["goal_id"]["uuid"])
        with self._lock:
            if any(goal_id):
                goal = self._goals.get(goal_id)
                if goal is None:
                    return {"return_code": CANCEL_UNKNOWN_GOAL, "goals_canceling": []}
                if goal.status in TERMINAL:
                    return {"return_code": CANCEL_TERMINATED, "goals_canceling": []}
                targets = [goal]
            else:  # a zero id: every goal (accepted before the stamp, when one is given)
                before = _seconds(info["stamp"]) or math.inf
                targets = [g for g in self._goals.values()
                           if g.status not in TERMINAL and _seconds(g.stamp) <= before]
            for goal in targets:
                goal.status, goal.cancel = CANCELING, True
        if targets:
            self._publish_status()
            threading.Thread(target=self._stop, name="ros-cancel", daemon=True).start()
        return {"return_code": CANCEL_OK if targets else CANCEL_REJECTED,
                "goals_canceling": [{"goal_id": {"uuid": list(g.goal_id)}, "stamp": g.stamp} for g in targets]}

    # ------------------------------------------------------------------ the goal
    def _follow_request(self, goal: dict[str, Any]) -> FollowRequest:
        trajectory = goal["trajectory"]
        names = list(trajectory["joint_names"])
        if goal["multi_dof_trajectory"]["joint_names"] or goal["multi_dof_trajectory"]["points"]:
            raise GoalError(INVALID_JOINTS, "multi-DOF joints are not supported; the robot has the joints "
                                            + ", ".join(self.joint_names))
        if sorted(names) != sorted(self.joint_names):
            raise GoalError(INVALID_JOINTS, f"the goal's joints {names} are not the robot's joints "
                                            f"{self.joint_names} (each exactly once, any order)")
        order = [names.index(n) for n in self.joint_names]
        points = trajectory["points"]
        if not points:
            raise GoalError(INVALID_GOAL, "the trajectory has no points")

        def column(point: dict[str, Any], key: str, k: int, required: bool) -> list[float] | None:
            values = point[key]
            if not values and not required:
                return None
            if len(values) != len(names):
                raise GoalError(INVALID_GOAL, f"point {k}: {len(values)} {key} for {len(names)} joints")
            return [math.degrees(values[i]) for i in order]

        t = [_seconds(p["time_from_start"]) for p in points]
        q = [column(p, "positions", k, True) or [] for k, p in enumerate(points)]
        qd = [column(p, "velocities", k, False) for k, p in enumerate(points)]
        qdd = [column(p, "accelerations", k, False) for k, p in enumerate(points)]
        velocities = [v for v in qd if v is not None]
        accelerations = [a for a in qdd if a is not None]
        if 0 < len(velocities) < len(points) or 0 < len(accelerations) < len(points):
            raise GoalError(INVALID_GOAL, "velocities and accelerations must be given for every point or none")
        if accelerations and not velocities:
            raise GoalError(INVALID_GOAL, "accelerations without velocities")
        return FollowRequest(t=t, q=q, qd=velocities or None, qdd=accelerations or None,
                             start_tolerance=self.start_tolerance)

    def _execute(self, goal: Goal, follow: FollowRequest, started: threading.Event) -> None:
        feeding = threading.Event()
        feeder = threading.Thread(target=self._feed, args=(goal, feeding), name="ros-feedback", daemon=True)

        def on_started(_seconds: float, _what: str) -> None:
            """The planner's announcement: the driver took the motion."""
            if started.is_set():
                return
            with self._lock:
                goal.started = time.monotonic()
                if goal.status == ACCEPTED:
                    goal.status = EXECUTING
                cancelled = goal.cancel  # asked before the motion started: stop it now
            self._publish_status()
            feeder.start()
            started.set()
            if cancelled:
                threading.Thread(target=self._stop, name="ros-cancel", daemon=True).start()

        try:
            reply: MoveReply = self.bus.request("planner", "follow", follow, waiting=on_started)
        except BusError as exc:
            reply = MoveReply(ok=False, reason=f"planner: {exc.message}", error=exc.message)
        finally:
            feeding.set()
            if feeder.is_alive():
                feeder.join()
        self._conclude(goal, reply)
        started.set()

    def _conclude(self, goal: Goal, reply: MoveReply) -> None:
        if reply.ok:
            self._finish(goal, SUCCEEDED, SUCCESSFUL, "")
        elif goal.cancel:
            self._finish(goal, CANCELED, SUCCESSFUL, reply.reason or "canceled")
        elif reply.invalid:
            self._finish(goal, ABORTED, INVALID_GOAL, reply.busy or reply.reason)
        else:
            self._finish(goal, ABORTED, PATH_TOLERANCE_VIOLATED, reply.error or reply.reason or "the motion failed")

    def _stop(self) -> None:
        try:
            ack: Ack = self.bus.request("planner", "follow_stop", Empty())
            if not ack.ok:
                log.warning("cancel: %s", ack.reason or ack.error)
        except BusError as exc:
            log.error("cancel: the planner did not stop the arm: %s", exc.message)

    def _feed(self, goal: Goal, done: threading.Event) -> None:
        while not done.wait(FEEDBACK_PERIOD_S):
            state = self.state()
            if state is None:
                continue
            elapsed = time.monotonic() - goal.started
            desired = _interpolate(goal.t, goal.q, elapsed, state.q)
            actual = [math.radians(v) for v in state.q]
            want = [math.radians(v) for v in desired]
            self.feedback.publish({"goal_id": {"uuid": list(goal.goal_id)}, "feedback": {
                "header": {"stamp": _stamp(time.time()), "frame_id": ""}, "joint_names": self.joint_names,
                "desired": {"positions": want, "time_from_start": _stamp(elapsed)},
                "actual": {"positions": actual, "velocities": [math.radians(v) for v in state.qd],
                           "time_from_start": _stamp(elapsed)},
                "error": {"positions": [w - a for w, a in zip(want, actual, strict=True)],
                          "time_from_start": _stamp(elapsed)}}})

    def _finish(self, goal: Goal, status: int, code: int, message: str) -> None:
        with self._lock:
            goal.status, goal.result = status, {"error_code": code, "error_string": message}
            waiters, goal.waiters = goal.waiters, []
        self._publish_status()
        for respond in waiters:
            respond({"status": status, "result": goal.result})

    def _publish_status(self) -> None:
        with self._lock:
            status_list = [{"goal_info": {"goal_id": {"uuid": list(g.goal_id)}, "stamp": g.stamp}, "status": g.status}
                           for g in self._goals.values()]
        self.status.publish({"status_list": status_list})


def _interpolate(t: list[float], q: list[list[float]], at: float, start: list[float]) -> list[float]:
    """The goal's positions at ``at`` seconds, linear between points (from ``start`` before the first)."""
    times = [0.0, *t] if t and t[0] > 0 else list(t)
    points = [start, *q] if t and t[0] > 0 else list(q)
    if not points:
        return list(start)
    if at >= times[-1]:
        return list(points[-1])
    k = max(i for i, ti in enumerate(times) if ti <= at) if at >= times[0] else 0
    s = (at - times[k]) / (times[k + 1] - times[k])
    return [a + s * (b - a) for a, b in zip(points[k], points[k + 1], strict=True)]
