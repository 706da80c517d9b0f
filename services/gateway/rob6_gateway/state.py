"""What the gateway keeps between commands: the motion configuration and each session's state.

What the gateway keeps between commands: the motion configuration and each
client session's own state.

The planner publishes the motion configuration whenever it changes; the gateway
keeps the latest, so kinematics requests (which need the limits) take one round
trip, not two.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
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
        turn_min=list(robot.turn_min), weights=list(robot.default_weights),
        allowed=["toggleHand", "toggleElbow", "toggleArm"], rt_speed_control=1,
    )


class ConfigMirror:
    """The planner's motion configuration: from its replies and its publications.

    ``current()`` answers configuration reads without a bus round trip, but only with
    a configuration known to come from the planner instance alive now (a restarted
    planner starts from its defaults: until its configuration arrived, reads ask it).
    Every Set updates the mirror from the planner's reply before the client gets its
    answer, so a read after a Set always shows it.
    """

    def __init__(self, bus: Bus, robot: RobotModel):
        self.bus = bus
        self.config = default_config(robot)  # what kinematics requests use until the planner's is known
        self._source: str | None = None  # the planner instance ``config`` came from
        self._lock = threading.Lock()
        self._decoder = msgspec.json.Decoder(MotionConfig)
        bus.subscribe("planner/config", self._on_config, owner="planner")

    def _on_config(self, _key: str, payload: bytes) -> None:
        self.set(self._decoder.decode(payload))

    def set(self, config: MotionConfig) -> None:
        source = self.bus.owner("planner")
        with self._lock:  # publications (Zenoh's thread) and replies (the session's thread) may cross
            if source != self._source or config.version >= self.config.version:
                self.config, self._source = config, source

    def current(self) -> MotionConfig | None:
        source = self._source
        return self.config if source is not None and source == self.bus.owner("planner") else None


@dataclass
class Session:
    """One client connection."""

    number: int
    peer: str
    cid: str = field(default_factory=new_cid)  # of the command being executed
    routetest: list[float] | None = None  # the virtual position while route testing
    seq: int = 0  # client exchanges recorded so far (ClientExchange.seq of the last one)
    #: has the client's connection closed? Asked while a move waits (``Bus.request``'s
    #: ``abandon``): the move is then abandoned and the robot stops. The server reads the
    #: socket here (``Connection.poll``); without a connection, never.
    client_gone: Callable[[], bool] = lambda: False
