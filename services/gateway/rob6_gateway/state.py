"""What the gateway keeps between commands: the motion configuration and each
client session's own state.

The planner publishes the motion configuration whenever it changes; the gateway
keeps the latest, so kinematics requests (which need the limits) take one round
trip, not two.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import msgspec

from rob6.bus import Bus, new_cid
from rob6.messages import MotionConfig
from rob6.robots import RobotModel



def default_config(robot: RobotModel) -> MotionConfig:
    """The planner's power-on configuration (used until the planner has told us its own)."""
    return MotionConfig(
        speed=list(robot.default_speed), accel=list(robot.default_accel),
        max_change=list(robot.default_max_change), turn_max=list(robot.turn_max),
        turn_min=list(robot.turn_min), weights=[4.0, 1.0, 1.0, 1.0, 1.0, 1.0],
        allowed=["toggleHand", "toggleElbow", "toggleArm"], rt_speed_control=1,
    )


class ConfigMirror:
    """The planner's motion configuration: from its replies and its publications."""

    def __init__(self, bus: Bus, robot: RobotModel):
        self.config = default_config(robot)
        self._decoder = msgspec.json.Decoder(MotionConfig)
        bus.subscribe("planner/config", self._on_config)

    def _on_config(self, _key: str, payload: bytes) -> None:
        self.config = self._decoder.decode(payload)


@dataclass
class Session:
    """One client connection."""

    number: int
    peer: str
    cid: str = field(default_factory=new_cid)  # of the command being executed
    routetest: list[float] | None = None  # the virtual position while route testing
