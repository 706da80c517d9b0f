"""The latest joint state of the robot, kept from the driver's publications.

The driver publishes its state every controller cycle (at rest every 100 ms); the gateway,
which answers position and status reads, keeps the newest one instead of asking.
"""

from __future__ import annotations

import threading
import time

import msgspec

from .bus import Bus
from .messages import JointState

STATE_STALE_S = 0.25  # a joint state older than this means the driver is not running


def replaces(state: JointState, kept: JointState | None) -> bool:
    """Whether a published ``state`` replaces the ``kept`` one: a later cycle of the same
    driver, or another driver instance (a restarted driver counts its cycles again). An
    older cycle, or the same one again, is a publication from before a move that the move's
    reply already reported, arriving after it over another link: kept out, or a read right
    after the move would show where the robot was, and the next move would start there."""
    return kept is None or state.instance != kept.instance or state.cycle > kept.cycle


class JointStateMirror:
    def __init__(self, bus: Bus):
        self.bus = bus
        self._lock = threading.Lock()
        self._state: JointState | None = None
        self._seen = 0.0
        self._decoder = msgspec.json.Decoder(JointState)
        bus.subscribe("driver/state", self._on_state, owner="driver")  # one robot, one driver

    def _on_state(self, _key: str, payload: bytes) -> None:
        state = self._decoder.decode(payload)
        with self._lock:
            if replaces(state, self._state):
                self._state, self._seen = state, time.monotonic()

    def update(self, state: JointState) -> None:
        """A state from a reply (a move just ended): newer than anything published before it."""
        with self._lock:
            self._state, self._seen = state, time.monotonic()

    def get(self) -> JointState | None:
        """The current joint state, or None when the driver is gone or silent."""
        if not self.bus.instances("driver"):
            return None
        with self._lock:
            if self._state is None or time.monotonic() - self._seen > STATE_STALE_S:
                return None
            return self._state
