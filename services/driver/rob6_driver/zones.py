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
import time

import numpy as np

from rob6.cell import CellError, CellModel, Guard
from rob6.cell.guard import ESCAPE_DIP_MM, ESCAPE_SPEED_MM_S, MEASURES_MAX, straight
from rob6.messages import Cell, Clearance
from rob6.robots import RobotModel

from .limits import Limits

__all__ = ["ZoneGuard", "ZoneReason", "straight"]


#: the share of the controller's cycle one setpoint's check may take at worst (measured at start)
CHECK_SHARE = 0.5


class ZoneReason(str):
    """Why the cell stopped a motion or refused a target: a reason the client is told (the
    gateway's ``ERROR:`` line), where the limit monitor's are only logged."""


class ZoneGuard:
    """The cell's rule for the motion core's cycle. Thread-safe: the cycle, a request (an
    Alter target) and the state's publication take turns on one Pinocchio model (each asks
    for well under a millisecond; a model per thread cost each new thread of Zenoh's a
    model's build, some 100 ms, on the real-time path)."""

    def __init__(self, robot: RobotModel, cell: Cell, budget_s: float | None = None) -> None:
        self.robot, self.cell = robot, cell
        self._lock = threading.Lock()
        # built now: a cell Pinocchio cannot take fails the start, not the first motion
        self._guard = Guard(CellModel(robot, cell))
        self.unchecked, self.warnings = self._guard.model.unchecked, self._guard.model.warnings
        budget = CHECK_SHARE * robot.cycle_s if budget_s is None else budget_s
        self.worst_check_s = self._time_worst_check()
        if self.worst_check_s > budget:
            raise CellError(f"cell file {cell.source}: one setpoint's check takes up to {self.worst_check_s * 1e3:.2f} ms "
                            f"here, more than {budget * 1e3:.2f} ms ({CHECK_SHARE:.0%} of the {robot.name}'s "
                            f"{robot.cycle_s * 1e3:g} ms cycle): fewer zones or tool shapes, or self_collision off")
        self._floors: np.ndarray | None = None  # on a way out: how near each pair may come (Guard.floors)

    def _time_worst_check(self) -> float:
        """How long one setpoint's check takes at worst here (s): every distance measurement
        the guard may make for one setpoint (the pose, the way from the last, the reaction,
        the brake's samples: ``MEASURES_MAX`` and four more), timed in this thread's CPU time
        (what the check costs, not how long a busy machine kept the thread waiting for a core:
        under a load average of 30 the wall clock took 8 ms for the default cell and refused
        the start), the fastest of ten."""
        if self.empty:
            return 0.0
        model, runs = self._guard.model, []
        q = np.zeros(6)
        for _ in range(10):
            start = time.thread_time()
            for _ in range(MEASURES_MAX + 4):
                model.distances(q)
            runs.append(time.thread_time() - start)
        return min(runs)

    @property
    def empty(self) -> bool:
        """Nothing to check: no zone and no pair of the arm."""
        return self._guard.empty

    def observe(self, q: np.ndarray) -> str:
        """The arm is at rest at ``q`` (start-up, a link back, a motion about to start): the
        pairs within their margin there may only move away (the way out, ``Guard.floors``).
        Returns one line saying which part is where ("" when every pair keeps its margin)."""
        with self._lock:
            d = self._guard.model.distances(q)
            floors = self._guard.floors_from(d)
            if floors is None:
                self._floors = None
                return ""
            if self._floors is not None:  # what a way out has won is kept, unless the arm was moved in since
                floors = np.where(d > self._floors, np.maximum(self._floors, floors), floors)
            self._floors = floors
            stop = self._guard.pose(q)
        assert stop is not None  # a pair is within its margin
        return f"{stop.describe()}: it may only move away from it, at {ESCAPE_SPEED_MM_S:g} mm/s at most"

    @property
    def escaping(self) -> bool:
        """A pair is within its margin: motions are on the way out."""
        return self._floors is not None

    def escape_share(self, q: np.ndarray, vmax: np.ndarray) -> float:
        """The share of ``vmax`` a motion from ``q`` may use (``Guard.escape_share``)."""
        if self._floors is None:
            return 1.0
        with self._lock:
            return self._guard.escape_share(q, vmax)

    def setpoint(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, limits: Limits,
                 along: np.ndarray | None = None, prev: np.ndarray | None = None) -> ZoneReason | None:
        """Why ``q`` (reached with ``qd``, ``qdd`` from ``prev``) may not be commanded: the way
        there or a stop from there would not keep the arm out of every zone (None when it may).
        ``along``: the end of the straight trajectory it follows, whose poses ``trajectory``
        found clear."""
        with self._lock:
            stop = self._guard.setpoint(q, qd, qdd, limits.vmax, limits.amax, limits.jmax, along=along, prev=prev,
                                        floors=self._floors)
            if stop is None and self._floors is not None:
                self._raise_floors(q)
            hint = stop.hint() if stop is not None and self._floors is not None else ""
        return ZoneReason(f"stopped before {stop.describe()}{hint}") if stop is not None else None

    def _raise_floors(self, q: np.ndarray) -> None:
        """On a way out, what a pair has won is kept: its floor follows it out (lock held)."""
        assert self._floors is not None
        d = self._guard.model.distances(q)
        margins = self._guard.margins
        self._floors = np.where(self._floors < margins, np.minimum(margins, np.maximum(self._floors, d - ESCAPE_DIP_MM)),
                                margins)
        if (self._floors >= margins).all():
            self._floors = None

    def trajectory(self, q: np.ndarray, dt: float) -> ZoneReason | None:
        """Why a trajectory (rows of setpoints, joined by straight lines) may not start: one of
        its poses is in a zone or within the margin, or on a way out nearer than it starts
        (the planner checked it too; the driver does not rely on that)."""
        self.observe(q[0])
        with self._lock:
            breach = self._guard.poses(q, floors=self._floors)
        if breach is None:
            return None
        at, stop = breach
        return ZoneReason(f"trajectory refused: at {at * dt:.2f} s {stop.describe()}")

    def target(self, q: np.ndarray) -> ZoneReason | None:
        """Why an Alter target at ``q`` is refused: the pose is in a zone or within the margin,
        or on a way out nearer than the arm has been (None: it is not)."""
        with self._lock:
            stop = self._guard.pose(q, self._floors)
            hint = stop.hint() if stop is not None and self._floors is not None else ""
        return ZoneReason(f"target refused: {stop.describe()}{hint}") if stop is not None else None

    def clearance(self, t: float, q: np.ndarray) -> Clearance | None:
        """The pair nearest at ``q``, for the live view and the recording (None: nothing to measure)."""
        if self.empty:
            return None
        with self._lock:
            distance, pair = self._guard.model.nearest_pair(q)
        return Clearance(t=t, distance_mm=round(distance, 1), part=pair.part, other=pair.other, zone=pair.zone)
