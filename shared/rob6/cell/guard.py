"""The rule of the safety zones: no part comes nearer a zone, or another part, than the margin plus what a stop from there travels.

One rule for the planner (every sample of a path, before anything moves) and the driver
(every setpoint, Alter streams above all): a setpoint is admitted only if, were the arm to
brake from it at once (the driver's jerk-limited stop, with the limits it enforces), every
part would stay farther than ``margin_mm`` from every zone and from every part it may not
touch, all the way to rest. The driver brakes from the last admitted setpoint instead of
commanding one that breaks the rule, so the arm comes to rest on its ramp outside every
zone, and the rule holds there too.

How far a stop travels is bounded in three steps, each only when the one before cannot
show enough room: (1) a bound of the brake's joint travel from the speed and acceleration
alone; (2) the joint travel of the brake itself (Ruckig, as the driver plans it); (3) the brake's path sampled, each sample's distances
measured and the motion between samples bounded by what both ends' distances leave (a
segment they do not cover is halved, within ``MEASURES_MAX`` measurements), so an arm
moving away from a zone it is near may go. ``CellModel.lever`` turns joint travel
into a bound of how far any point of a part moves, in every configuration, so each step is
conservative: the arm may stop a little farther out than needed, never nearer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ruckig

from .model import N_JOINTS, CellModel, Pair

#: the brake's path is sampled at this period at most (step 3), and at most this often
BRAKE_SAMPLE_S = 0.05
BRAKE_SAMPLES_MAX = 12
#: the most distance measurements one setpoint's check makes on a brake's path (step 3): its
#: cost stays within the driver's cycle (docs/SAFETY_ZONES.md has the figures)
MEASURES_MAX = 24
#: how far (deg) a sample may be off the line and still count as on it (``straight``)
STRAIGHT_TOL = 1e-6
#: how many samples of a path one measured sample's bound covers at most
LOOK_AHEAD = 256
#: limits below this (deg/s^2, deg/s^3) freeze a joint: it does not move, so it adds no travel
FROZEN = 1e-9


@dataclass(frozen=True)
class Stop:
    """Why a pose or setpoint breaks the rule: the pair, how far apart it is (mm, < 0 inside)
    and how far it had to be (the margin plus a stop's travel)."""

    pair: Pair
    distance_mm: float
    needed_mm: float
    margin_mm: float
    index: int  # of the pair in ``CellModel.pairs``

    def describe(self) -> str:
        """``tool tip 12 mm inside keep-out 'table'``, ``link_6 40 mm from keep-out 'table',
        a stop there needs 65 mm``..."""
        p, d = self.pair, self.distance_mm
        other = f"keep-{p.keep} '{p.other}'" if p.zone else p.other
        if d < 0:
            where = "outside" if p.keep == "in" else "inside" if p.zone else "into"
            return f"{p.part} {-d:.0f} mm {where} {other}"
        if d <= self.margin_mm:
            return f"{p.part} {d:.0f} mm from {other}, within the {self.margin_mm:g} mm margin"
        return f"{p.part} {d:.0f} mm from {other}, a stop there needs {self.needed_mm:.0f} mm"

    @property
    def zone_name(self) -> str:
        """``keep-out 'table'``, or the other part for a pair of the arm."""
        return f"keep-{self.pair.keep} '{self.pair.other}'" if self.pair.zone else self.pair.other


@dataclass(frozen=True)
class PathRefusal:
    """A path that breaks the rule: the first time it does, and how."""

    stop: Stop
    t: float  # seconds from the start of the path
    deepest_mm: float  # the pair's least distance along the whole path
    moving: bool  # only too fast to stop there: every pose of the path keeps the margin

    def message(self) -> str:
        """``path enters keep-out 'table' at 0.82 s (tool tip 12 mm inside)`` and its kin."""
        p, at, other = self.stop.pair, f"at {self.t:.2f} s", self.stop.zone_name
        depth = -self.deepest_mm
        if self.moving:
            return f"path passes {other} {at} too fast to stop before it ({self.stop.describe()})"
        if depth > 0 and p.zone:
            verb, where = ("leaves", "outside") if p.keep == "in" else ("enters", "inside")
            return f"path {verb} {other} {at} ({p.part} {depth:.0f} mm {where})"
        if depth > 0:
            return f"path collides {p.part} with {other} {at} ({depth:.0f} mm deep)"
        margin = f"the {self.stop.margin_mm:g} mm margin of"
        if p.zone:
            return f"path comes within {margin} {other} {at} ({p.part} {-depth:.0f} mm away)"
        return f"path brings {p.part} within {margin} {other} {at} ({-depth:.0f} mm apart)"


class Guard:
    """The rule for one robot's cell (see the module doc); not thread-safe (one per thread)."""

    def __init__(self, model: CellModel) -> None:
        self.model = model
        self.margin = model.cell.margin_mm
        self._otg = ruckig.Ruckig(N_JOINTS)
        self._inp = ruckig.InputParameter(N_JOINTS)
        self._inp.control_interface = ruckig.ControlInterface.Velocity
        self._inp.target_velocity = [0.0] * N_JOINTS
        self._inp.target_acceleration = [0.0] * N_JOINTS

    @property
    def empty(self) -> bool:
        """Nothing to check (no zone, no pair of the arm)."""
        return not self.model.pairs

    def pose(self, q: np.ndarray) -> Stop | None:
        """The pose alone (at rest): every pair farther apart than the margin."""
        if self.empty or self.model.nearest(q) > self.margin:
            return None
        return self._worst(self.model.distances(q), 0.0)

    def setpoint(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
                 jmax: np.ndarray, along: np.ndarray | None = None) -> Stop | None:
        """A setpoint ``q`` (deg) reached with ``qd``, ``qdd`` (deg/s, deg/s^2): would a stop
        from there (limits in deg/s, deg/s^2, deg/s^3) keep every pair apart? None: yes.
        ``along``: the end of a straight path (in joint space) from ``q`` whose poses are known
        to be clear (``poses``): a brake that stays on it is clear too."""
        if self.empty:
            return None
        room = self.model.nearest(q) - self.margin
        if room <= 0:
            return self._worst(self.model.distances(q), 0.0)
        if not qd.any() and not qdd.any():
            return None
        # (1) the brake's joint travel bounded from the state alone
        bound = _brake_bound(qd, qdd, amax, jmax)
        if room > self.model.travel(bound).max():
            return None
        if along is not None and _on_segment(q, qd, qdd, along, bound):
            return None  # the brake's path is the rest of a path whose poses are clear
        # (2) the brake itself, as the driver plans it (phase-synchronised, else not)
        brakes = self._brakes(q, qd, qdd, vmax, amax, jmax)
        if not brakes:
            return self._worst(self.model.distances(q), self.model.travel(bound))
        end = np.asarray(brakes[0].at_time(brakes[0].duration)[0])
        if along is not None and _on_segment(q, qd, qdd, along, np.abs(end - q)):
            return None
        needed = self.model.travel(np.abs(end - q))
        if room > needed.max():
            return None
        d = self.model.distances(q)
        if (d - self.margin > needed).all():
            return None
        # (3) the brake's path, sampled where (2) left pairs short: each sample's room for them,
        # the motion between samples bounded
        short = np.flatnonzero(d - self.margin <= needed)
        budget = [MEASURES_MAX]
        for brake in brakes:
            count = min(BRAKE_SAMPLES_MAX, max(2, math.ceil(brake.duration / BRAKE_SAMPLE_S)))
            times = [brake.duration * k / count for k in range(count + 1)]
            rooms = [d[short] - self.margin] + [self._room(self._at(brake, t), short, budget) for t in times[1:]]
            for k in range(count):
                if not self._segment_clear(brake, times[k], times[k + 1], rooms[k], rooms[k + 1], short, budget):
                    return self._worst(d, needed)
        return None

    def _room(self, q: np.ndarray, pairs: np.ndarray, budget: list[int]) -> np.ndarray:
        """The room (distance minus margin) of ``pairs`` at ``q``: one measurement of the budget's."""
        budget[0] -= 1
        if budget[0] < 0:
            return np.full(len(pairs), -math.inf)
        room: np.ndarray = self.model.distances(q, pairs) - self.margin
        return room

    def _segment_clear(self, brake: ruckig.Trajectory, t0: float, t1: float, room0: np.ndarray, room1: np.ndarray,
                       pairs: np.ndarray, budget: list[int]) -> bool:
        """Does the brake keep ``pairs`` apart between ``t0`` and ``t1``, whose rooms are
        measured? A point between is no nearer than both ends allow: it holds when ``room0 +
        room1`` exceeds how much nearer each pair can come on the way (half of it from each
        end); else the segment is halved while the budget of measurements lasts (a setpoint the
        guard cannot clear within it is refused: the arm stops a little early, never late)."""
        if (room0 <= 0).any() or (room1 <= 0).any():
            return False
        if (room0 + room1 > self.model.travel(self._at(brake, t1) - self._at(brake, t0))[pairs]).all():
            return True
        mid = (t0 + t1) / 2
        room = self._room(self._at(brake, mid), pairs, budget)
        return (self._segment_clear(brake, t0, mid, room0, room, pairs, budget)
                and self._segment_clear(brake, mid, t1, room, room1, pairs, budget))

    @staticmethod
    def _at(brake: ruckig.Trajectory, t: float) -> np.ndarray:
        return np.asarray(brake.at_time(t)[0], float)

    def poses(self, q: np.ndarray, lower: np.ndarray | None = None) -> tuple[int, Stop] | None:
        """The first sample of a path (rows of joints) whose pose breaks the margin, and how;
        None: every pose keeps it. Few samples are measured (``lower``: ``_lower_bounds(q)``)."""
        if self.empty or len(q) == 0:
            return None
        for k in np.flatnonzero((self._lower_bounds(q) if lower is None else lower) <= 0).tolist():
            stop = self._worst(self.model.distances(q[k]), 0.0)  # the bound cannot rule it out: measured
            if stop is not None:
                return k, stop
        return None

    def path(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, dt: float, vmax: np.ndarray,
             amax: np.ndarray, jmax: np.ndarray) -> PathRefusal | None:
        """A sampled path (rows at the driver's cycle ``dt``): every pose keeps the margin, and
        every sample the rule of ``setpoint``. None: it may run."""
        if self.empty or len(q) == 0:
            return None
        lower = self._lower_bounds(q)
        breach = self.poses(q, lower)
        if breach is not None:
            first, found = breach
            return PathRefusal(found, first * dt, self._deepest(q, first, found.pair), moving=False)
        along = q[-1] if straight(q) else None  # a point-to-point move: a brake stays on the path
        bounds = _brake_bound(qd, qdd, amax, jmax)
        unsure = lower <= self.model.travel(bounds).max(axis=-1)
        if along is not None:
            unsure &= ~_on_segment(q, qd, qdd, along, bounds)
        for k in np.flatnonzero(unsure):
            stop = self.setpoint(q[k], qd[k], qdd[k], vmax, amax, jmax, along=along)
            if stop is not None:
                return PathRefusal(stop, float(k * dt), stop.distance_mm, moving=True)
        return None

    # ------------------------------------------------------------------ helpers
    def _worst(self, d: np.ndarray, needed: np.ndarray | float) -> Stop | None:
        """The pair with the least room (distance - margin - needed), if it has none."""
        short = d - self.margin - needed
        k = int(np.argmin(short))
        if short[k] > 0:
            return None
        need = needed[k] if isinstance(needed, np.ndarray) else needed
        return Stop(self.model.pairs[k], float(d[k]), float(self.margin + need), self.margin, k)

    def _lower_bounds(self, q: np.ndarray) -> np.ndarray:
        """A lower bound of each sample's least room (mm), measuring few of them: from a
        measured sample, the next ones have at least its room minus how far any pair came
        nearer (``CellModel.travel``); the next one measured is the first whose bound has
        lost half of it."""
        n = len(q)
        lower = np.empty(n)
        k = 0
        while k < n:
            lower[k] = room = self.model.nearest(q[k]) - self.margin
            ahead = q[k + 1:k + 1 + LOOK_AHEAD]
            if len(ahead) == 0:
                break
            bound = room - self.model.travel(ahead - q[k]).max(axis=1)
            stale = np.flatnonzero(bound <= 0.5 * max(room, 0.0))
            end = k + 1 + (int(stale[0]) if len(stale) else len(ahead))
            lower[k + 1:end] = bound[:end - k - 1]
            k = end
        return lower

    def _deepest(self, q: np.ndarray, first: int, pair: Pair) -> float:
        """The least distance of ``pair``'s two parts (any of their shapes) along the path from
        sample ``first`` on (mm)."""
        same = [k for k, other in enumerate(self.model.pairs) if other == pair]
        return min(float(self.model.distances(row)[same].min()) for row in q[first:])

    def _brakes(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
                jmax: np.ndarray) -> list[ruckig.Trajectory]:
        """The brake the driver makes from this state (rob6_driver.motion: phase-synchronised,
        else each joint on its own); empty when none can be planned. (The driver falls back to
        the second also when the first would leave the turn limits, which only limits changed
        under a motion can bring about; then it brakes at once, the shortest way.)"""
        inp = self._inp
        held = (amax <= FROZEN) | (jmax <= FROZEN)
        inp.current_position = q.tolist()
        inp.current_velocity = np.where(held, 0.0, qd).tolist()
        inp.current_acceleration = np.where(held, 0.0, qdd).tolist()
        inp.max_velocity = np.where(held, 1.0, np.maximum(np.maximum(vmax, np.abs(qd)), FROZEN)).tolist()
        inp.max_acceleration = np.where(held, 1.0, np.maximum(amax, np.abs(qdd))).tolist()
        inp.max_jerk = np.where(held, 1.0, jmax).tolist()
        for sync in (ruckig.Synchronization.Phase, ruckig.Synchronization.No):
            inp.synchronization = sync
            trajectory = ruckig.Trajectory(N_JOINTS)
            try:
                result = self._otg.calculate(inp, trajectory)
            except RuntimeError:
                continue
            if result in (ruckig.Result.Working, ruckig.Result.Finished):
                return [trajectory]
        return []


def straight(q: np.ndarray) -> bool:
    """Is the path (rows of joints) a straight line in joint space, from its first row to its
    last (a point-to-point move, phase-synchronised: rob6_planner.trajectory)?"""
    if len(q) < 2:
        return True
    direction = q[-1] - q[0]
    length = float(np.linalg.norm(direction))
    if length < STRAIGHT_TOL:
        return bool(np.abs(q - q[0]).max() <= STRAIGHT_TOL)
    offsets = q - q[0]
    along = offsets @ (direction / length)
    return bool(np.abs(offsets - along[:, None] * (direction / length)).max() <= STRAIGHT_TOL)


def _on_segment(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, end: np.ndarray, travel: np.ndarray) -> np.ndarray:
    """Does a phase-synchronised brake from (``q``, ``qd``, ``qdd``) that travels at most
    ``travel`` per joint stay on the straight segment from ``q`` to ``end``? Its path is the
    line through ``q`` along the velocity (the acceleration parallel to it), so: both point
    to ``end``, and no joint goes past it. Rows (..., 6) give (...,) answers."""
    direction = end - q
    length = np.linalg.norm(direction, axis=-1, keepdims=True)
    unit = direction / np.maximum(length, STRAIGHT_TOL)
    ok = length[..., 0] >= STRAIGHT_TOL
    for vector in (qd, qdd):
        off = np.abs(vector - (vector * unit).sum(axis=-1, keepdims=True) * unit).max(axis=-1)
        ok &= off <= STRAIGHT_TOL * (1.0 + np.abs(vector).max(axis=-1))
    answer: np.ndarray = ok & ((qd * unit).sum(axis=-1) >= 0.0) & (travel <= np.abs(direction) + STRAIGHT_TOL).all(axis=-1)
    return answer


def _brake_bound(qd: np.ndarray, qdd: np.ndarray, amax: np.ndarray, jmax: np.ndarray) -> np.ndarray:
    """Per joint, a bound of how far (deg) any jerk-limited brake with these limits travels,
    phase-synchronised ones included: at most the speed it can reach, for as long as the
    slowest joint's brake lasts (turn the acceleration round, brake at the limit, end it).
    ``qd``, ``qdd`` (..., 6) give (..., 6)."""
    moving = (amax > FROZEN) & (jmax > FROZEN)
    a = np.where(moving, amax, 1.0)
    j = np.where(moving, jmax, 1.0)
    a0 = np.abs(qdd)
    peak = np.where(moving, np.abs(qd) + a0 * a0 / (2.0 * j), 0.0)
    duration = np.where(moving, (a0 + a) / j + peak / a + a / j, 0.0)
    travel: np.ndarray = peak * duration.max(axis=-1, keepdims=True)
    return travel
