"""The gripper service: the Adept's serial gripper (or its simulation) on the bus."""

from __future__ import annotations

import logging
import threading
import time

from rob6.bus import Bus, Context
from rob6.deadlines import SLACK_S
from rob6.messages import Empty, GripperCommand, GripperReply, GripperState

from .backend import GripperBackend, Result

log = logging.getLogger("rob6.gripper")

STATE_PERIOD_S = 0.02  # 50 Hz: fast enough to plot a 0.3 s closing motion
STATE_HEARTBEAT_S = 1.0  # an unchanged state is published again this often


class GripperService:
    def __init__(self, bus: Bus, backend: GripperBackend, timeout: float = 10.0):
        self.bus = bus
        self.backend = backend
        self.timeout = timeout
        self._stop = threading.Event()
        self._publisher = threading.Thread(target=self._publish_state, name="gripper-state", daemon=True)

    def command(self, req: GripperCommand, ctx: Context) -> GripperReply:
        name, value = req.command, req.value
        bound = self.backend.command_bound_s
        if name == "HasGripper":
            if bound:
                ctx.waiting(bound + SLACK_S, "asking the gripper")
            return GripperReply(ok=self.backend.has_gripper())
        ctx.waiting(self.timeout + 2 * bound + SLACK_S, "waiting for the gripper")  # the backend's own bound
        if name == "GripperGoHome":
            return self._reply(self.backend.go_home(self.timeout))
        if value is None:  # the gateway sends one with every move (it answers ParseError otherwise)
            return GripperReply(ok=False, reason=f"{name} without a value")
        if name == "GripperMove":
            return self._reply(self.backend.move_current(value, self.timeout))
        if name == "GripperMoveToPosition":
            return self._reply(self.backend.move_to_position(value, self.timeout))
        return GripperReply(ok=False, reason=f"unknown gripper command {name!r}")

    @staticmethod
    def _reply(result: Result) -> GripperReply:
        if not result.ok:
            log.warning("gripper: %s", result.error)
        return GripperReply(ok=result.ok, reason=result.error, position=result.position)

    def state(self, _req: Empty, _ctx: Context) -> GripperState:
        return GripperState(**self.backend.state().as_dict())

    def _publish_state(self) -> None:
        """Sample the gripper at 50 Hz; publish each change, and at rest a heartbeat every
        ``STATE_HEARTBEAT_S`` (an idle gripper cost every subscriber 50 messages a second)."""
        last: GripperState | None = None
        last_sent = 0.0
        while not self._stop.wait(STATE_PERIOD_S):
            try:
                state = GripperState(**self.backend.state().as_dict())
                now = time.monotonic()
                if state != last or now - last_sent >= STATE_HEARTBEAT_S:
                    self.bus.publish("gripper/state", state)
                    last, last_sent = state, now
            except Exception:
                log.exception("could not read the gripper state")
                self._stop.wait(1.0)

    def start(self) -> None:
        self.bus.serve({"command": self.command, "state": self.state}, workers=2)
        self._publisher.start()

    def stop(self) -> None:
        self._stop.set()
        self.backend.stop()
        self.backend.close()
