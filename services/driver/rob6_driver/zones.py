"""The zone guard: every setpoint the driver commands keeps the arm out of the cell's zones, with room to stop.

Beside the limit monitor (``limits.py``) and as independent of the motion: ``MotionCore``
asks it about each next setpoint of a trajectory or of Alter, with the limits the monitor
enforces, and brakes from the last admitted one instead of commanding one it refuses
(``rob6.cell.guard``: the rule, shared with the planner's check of every path). Stops are
not asked: their travel was accounted for when the setpoint before them was admitted.

It also answers where the arm is nearest to a zone or to itself (``clearance``), which the
driver publishes for the live view and the recording.
"""

from __future__ import annotations

import threading

import numpy as np

from rob6.cell import CellModel, Guard
from rob6.cell.guard import straight
from rob6.messages import Cell, Clearance
from rob6.robots import RobotModel

from .limits import Limits

__all__ = ["ZoneGuard", "ZoneReason", "straight"]


class ZoneReason(str):
    """Why the cell stopped a motion or refused a target: a reason the client is told (the
    gateway's ``ERROR:`` line), where the limit monitor's are only logged."""


class ZoneGuard:
    """The cell's rule for the motion core's cycle. Thread-safe: the cycle, a request (an
    Alter target) and the state's publication take turns on one Pinocchio model (each asks
    for well under a millisecond; a model per thread cost each new thread of Zenoh's a
    model's build, some 100 ms, on the real-time path)."""

    def __init__(self, robot: RobotModel, cell: Cell) -> None:
        self.robot, self.cell = robot, cell
        self._lock = threading.Lock()
        # built now: a cell Pinocchio cannot take fails the start, not the first motion
        self._guard = Guard(CellModel(robot, cell))

    @property
    def empty(self) -> bool:
        """Nothing to check: no zone and no pair of the arm."""
        return self._guard.empty

    def setpoint(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, limits: Limits,
                 along: np.ndarray | None = None) -> ZoneReason | None:
        """Why ``q`` (reached with ``qd``, ``qdd``) may not be commanded: a stop from there would
        not keep the arm out of every zone (None when it may). ``along``: the end of the straight
        trajectory it follows, whose poses ``trajectory`` found clear."""
        with self._lock:
            stop = self._guard.setpoint(q, qd, qdd, limits.vmax, limits.amax, limits.jmax, along=along)
        return ZoneReason(f"stopped before {stop.describe()}") if stop is not None else None

    def trajectory(self, q: np.ndarray, dt: float) -> ZoneReason | None:
        """Why a trajectory (rows of setpoints) may not start: one of its poses is in a zone or
        within the margin (the planner checked it too; the driver does not rely on that)."""
        with self._lock:
            breach = self._guard.poses(q)
        if breach is None:
            return None
        k, stop = breach
        return ZoneReason(f"trajectory refused: at {k * dt:.2f} s {stop.describe()}")

    def target(self, q: np.ndarray) -> ZoneReason | None:
        """Why an Alter target at ``q`` is refused: the pose is in a zone or within the margin (None: it is not)."""
        with self._lock:
            stop = self._guard.pose(q)
        return ZoneReason(f"target refused: {stop.describe()}") if stop is not None else None

    def clearance(self, t: float, q: np.ndarray) -> Clearance | None:
        """The pair nearest at ``q``, for the live view and the recording (None: nothing to measure)."""
        if self.empty:
            return None
        with self._lock:
            distance, pair = self._guard.model.nearest_pair(q)
        return Clearance(t=t, distance_mm=round(distance, 1), part=pair.part, other=pair.other, zone=pair.zone)
