"""The planner's check of every path against the cell's safety zones, before anything moves.

The cell is the driver's (it loads ``ROB6_CELL`` and guards every setpoint): the planner
asks it for the cell when the driver appears, and checks each sampled path with the same
rule (``rob6.cell.guard``) and the limits the driver will enforce, so that a path the
planner lets run is one the driver's guard lets finish. A refused path names the zone, the
part and when; nothing moves.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence

import numpy as np

from rob6.bus import Bus, BusError
from rob6.cell import CellModel, Guard
from rob6.messages import Cell, Empty
from rob6.robots import RobotModel

from .trajectory import JointLimits, SampledTrajectory

log = logging.getLogger("rob6.planner")


class CellUnknown(Exception):
    """The driver's cell could not be had: no path can be checked (the message says why)."""


class PathCheck:
    """The driver's cell as the planner checks paths against it. Thread-safe: each worker
    thread has its own Pinocchio data, rebuilt when the cell changes."""

    def __init__(self, bus: Bus, robot: RobotModel) -> None:
        self.bus, self.robot = bus, robot
        self._cell: Cell | None = None
        self._version = 0
        self._lock = threading.Lock()
        self._local = threading.local()

    def fetch(self) -> None:
        """Ask the driver for its cell (it appeared, or the planner started)."""
        try:
            cell: Cell = self.bus.request("driver", "cell", Empty())
        except BusError as exc:
            log.warning("could not get the driver's cell: %s", exc.message)
            return
        with self._lock:
            if cell != self._cell:
                self._cell, self._version = cell, self._version + 1
                log.info("cell %s: %d zones, %d tool shapes, self-collision %s", cell.source, len(cell.zones),
                         len(cell.tool), "on" if cell.self_collision else "off")

    def _guard(self) -> Guard:
        with self._lock:
            cell, version = self._cell, self._version
        if cell is None:
            self.fetch()
            with self._lock:
                cell, version = self._cell, self._version
            if cell is None:
                raise CellUnknown("the driver's cell (safety zones) is not known: the driver does not answer")
        local = self._local
        if getattr(local, "version", None) != version:
            local.guard, local.version = Guard(CellModel(self.robot, cell)), version
        guard: Guard = local.guard
        return guard

    def path(self, trajectory: SampledTrajectory, limits: JointLimits) -> str:
        """Why ``trajectory`` may not run (its first breach of the cell's rule), or "". ``limits``:
        those the driver enforces, with which it would brake."""
        refusal = self._guard().path(trajectory.q, trajectory.qd, trajectory.qdd, trajectory.dt, limits.vmax,
                                     limits.amax, limits.jmax)
        return refusal.message() if refusal is not None else ""

    def escape_share(self, joints: Sequence[float], limits: JointLimits) -> float:
        """The share of the speed limits a motion from ``joints`` may use: below 1 on a way
        out of a zone's margin (``Guard.escape_share``)."""
        return self._guard().escape_share(np.asarray(joints, float), limits.vmax)

    def pose(self, joints: list[float]) -> str:
        """IsPossible: why the arm may not be at ``joints`` (a zone of the lab's cell file, or
        the margin), or "". With the default cell IsPossible answers as the original did: its
        transcripts ask about poses below the floor and count on ``true`` (docs/SAFETY_ZONES.md)."""
        guard = self._guard()
        if not guard.model.cell.from_file:
            return ""
        stop = guard.pose(np.asarray(joints, float))
        return f"pose in the cell's way: {stop.describe()}" if stop is not None else ""
