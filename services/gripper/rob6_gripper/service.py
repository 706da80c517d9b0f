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

STATE_PERIOD_S = 0.02  # 50 Hz while a command runs or the state changes: enough to plot a 0.3 s closing motion
#: an idle gripper is sampled this often: a change nobody commanded (a fault, a hand on the
#: jaws) is seen within it, and then sampled at STATE_PERIOD_S again. At 50 Hz the idle
#: sampling cost 0.6-1.1 % of a core (docs/PERFORMANCE.md, the idle system)
STATE_REST_PERIOD_S = 0.2
STATE_HEARTBEAT_S = 1.0  # an unchanged state is published again this often


class GripperService:
    def __init__(self, bus: Bus, backend: GripperBackend, timeout: float = 10.0):
        self.bus = bus
        self.backend = backend
        self.timeout = timeout
        self._stop = threading.Event()
        self._commands = 0  # running now: the state is sampled at STATE_PERIOD_S meanwhile
        self._commands_lock = threading.Lock()
        self._wake = threading.Event()  # a command began, or the service stops
        self._publisher = threading.Thread(target=self._publish_state, name="gripper-state", daemon=True)

    def command(self, req: GripperCommand, ctx: Context) -> GripperReply:
        with self._commands_lock:
            self._commands += 1
        self._wake.set()
        try:
            return self._command(req, ctx)
        finally:
            with self._commands_lock:
                self._commands -= 1

    def _command(self, req: GripperCommand, ctx: Context) -> GripperReply:
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
        """Sample the gripper at 50 Hz while a command runs or the state changes, else every
        ``STATE_REST_PERIOD_S``; publish each change, and at rest a heartbeat every
        ``STATE_HEARTBEAT_S`` (an idle gripper cost every subscriber 50 messages a second)."""
        last: GripperState | None = None
        last_sent = 0.0
        period = STATE_PERIOD_S
        while True:
            self._wake.wait(period)
            self._wake.clear()
            if self._stop.is_set():
                return
            try:
                state = GripperState(**self.backend.state().as_dict())
                now = time.monotonic()
                changed = state != last
                if changed or now - last_sent >= STATE_HEARTBEAT_S:
                    self.bus.publish_state("gripper/state", state)
                    last, last_sent = state, now
                period = STATE_PERIOD_S if changed or self._commands else STATE_REST_PERIOD_S
            except Exception:
                log.exception("could not read the gripper state")
                period = 1.0

    def start(self) -> None:
        self.bus.serve({"command": self.command, "state": self.state}, workers=2)
        self._publisher.start()

    def stop(self) -> None:
        """The publisher ends before the backend and the bus close: it never reads a closed
        port or publishes on a closed session."""
        self._stop.set()
        self._wake.set()
        if self._publisher.is_alive():
            self._publisher.join()
        self.backend.stop()
        self.backend.close()
