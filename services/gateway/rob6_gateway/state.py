"""What the gateway knows between commands: the robot, its live joint state, the motion
configuration, the protocol's verbosity, and each client session's own state.

The driver publishes the joint state every cycle and the planner publishes the
motion configuration whenever it changes; the gateway keeps the latest of each so
position queries and kinematics requests need no extra round trip.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import msgspec

from rob6.bus import Bus, new_cid
from rob6.messages import JointState, MotionConfig
from rob6.robots import RobotModel

STATE_STALE_S = 1.0  # a joint state older than this means the driver is not running


def default_config(robot: RobotModel) -> MotionConfig:
    """The planner's power-on configuration (used until the planner has told us its own)."""
    return MotionConfig(
        speed=list(robot.default_speed), accel=list(robot.default_accel),
        max_change=list(robot.default_max_change), turn_max=list(robot.turn_max),
        turn_min=list(robot.turn_min), weights=[4.0, 1.0, 1.0, 1.0, 1.0, 1.0],
        allowed=["toggleHand", "toggleElbow", "toggleArm"], rt_speed_control=1,
    )


class Mirror:
    """Latest joint state and motion configuration, updated from the bus."""

    def __init__(self, bus: Bus, robot: RobotModel):
        self._lock = threading.Lock()
        self._state: JointState | None = None
        self._state_seen = 0.0
        self.config = default_config(robot)
        self._state_decoder = msgspec.json.Decoder(JointState)
        self._config_decoder = msgspec.json.Decoder(MotionConfig)
        bus.subscribe("driver/state", self._on_state)
        bus.subscribe("planner/config", self._on_config)

    def _on_state(self, _key: str, payload: bytes) -> None:
        state = self._state_decoder.decode(payload)
        with self._lock:
            if self._state is None or state.cycle >= self._state.cycle or state.t < self._state.t:
                self._state, self._state_seen = state, time.monotonic()

    def _on_config(self, _key: str, payload: bytes) -> None:
        self.config = self._config_decoder.decode(payload)

    def set_state(self, state: JointState) -> None:
        """A state from a reply (a move just ended): newer than anything published before it."""
        with self._lock:
            self._state, self._state_seen = state, time.monotonic()

    def state(self) -> JointState | None:
        """The current joint state, or None when the driver has not published lately."""
        with self._lock:
            if self._state is None or time.monotonic() - self._state_seen > STATE_STALE_S:
                return None
            return self._state


@dataclass
class Session:
    """One client connection."""

    number: int
    peer: str
    cid: str = field(default_factory=new_cid)  # of the command being executed
    routetest: list[float] | None = None  # the virtual position while route testing
