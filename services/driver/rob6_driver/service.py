"""The driver service: owns the robot, runs the controller cycle, publishes joint state.

The motion core (``motion.MotionCore``) executes the planner's sampled trajectories,
follows Alter targets with Ruckig, and checks every setpoint against the limits on
its own, whatever the planner sent. The link (``links/``) owns the clock and reaches
the plant: ``sim``, the simulation (default), ``rsi``, a KUKA KR C4 over RSI, or
``simple_message`` (also called ``adept``), an Adept V+ controller over ROS-Industrial
simple_message, or ``kawasaki``, a Kawasaki controller running rob6's AS program. A motion's ``true`` waits for the link to confirm the robot arrived.

The Adept's digital outputs (``signal``: V+ SIGNAL, DirectAdeptCmd signal 5, -6) are
switched through the link (the simulation's own, or the V+ program's I/O port) and
published with every joint state (``outputs``).

A failure of the plant (robot not connected, link lost) comes back in the replies'
``error`` field, which the gateway shows the client as ``ERROR: driver: <error>``;
an ordinary refusal (busy, limits) only has ``reason`` and the client sees ``false``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any

from rob6.bus import Bus, Context
from rob6.cell import default_cell
from rob6.deadlines import arm_s
from rob6.messages import (
    Ack,
    AlterMode,
    AlterTarget,
    Cell,
    Empty,
    ExecuteReply,
    ExecuteRequest,
    JointState,
    LimitsUpdate,
    LinkEvent,
    LinkQuery,
    LinkStatus,
    PingReply,
    SignalRequest,
)
from rob6.robots import RobotModel
from rob6.vplus import check_signals

from .links import Link
from .links.kawasaki import KawasakiLink, KawasakiSettings
from .links.rsi import DEFAULT_LISTEN, DEFAULT_SEN_TYPE, RsiLink
from .links.sim import SimLink
from .links.simple_message import AdeptLink, AdeptSettings
from .motion import CoreState, Motion, MotionCore, Offline
from .zones import ZoneGuard, ZoneReason

log = logging.getLogger("rob6.driver")

STOPPING = "waiting for the arm to stop"
#: why a motion ended when its caller stopped it (``stop``): on purpose, not a fault
STOP_REQUESTED = "stop requested"
#: a state that differs from the last one published only in its time and cycle (the robot
#: at rest) is published this often, not every cycle: each subscriber of a 250 Hz stream
#: (gateway, recorder, live view) pays 2-4 % of a core for it (issue 13), and each state at
#: rest costs the recorder its trace batch (docs/PERFORMANCE.md, "The idle system"). 10 Hz,
#: the rate of ROS's joint_state_publisher. Nothing is lost: until the next state, the robot
#: is where the last one says. Well below the gateway's rob6.state.STATE_STALE_S (two states
#: may go missing), so a silent driver is still told from a resting robot.
REST_STATE_PERIOD_S = 0.1
#: while the arm moves, the clearance to the cell's zones is published this often (driver clock)
CLEARANCE_PERIOD_S = 0.1
#: at most this long a switched output waits for the next cycle's state to carry it
SIGNAL_PUBLISH_WAIT_S = 0.5
#: a motion slowed to its arm's pace announces its longer bound each time it grew this much (s)
REANNOUNCE_S = 0.5


class DriverService:
    def __init__(self, bus: Bus, robot: RobotModel, dummy: bool, alter_timeout_s: float = 0.5, *,
                 link: str = "sim", rsi_listen: str = DEFAULT_LISTEN, rsi_sen_type: str = DEFAULT_SEN_TYPE,
                 sm: AdeptSettings | None = None, kas: KawasakiSettings | None = None,
                 cell: Cell | None = None) -> None:
        self.bus = bus
        self.robot = robot
        self.cell = cell or default_cell(robot)
        self.zones = ZoneGuard(robot, self.cell)
        self.cell.unchecked = list(self.zones.unchecked)  # GetCell says which pairs are not measured, and why
        self.core = MotionCore(robot, dummy=dummy, alter_timeout_s=alter_timeout_s, on_event=self._on_event,
                               zones=self.zones)
        self._clearance_t = -math.inf  # driver clock of the last clearance published
        self._clearance_q: list[float] | None = None  # and the joints it was measured at
        self._published: tuple[object, ...] | None = None  # the last published state without t and cycle
        self._published_t = 0.0
        self._published_outputs: list[int] = []  # in the last published state
        self._outputs_published = threading.Condition()
        self.link: Link
        if link == "rsi":
            self.link = RsiLink(self.core, robot, rsi_listen, self._publish, self._publish_link_event,
                                sen_type=rsi_sen_type)
        elif link in ("simple_message", "adept"):
            self.link = AdeptLink(self.core, robot, sm or AdeptSettings(), self._publish, self._publish_link_event)
        elif link == "kawasaki":
            self.link = KawasakiLink(self.core, robot, kas or KawasakiSettings(), self._publish,
                                     self._publish_link_event)
        elif link == "sim":
            self.link = SimLink(self.core, self._publish)
        else:
            raise ValueError(f"unknown link {link!r} (sim, rsi, simple_message or kawasaki)")

    def joint_state(self, state: CoreState) -> JointState:
        link = self.link
        return JointState(t=state.t, cycle=state.cycle, q=state.q.tolist(), qd=state.qd.tolist(),
                          moving=bool(state.moving), mode=state.mode, missed=link.missed,
                          instance=self.bus.instance, link=link.state, late=link.late, q_actual=link.q_actual,
                          outputs=link.outputs())

    def _publish(self, state: CoreState) -> None:
        """Every cycle's state, except at rest (``REST_STATE_PERIOD_S``); with it the clearance to
        the cell's zones, while the arm moves every ``CLEARANCE_PERIOD_S``, and where it stops."""
        message = self.joint_state(state)
        content = (message.q, message.qd, message.moving, message.mode, message.missed, message.link,
                   message.late, message.q_actual, message.outputs)
        if content == self._published and 0.0 <= message.t - self._published_t < REST_STATE_PERIOD_S:
            return
        self._published, self._published_t = content, message.t
        self.bus.publish_state("driver/state", message)
        # where the arm comes to rest too, whenever the period has not run out there
        if message.q != self._clearance_q and (not message.moving
                                               or not 0.0 <= message.t - self._clearance_t < CLEARANCE_PERIOD_S):
            self._clearance_t, self._clearance_q = message.t, message.q
            clearance = self.zones.clearance(message.t, state.q)
            if clearance is not None:
                self.bus.publish_state("driver/clearance", clearance)
        if message.outputs != self._published_outputs:
            with self._outputs_published:
                self._published_outputs = message.outputs
                self._outputs_published.notify_all()

    def _publish_link_event(self, event: LinkEvent) -> None:
        # a record, like the traces: queued, so the link's thread never waits for the network
        # (a BLOCK publication could, towards a partitioned recorder), and kept in the trace
        # cache for a recorder that was away
        self.bus.trace("driver/link", event)

    def _on_event(self, event: dict[str, Any]) -> None:
        if event.get("type") == "violation" and event.get("kind") == "zone":  # the guard did its job
            log.warning("zones: %s", event.get("message"))
        elif event.get("type") == "violation":
            log.error("limit monitor: %s", event.get("message"))
        else:
            log.info("driver event: %s", event)

    # ---- operations ----------------------------------------------------------
    def ping(self, _req: Empty, _ctx: Context) -> PingReply:
        return PingReply(robot_time=self.core.t, wall_time=time.time())

    def state(self, _req: Empty, _ctx: Context) -> JointState:
        return self.joint_state(self.core.state())

    def execute(self, req: ExecuteRequest, ctx: Context) -> ExecuteReply:
        trajectory = req.trajectory
        motion = self.core.execute(trajectory.q, trajectory.dt, trajectory.qd, trajectory.qdd)
        if not req.wait and not (motion.done.is_set() and not motion.ok):
            return ExecuteReply(ok=True)
        duration = len(trajectory.q) * trajectory.dt
        if not self._ended(motion, duration, ctx):
            self.core.stop("the motion did not end in time")
            return ExecuteReply(ok=False, reason="the motion did not end in time",
                                state=self.joint_state(self.core.state()))
        final = motion.final or self.core.state()
        if motion.ok or (motion.started and not motion.error):
            # the setpoints are done, or stopped on the ramp: a robot that lags behind them
            # must be there too before the reply says where it rests
            failed = self.link.settle(final.q, waiting=ctx.waiting)
            if failed:
                log.info("motion failed: %s", failed)
                return ExecuteReply(ok=False, reason=failed, error=failed, state=self.joint_state(self.core.state()))
        if motion.error:  # the link already said why, at WARNING
            log.info("motion failed: %s", motion.error)
        elif not motion.ok:  # stopped on request (a client's Stop or its leaving, rob6 stopping) is no fault
            log.log(logging.INFO if motion.reason == STOP_REQUESTED else logging.WARNING,
                    "trajectory refused or stopped: %s", motion.reason)
        return ExecuteReply(ok=bool(motion.ok), reason=str(motion.reason or ""), error=motion.error,
                            state=self.joint_state(final), zone=_zone(motion.reason))

    def _ended(self, motion: Motion, duration: float, ctx: Context) -> bool:
        """Wait for a trajectory of ``duration`` s to end, announced to the caller: its bound,
        then the link's own check that the robot arrived. A link that paces the core by its
        arm (``MotionCore.held_back_s``) makes it longer: the bound grows with it, announced
        again each time it has grown by ``REANNOUNCE_S``."""
        if motion.done.is_set() and self.link.settle_bound_s == 0.0:  # a dummy's is done
            return True
        what = f"waiting for the {duration:.1f} s motion"
        began, held = time.monotonic(), 0.0
        deadline = began + arm_s(duration)
        ctx.waiting(deadline - began + self.link.settle_bound_s, what)
        while not motion.wait(max(0.0, min(deadline - time.monotonic(), REANNOUNCE_S))):
            if self.core.held_back_s >= held + REANNOUNCE_S:
                held = self.core.held_back_s
                deadline = began + arm_s(duration + held)
                ctx.waiting(deadline - time.monotonic() + self.link.settle_bound_s, f"{what}, slowed to its arm's pace")
            elif time.monotonic() >= deadline:
                return False
        return True

    def limits(self, req: LimitsUpdate, _ctx: Context) -> Ack:
        ok, reason = self.core.set_limits(req.turn_min, req.turn_max, req.max_speed, req.max_accel,
                                          req.max_change)
        return Ack(ok=ok, reason=reason)

    def _at_rest(self, stop: Motion, ctx: Context) -> bool:
        """Wait for ``stop`` to complete (the robot at rest), bounded by the stop ramp."""
        if stop.done.is_set():
            return True
        bound = arm_s(self.core.stop_bound_s())
        ctx.waiting(bound, STOPPING)
        return stop.wait(bound)

    def alter_mode(self, req: AlterMode, ctx: Context) -> Ack:
        if req.enable:
            stop = self.core.stopping()  # Alter starts at rest: a stop in progress ends first
            if stop is not None and not self._at_rest(stop, ctx):
                return Ack(ok=False, reason="the robot did not come to rest in time")
            try:
                ok, reason = self.core.enable_alter(req.synchronized, req.timeout_s)
            except Offline as exc:
                return Ack(ok=False, reason=str(exc), error=str(exc))
            return Ack(ok=ok, reason=reason)
        return self._stopped(self.core.disable_alter(), ctx)  # done once the robot is at rest

    def alter_target(self, req: AlterTarget, _ctx: Context) -> Ack:
        try:
            ok, reason = self.core.set_target(req.q, req.synchronized, req.relative)
        except Offline as exc:
            return Ack(ok=False, reason=str(exc), error=str(exc))
        return Ack(ok=ok, reason=str(reason), zone=_zone(reason))

    def get_cell(self, _req: Empty, _ctx: Context) -> Cell:
        """The cell this driver guards (``ROB6_CELL``): the planner checks every path against it."""
        return self.cell

    def stop(self, _req: Empty, ctx: Context) -> Ack:
        """Stop whatever runs (a trajectory, Alter) with the ramp; ``ok``: at rest."""
        return self._stopped(self.core.stop(STOP_REQUESTED), ctx)

    def _stopped(self, stop: Motion, ctx: Context) -> Ack:
        """The answer to an operation that stops the arm: at rest (with the state there,
        where the next motion starts; a link whose arm lags behind the setpoints waits for
        the arm to rest there too), or not in time."""
        if not self._at_rest(stop, ctx):
            return Ack(ok=False, reason="the robot did not come to rest in time")
        final = stop.final or self.core.state()
        if self.link.settle_bound_s and not self.core.offline_reason:  # an arm that lags: at rest too
            ctx.waiting(self.link.settle_bound_s, STOPPING)
            failed = self.link.settle(final.q, waiting=ctx.waiting)
            if failed:
                return Ack(ok=False, reason=failed, error=failed, state=self.joint_state(self.core.state()))
        return Ack(ok=True, state=self.joint_state(final))

    def signal(self, req: SignalRequest, ctx: Context) -> Ack:
        """Switch the Adept's digital outputs; the numbers are checked again here (rob6.vplus),
        so nothing reaches the controller that V+ SIGNAL would not take."""
        if not self.robot.is_adept:
            return Ack(ok=False, reason=f"{self.robot.name} has no V+ digital outputs")
        problem = check_signals(req.signals)
        if problem:
            return Ack(ok=False, reason=problem)
        ctx.waiting(self.link.signal_bound_s(len(req.signals)) + SIGNAL_PUBLISH_WAIT_S,
                    f"waiting for the controller to switch {len(req.signals)} outputs")
        failed = self.link.signal(req.signals)
        if failed:
            return Ack(ok=False, reason=failed, error=failed)
        # answered once a published state shows them (the next cycle): whoever reads the
        # state after the reply sees the change, and the recording has every change
        switched = self.link.outputs()
        with self._outputs_published:
            self._outputs_published.wait_for(lambda: self._published_outputs == switched, SIGNAL_PUBLISH_WAIT_S)
        return Ack()

    def link_status(self, req: LinkQuery, _ctx: Context) -> LinkStatus:
        return self.link.status(reset=req.reset)

    def _on_liveliness(self, service: str, _instance: str, alive: bool) -> None:
        """The planner supervises every motion: without one, the robot stops (ramped)."""
        if service == "planner" and not alive and not self.bus.instances("planner") and self.core.state().moving:
            log.warning("the planner went away during a motion: stopping")
            self.core.stop("planner went away")

    def start(self) -> None:
        cell = self.cell
        # shown at the default level, as the gateway's and the router's start lines: which cell this run guards
        log.warning("cell %s: %d zones, %d tool shapes, margin %g mm, sha256 %s", cell.source, len(cell.zones),
                    len(cell.tool), cell.margin_mm, cell.sha256 or "(none)")
        for warning in self.zones.warnings:
            log.warning("cell %s: %s", cell.source, warning)
        log.info("cell %s: one setpoint's check takes up to %.2f ms here; pairs not measured: %s", cell.source,
                 self.zones.worst_check_s * 1e3, "; ".join(cell.unchecked) or "none")
        if where := self.zones.observe(self.core.state().q):
            log.warning("cell %s: the robot is at a pose where %s", cell.source, where)
        self.bus.on_liveliness(self._on_liveliness)
        self.link.start()
        self.bus.serve({"ping": self.ping, "state": self.state, "execute": self.execute,
                        "limits": self.limits, "alter_mode": self.alter_mode,
                        "alter_target": self.alter_target, "stop": self.stop,
                        "link": self.link_status, "signal": self.signal, "cell": self.get_cell}, workers=4,
                       inline=("ping", "state", "alter_target", "link", "cell"))

    def shutdown(self) -> None:
        self.core.stop("driver shutting down").wait(arm_s(self.core.stop_bound_s()))
        self.link.stop()
        status = self.link.status()
        log.info("driver: %d cycles, %d missed, %d late", status.packets, status.missed, status.late)


def _zone(reason: str | None) -> str:
    """The reason again when the cell gave it (``ZoneReason``: the client is told), else ""."""
    return str(reason) if isinstance(reason, ZoneReason) else ""
