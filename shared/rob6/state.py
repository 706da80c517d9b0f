"""The latest joint state of the robot, kept from the driver's publications.

The driver publishes its state every controller cycle (at rest every 100 ms); the gateway,
which answers position and status reads, keeps the newest one instead of asking. Zenoh holds
the states that arrive (``Bus.subscribe_latest``) and the mirror takes them when it is read and
every ``STATE_TAKE_S``, so no Python runs for each of the 250 states a second while the arm
moves: in the gateway, a state's callback took the interpreter just as the driver's replies
came, which cost a 250 Hz Alter stream a fifth of its p99 (docs/PERFORMANCE.md, "The gateway's
mirror of the joint state").
"""

from __future__ import annotations

import logging
import threading
import time

import msgspec

from .bus import Bus
from .messages import JointState

log = logging.getLogger("rob6.state")

STATE_STALE_S = 0.25  # a joint state older than this means the driver is not running
#: how often the mirror takes the states that arrived when nobody reads: a state counts as
#: arrived when the take before the one that found it was made, so a state is judged at most
#: this much older than it is, and a silent driver is told within STATE_STALE_S
STATE_TAKE_S = 0.05


def replaces(state: JointState, kept: JointState | None) -> bool:
    """Whether a published ``state`` replaces the ``kept`` one: a later cycle of the same
    driver, or another driver instance (a restarted driver counts its cycles again). An
    older cycle, or the same one again, is a publication from before a move that the move's
    reply already reported, arriving after it over another link: kept out, or a read right
    after the move would show where the robot was, and the next move would start there."""
    return kept is None or state.instance != kept.instance or state.cycle > kept.cycle


class JointStateMirror:
    """The driver's newest joint state, and how fresh it is (see the module's text)."""

    def __init__(self, bus: Bus):
        self.bus = bus
        self._lock = threading.Lock()
        self._state: JointState | None = None
        self._seen = 0.0  # when the kept state had arrived at the latest
        self._taken = time.monotonic()  # the last take
        self._decoder = msgspec.json.Decoder(JointState)
        self._states = bus.subscribe_latest("driver/state", owner="driver")  # one robot, one driver
        threading.Thread(target=self._take_often, name="joint-state-mirror", daemon=True).start()

    def _take_often(self) -> None:
        while not self.bus.closed.wait(STATE_TAKE_S):
            try:
                self._take()
            except Exception:  # the next take tries again; a closing bus ends the loop
                if not self.bus.closed.is_set():
                    log.exception("taking the driver's states failed")

    def _take(self) -> None:
        with self._lock:
            arrived_after, self._taken = self._taken, time.monotonic()
            for payload in self._states.take():
                try:
                    state = self._decoder.decode(payload)
                except msgspec.DecodeError:  # one bad state must not cost the others
                    log.exception("a driver state that is not one: %r", payload[:200])
                    continue
                if replaces(state, self._state):
                    self._state, self._seen = state, arrived_after

    def update(self, state: JointState) -> None:
        """A state from a reply (a move just ended): newer than anything published before it."""
        with self._lock:
            self._state, self._seen = state, time.monotonic()

    def get(self) -> JointState | None:
        """The current joint state, or None when the driver is gone or silent."""
        if not self.bus.instances("driver"):
            return None
        self._take()
        with self._lock:
            if self._state is None or time.monotonic() - self._seen > STATE_STALE_S:
                return None
            return self._state
