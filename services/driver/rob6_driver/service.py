"""The driver service: owns the robot, runs the controller cycle, publishes joint state.

The robot here is the simulation (``sim.SimRobot``): it runs at the controller cycle
of the robot type, executes the planner's sampled trajectories in real time, follows
Alter targets with Ruckig, and checks every commanded sample against the limits on
its own, whatever the planner sent.
"""

from __future__ import annotations

import logging
import time

from rob6.bus import Bus
from rob6.messages import (
    Ack,
    AlterMode,
    AlterTarget,
    Empty,
    ExecuteReply,
    ExecuteRequest,
    JointState,
    LimitsUpdate,
    PingReply,
)
from rob6.robots import RobotModel

from .loop import CycleRunner
from .sim import SimRobot, SimState

log = logging.getLogger("rob6.driver")

EXECUTE_MARGIN_S = 5.0  # beyond the trajectory's own duration


def joint_state(state: SimState, missed: int = 0) -> JointState:
    return JointState(t=state.t, cycle=state.cycle, q=state.q.tolist(), qd=state.qd.tolist(),
                      moving=bool(state.moving), mode=state.mode, missed=missed)


class DriverService:
    def __init__(self, bus: Bus, robot: RobotModel, dummy: bool, alter_timeout_s: float = 0.5):
        self.bus = bus
        self.robot = robot
        self.sim = SimRobot(robot, dummy=dummy, alter_timeout_s=alter_timeout_s, on_event=self._on_event)
        self.runner = CycleRunner(self.sim.step, robot.cycle_s, self._publish, name="driver-cycle")

    def _publish(self, state: SimState) -> None:
        self.bus.publish("driver/state", joint_state(state, self.runner.stats.missed))

    def _on_event(self, event: dict) -> None:
        if event.get("type") == "violation":
            log.error("limit monitor: %s", event.get("message"))
        else:
            log.info("driver event: %s", event)

    # ---- operations ----------------------------------------------------------
    def ping(self, _req: Empty, _ctx) -> PingReply:
        return PingReply(robot_time=self.sim.t, wall_time=time.time())

    def state(self, _req: Empty, _ctx) -> JointState:
        return joint_state(self.sim.state(), self.runner.stats.missed)

    def execute(self, req: ExecuteRequest, _ctx) -> ExecuteReply:
        trajectory = req.trajectory
        motion = self.sim.execute(trajectory.q, trajectory.dt, trajectory.qd, trajectory.qdd)
        if not req.wait:
            return ExecuteReply(ok=True)
        duration = len(trajectory.q) * trajectory.dt
        if not motion.wait(duration + EXECUTE_MARGIN_S):
            self.sim.stop("the motion did not end in time")
            return ExecuteReply(ok=False, reason="the motion did not end in time",
                                state=joint_state(self.sim.state()))
        final = motion.final or self.sim.state()
        if not motion.ok:
            log.warning("trajectory refused or stopped: %s", motion.reason)
        return ExecuteReply(ok=bool(motion.ok), reason=motion.reason or "", state=joint_state(final))

    def limits(self, req: LimitsUpdate, _ctx) -> Ack:
        ok, reason = self.sim.set_limits(req.turn_min, req.turn_max, req.max_speed, req.max_accel)
        return Ack(ok=ok, reason=reason)

    def alter_mode(self, req: AlterMode, _ctx) -> Ack:
        if req.enable:
            ok, reason = self.sim.enable_alter(req.synchronized, req.timeout_s)
            return Ack(ok=ok, reason=reason)
        stopped = self.sim.disable_alter().wait(10.0)  # done once the robot is at rest
        return Ack(ok=stopped, reason="" if stopped else "the robot did not come to rest in time")

    def alter_target(self, req: AlterTarget, _ctx) -> Ack:
        ok, reason = self.sim.set_target(req.q, req.synchronized)
        return Ack(ok=ok, reason=reason)

    def stop(self, _req: Empty, _ctx) -> Ack:
        motion = self.sim.stop("stop requested")
        return Ack(ok=motion.wait(4.0) and bool(motion.ok), reason=motion.reason or "")

    def _on_liveliness(self, service: str, _instance: str, alive: bool) -> None:
        """The planner supervises every motion: without one, the robot stops (ramped)."""
        if service == "planner" and not alive and not self.bus.instances("planner"):
            if self.sim.state().moving:
                log.warning("the planner went away during a motion: stopping")
                self.sim.stop("planner went away")

    def start(self) -> None:
        self.bus.on_liveliness(self._on_liveliness)
        self.runner.start()
        self.bus.serve({"ping": self.ping, "state": self.state, "execute": self.execute,
                        "limits": self.limits, "alter_mode": self.alter_mode,
                        "alter_target": self.alter_target, "stop": self.stop}, workers=4)

    def shutdown(self) -> None:
        self.sim.stop("driver shutting down").wait(2.0)
        self.runner.stop()
        log.info("driver: %d cycles, %d missed", self.runner.stats.cycles, self.runner.stats.missed)
