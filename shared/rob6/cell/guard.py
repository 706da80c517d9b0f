"""The rule of the safety zones: no part comes nearer a zone, or another part, than the margin plus what a stop from there travels.

One rule for the planner (every path, before anything moves) and the driver (every
setpoint, Alter streams above all): a setpoint is admitted only if the way to it from the
setpoint before keeps every part farther than its margin from every zone and from every
part it may not touch, and if, were the arm to brake from it after the reaction time
(``REACTION_CYCLES`` at the speed it has, then the driver's jerk-limited stop with the
limits it enforces), it would keep that distance all the way to rest. The driver brakes
from the last admitted setpoint instead of commanding one that breaks the rule, so the arm
comes to rest on its ramp outside every zone, and the rule holds there too.

Between two samples of a path, or two setpoints, the arm moves in a straight line in joint
space (the controller interpolates so; a slowed trajectory's setpoints lie on those lines).
No pose on the way is nearer than both ends' distances allow, less how far a pair can come
nearer on it (``CellModel.travel``); a segment whose ends do not allow it is halved until
they do, or until it is ``STEP_RESOLUTION_MM`` short (then refused), so nothing of any size
passes through a zone of any thickness between two samples, whatever the speed.

How far a stop travels is bounded in three steps, each only when the one before cannot
show enough room: (1) a bound of the brake's joint travel from the speed and acceleration
alone; (2) the joint travel of the brake itself (Ruckig, as the driver plans it); (3) the
brake's path sampled, each sample's distances measured and the motion between samples
bounded by what both ends' distances leave (halved within ``MEASURES_MAX`` measurements).
On a straight path (a point-to-point move) the driver's stop runs along the path
(``brake.line_brake``), so the path's own checked poses are its stop's.

The way out: a pair already within its margin (the arm jogged there, a controller's stop
that overshot, a zone added to the file) may move as long as it comes no nearer than it
was (less ``ESCAPE_DIP_MM``), at no more than ``ESCAPE_SPEED_MM_S``; every other pair keeps
the rule (``floors``). ``CellModel.lever`` turns joint travel into a bound of how far any
point of a part moves, in every configuration, so each step is conservative: the arm may
stop a little farther out than needed, never nearer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ruckig

from .brake import line_brake
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
#: the cycles a stop starts late at the speed the arm has: the one the link has sent and the
#: one the controller interpolates (its reaction; a controller's own stop is not rob6's:
#: docs/SAFETY_ZONES.md)
REACTION_CYCLES = 2
#: a segment of a path this short (mm that any pair can come nearer on it) whose ends do not
#: show it clear counts as a breach
STEP_RESOLUTION_MM = 0.05
#: on a way out, a pair within its margin may come this much nearer than it was (mm): a
#: joint move away from a plane may first graze along it
ESCAPE_DIP_MM = 0.5
#: on a way out, the fastest a point of a pair within its margin may move (mm/s): the reduced
#: speed of ISO 10218-1 (5.6), at which KUKA's T1 and a UR's recovery mode move
ESCAPE_SPEED_MM_S = 250.0


def pair_margins(model: CellModel) -> np.ndarray:
    """(pairs,) the margin of each pair (mm): its zone's own ``margin_mm`` where the file
    gives one (say, a controller's stopping distance), else the cell's."""
    own = {zone.name: zone.margin_mm for zone in model.cell.zones if zone.margin_mm is not None}
    return np.array([float(own.get(p.other, model.cell.margin_mm)) if p.zone else model.cell.margin_mm
                     for p in model.pairs], float)


@dataclass(frozen=True)
class Stop:
    """Why a pose or setpoint breaks the rule: the pair, how far apart it is (mm, < 0 inside)
    and how far it had to be (its floor, the margin or on a way out less, plus a stop's travel)."""

    pair: Pair
    distance_mm: float
    needed_mm: float
    margin_mm: float
    index: int  # of the pair in ``CellModel.pairs``
    speed_mm_s: float = 0.0  # on a way out: how fast the pair moved (too fast)

    @property
    def way_out(self) -> bool:
        """The pair was within its margin already: it may only move away, slowly."""
        return self.needed_mm < self.margin_mm or self.speed_mm_s > 0

    def describe(self) -> str:
        """``tool tip 12 mm inside keep-out 'table'``, ``link_6 40 mm from keep-out 'table',
        a stop there needs 65 mm``..."""
        p, d = self.pair, self.distance_mm
        other = f"keep-{p.keep} '{p.other}'" if p.zone else p.other
        if self.speed_mm_s > 0:
            return (f"{p.part} within the {self.margin_mm:g} mm margin of {other} moves at {self.speed_mm_s:.0f} mm/s: "
                    f"it may leave at {ESCAPE_SPEED_MM_S:g} mm/s at most")
        if self.way_out:
            return (f"{p.part} {_where(p, d)} {other} would come nearer than the {self.needed_mm + ESCAPE_DIP_MM:.0f} mm "
                    f"it starts at: within the {self.margin_mm:g} mm margin it may only move away from it")
        if d < 0:
            where = "outside" if p.keep == "in" else "inside" if p.zone else "into"
            return f"{p.part} {-d:.0f} mm {where} {other}"
        if d <= self.margin_mm:
            return f"{p.part} {d:.0f} mm from {other}, within the {self.margin_mm:g} mm margin"
        return f"{p.part} {d:.0f} mm from {other}, a stop there needs {self.needed_mm:.0f} mm"

    def hint(self) -> str:
        """What a client refused on a way out can do."""
        return f"; to get out, move {self.pair.part} away from {self.zone_name} (at most {ESCAPE_SPEED_MM_S:g} mm/s)"

    @property
    def zone_name(self) -> str:
        """``keep-out 'table'``, or the other part for a pair of the arm."""
        return f"keep-{self.pair.keep} '{self.pair.other}'" if self.pair.zone else self.pair.other


def _where(p: Pair, d: float) -> str:
    """``3 mm inside``, ``12 mm from``..."""
    if d < 0:
        return f"{-d:.0f} mm " + ("outside" if p.keep == "in" else "inside" if p.zone else "into")
    return f"{d:.0f} mm from"


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
        if self.stop.way_out:
            return f"path {at}: {self.stop.describe()}"
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

    def __init__(self, model: CellModel, reaction_s: float | None = None) -> None:
        self.model = model
        self.margins = pair_margins(model)  # (pairs,) mm
        self.margin = float(self.margins.max()) if len(self.margins) else model.cell.margin_mm
        self.reaction_s = REACTION_CYCLES * model.robot.cycle_s if reaction_s is None else float(reaction_s)
        self._otg = ruckig.Ruckig(N_JOINTS)
        self._inp = ruckig.InputParameter(N_JOINTS)
        self._inp.control_interface = ruckig.ControlInterface.Velocity
        self._inp.target_velocity = [0.0] * N_JOINTS
        self._inp.target_acceleration = [0.0] * N_JOINTS
        self._last: tuple[bytes, float] | None = None  # the last setpoint asked about, and its nearest distance

    @property
    def empty(self) -> bool:
        """Nothing to check (no zone, no pair of the arm)."""
        return not self.model.pairs

    # ------------------------------------------------------------------ the way out
    def floors(self, q: np.ndarray) -> np.ndarray | None:
        """How near each pair may come on a motion from ``q``: its margin, or, for a pair
        already within it (jogged there, a controller's overshoot, a zone added), no nearer
        than it is less ``ESCAPE_DIP_MM``. None: every pair keeps its margin at ``q``."""
        if self.empty or self.model.nearest(q) > self.margin:
            return None
        return self.floors_from(self.model.distances(q))

    def floors_from(self, d: np.ndarray) -> np.ndarray | None:
        """``floors`` from the pairs' distances at the start (mm)."""
        stuck = d <= self.margins
        return np.where(stuck, np.minimum(self.margins, d - ESCAPE_DIP_MM), self.margins) if stuck.any() else None

    def escape_share(self, q: np.ndarray, vmax: np.ndarray) -> float:
        """The share of the speed limits ``vmax`` (deg/s) a motion from ``q`` may use: 1, or
        while a pair is within its margin as much as keeps that pair's points within
        ``ESCAPE_SPEED_MM_S`` (the way out is slow, as a UR's recovery mode is)."""
        floors = self.floors(q)
        if floors is None:
            return 1.0
        stuck = floors < self.margins
        fastest = float(self.model.travel(vmax)[stuck].max())
        return 1.0 if fastest <= ESCAPE_SPEED_MM_S else ESCAPE_SPEED_MM_S / fastest

    # ------------------------------------------------------------------ the rule
    def pose(self, q: np.ndarray, floors: np.ndarray | None = None) -> Stop | None:
        """The pose alone (at rest): every pair farther apart than the margin (than ``floors``)."""
        if self.empty:
            return None
        if floors is None and self.model.nearest(q) > self.margin:
            return None
        return self._worst(self.model.distances(q), 0.0, floors)

    def setpoint(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
                 jmax: np.ndarray, along: np.ndarray | None = None, prev: np.ndarray | None = None,
                 floors: np.ndarray | None = None) -> Stop | None:
        """A setpoint ``q`` (deg) reached with ``qd``, ``qdd`` (deg/s, deg/s^2): would a stop
        from there (after the reaction time; limits in deg/s, deg/s^2, deg/s^3) keep every
        pair apart? None: yes. ``prev``: the setpoint before, from which the arm moves to
        ``q`` in a straight line: that way is checked too. ``along``: the end of a straight
        path from ``q`` whose poses are known to be clear (``poses``): a stop on it
        (``line_brake``) is clear too. ``floors``: the pairs' floors on a way out (``floors``)."""
        if self.empty:
            return None
        top = self.margin if floors is None else float(floors.max())
        d = None
        nearest = self.model.nearest(q)
        last, self._last = self._last, (q.tobytes(), nearest)
        room = nearest - top
        if room <= 0:  # measured pair by pair: one within its margin (a way out) may be fine
            d = self.model.distances(q)
            if floors is None or (d <= floors).any():
                return self._worst(d, 0.0, floors)
        if prev is not None:
            # the way from the setpoint before (whose nearest distance the last call measured)
            before = last[1] if last is not None and last[0] == prev.tobytes() else self.model.nearest(prev)
            if before - top + room <= self.model.travel(q - prev).max():
                d = self.model.distances(q) if d is None else d
                found = self._between(prev, q, self.model.distances(prev), d, self.margins if floors is None else floors)
                if found is not None:
                    return self._worst(found[1], 0.0, floors)
        if floors is not None and (stop := self._too_fast(qd, floors, d if d is not None else self.model.distances(q))):
            return stop
        if not qd.any() and not qdd.any():
            return None
        # (1) the brake's joint travel bounded from the state alone, after the reaction time
        react = np.abs(qd) * self.reaction_s
        bound = _brake_bound(qd, qdd, amax, jmax) + react
        if room > self.model.travel(bound).max():
            return None
        if along is not None and line_brake(q, qd, qdd, along, vmax, amax, jmax) is not None:
            # the stop is the rest of a path whose poses are clear; its reaction too: until the
            # brake begins the arm follows the setpoints already sent, which lie on the path
            return None
        # (2) the brake itself, as the driver plans it (phase-synchronised, else not)
        brakes = self._brakes(q, qd, qdd, vmax, amax, jmax)
        if d is None:
            d = self.model.distances(q)
        if not brakes:
            return self._worst(d, self.model.travel(bound), floors)
        end = np.asarray(brakes[0].at_time(brakes[0].duration)[0])
        needed = self.model.travel(np.abs(end - q) + react)
        floor = self.margins if floors is None else floors
        if (d - floor > needed).all():
            return None
        # (3) the reaction (the arm goes on at its speed, a straight line in joint space), then
        # the brake from there: its path sampled where (2) left pairs short, each sample's room
        # for them measured and the motion between samples bounded
        delta = qd * self.reaction_s
        d_late = self.model.distances(q + delta) if delta.any() else d
        if delta.any() and self._between(q, q + delta, d, d_late, floor) is not None:
            return self._worst(d, needed, floors)
        short = np.flatnonzero(d - floor <= needed)
        budget = [MEASURES_MAX]
        for brake in brakes:
            count = min(BRAKE_SAMPLES_MAX, max(2, math.ceil(brake.duration / BRAKE_SAMPLE_S)))
            times = [brake.duration * k / count for k in range(count + 1)]
            rooms = [d_late[short] - floor[short]]
            rooms += [self._room(self._at(brake, t) + delta, short, floor, budget) for t in times[1:]]
            for k in range(count):
                if not self._segment_clear(brake, times[k], times[k + 1], rooms[k], rooms[k + 1], short, floor,
                                           delta, budget):
                    return self._worst(d, needed, floors)
        return None

    def _too_fast(self, qd: np.ndarray, floors: np.ndarray, d: np.ndarray) -> Stop | None:
        """On a way out, a pair within its margin moves at most ``ESCAPE_SPEED_MM_S``."""
        stuck = floors < self.margins
        speed = self.model.travel(qd)
        if (speed[stuck] <= ESCAPE_SPEED_MM_S * (1.0 + 1e-6)).all():
            return None
        k = int(np.flatnonzero(stuck)[np.argmax(speed[stuck])])
        return Stop(self.model.pairs[k], float(d[k]), float(floors[k]), float(self.margins[k]), k,
                    speed_mm_s=float(speed[k]))

    def _room(self, q: np.ndarray, pairs: np.ndarray, floor: np.ndarray, budget: list[int]) -> np.ndarray:
        """The room (distance less its floor) of ``pairs`` at ``q``: one measurement of the budget's."""
        budget[0] -= 1
        if budget[0] < 0:
            return np.full(len(pairs), -math.inf)
        room: np.ndarray = self.model.distances(q, pairs) - floor[pairs]
        return room

    def _segment_clear(self, brake: ruckig.Trajectory, t0: float, t1: float, room0: np.ndarray, room1: np.ndarray,
                       pairs: np.ndarray, floor: np.ndarray, delta: np.ndarray, budget: list[int]) -> bool:
        """Does the brake (shifted by ``delta``, the reaction's travel) keep ``pairs`` apart
        between ``t0`` and ``t1``, whose rooms are measured? A point between is no nearer than
        both ends allow: it holds when ``room0 + room1`` exceeds how much nearer each pair can
        come on the way (half of it from each end); else the segment is halved while the budget
        of measurements lasts (a setpoint the guard cannot clear within it is refused: the arm
        stops a little early, never late)."""
        if (room0 <= 0).any() or (room1 <= 0).any():
            return False
        if (room0 + room1 > self.model.travel(self._at(brake, t1) - self._at(brake, t0))[pairs]).all():
            return True
        mid = (t0 + t1) / 2
        room = self._room(self._at(brake, mid) + delta, pairs, floor, budget)
        return (self._segment_clear(brake, t0, mid, room0, room, pairs, floor, delta, budget)
                and self._segment_clear(brake, mid, t1, room, room1, pairs, floor, delta, budget))

    @staticmethod
    def _at(brake: ruckig.Trajectory, t: float) -> np.ndarray:
        return np.asarray(brake.at_time(t)[0], float)

    def _between(self, qa: np.ndarray, qb: np.ndarray, da: np.ndarray, db: np.ndarray,
                 floor: np.ndarray) -> tuple[float, np.ndarray] | None:
        """The first point of the straight joint segment ``qa``-``qb`` (their pairs'
        distances ``da``, ``db``) where a pair is not above its floor: (the fraction along
        it, the distances there); None: clear all the way. A point between is no nearer than
        both ends allow (``_segment_clear``'s argument); where they do not allow enough the
        segment is halved, down to ``STEP_RESOLUTION_MM`` of travel, below which a segment
        whose ends are both this near counts as a breach (refused a little early, never late)."""
        todo = [(0.0, 1.0, da, db)]
        while todo:
            s0, s1, d0, d1 = todo.pop()
            if (d0 <= floor).any():
                return s0, d0
            if (d1 <= floor).any():
                return s1, d1
            travel = self.model.travel((qb - qa) * (s1 - s0))
            unsure = d0 + d1 - 2.0 * floor <= travel
            if not unsure.any():
                continue
            mid = (s0 + s1) / 2
            dm = self.model.distances(qa + mid * (qb - qa))
            if travel.max() <= STEP_RESOLUTION_MM:
                return mid, np.where(unsure, np.minimum(dm, floor), dm)
            todo += [(mid, s1, dm, d1), (s0, mid, d0, dm)]  # the earlier half first
        return None

    def poses(self, q: np.ndarray, lower: np.ndarray | None = None,
              floors: np.ndarray | None = None) -> tuple[float, Stop] | None:
        """The first point of a path (rows of joints, joined by straight lines) whose pose
        breaks the margin (``floors``), and how: (where, in samples, fractional between two;
        the stop); None: every pose keeps it. Few samples are measured (``lower``:
        ``_lower_bounds(q)``)."""
        if self.empty or len(q) == 0:
            return None
        if lower is None:
            lower = self._lower_bounds(q, floors)
        floor = self.margins if floors is None else floors
        measured: dict[int, np.ndarray] = {}

        def at(k: int) -> np.ndarray:
            if k not in measured:
                measured[k] = self.model.distances(q[k])
            return measured[k]

        # a segment is clear when both ends' room covers how much nearer any pair comes on it
        steps = self.model.travel(np.diff(q, axis=0)).max(axis=1) if len(q) > 1 else np.zeros(0)
        unsure = set(np.flatnonzero(lower <= 0).tolist()) | set(np.flatnonzero(lower[:-1] + lower[1:] <= steps).tolist())
        for k in sorted(unsure):
            stop = self._worst(at(k), 0.0, floors)
            if stop is not None:
                return float(k), stop
            if k + 1 < len(q):
                found = self._between(q[k], q[k + 1], at(k), at(k + 1), floor)
                if found is not None:
                    return k + found[0], self._breach(found[1], floors)
        return None

    def path(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, dt: float, vmax: np.ndarray,
             amax: np.ndarray, jmax: np.ndarray) -> PathRefusal | None:
        """A sampled path (rows at the driver's cycle ``dt``, joined by straight lines): every
        pose keeps the margin, between samples too, and every sample the rule of ``setpoint``.
        From a pose within the margin (a way out), the pairs within it get no nearer than
        they start (``floors``) and move no faster than ``ESCAPE_SPEED_MM_S``. None: it may run."""
        if self.empty or len(q) == 0:
            return None
        d0 = self.model.distances(q[0])
        floors = self.floors_from(d0)
        lower = self._lower_bounds(q, floors)
        breach = self.poses(q, lower, floors)
        if breach is not None:
            at, found = breach
            return PathRefusal(found, at * dt, self._deepest(q, int(at), found.pair), moving=False)
        if floors is not None:
            stuck = floors < self.margins
            d_end = self.model.distances(q[-1])
            deeper = np.flatnonzero(stuck & (d_end < d0))
            if len(deeper):
                pair = int(deeper[0])
                end = Stop(self.model.pairs[pair], float(d_end[pair]), float(d0[pair] - ESCAPE_DIP_MM),
                           float(self.margins[pair]), pair)
                return PathRefusal(end, (len(q) - 1) * dt, float(d_end[pair]), moving=False)
            fastest = self.model.travel(qd)[:, stuck].max(axis=1)
            if fastest.max() > ESCAPE_SPEED_MM_S * (1.0 + 1e-6):
                first = int(np.argmax(fastest))
                fast = self._too_fast(qd[first], floors, self.model.distances(q[first]))
                assert fast is not None  # found too fast just now
                return PathRefusal(fast, first * dt, fast.distance_mm, moving=True)
        along = q[-1] if straight(q) else None  # a point-to-point move: the stop runs along the path
        bounds = _brake_bound(qd, qdd, amax, jmax) + np.abs(qd) * self.reaction_s
        unsure = lower <= self.model.travel(bounds).max(axis=-1)
        if along is not None:
            unsure &= ~_on_segment(q, qd, qdd, along, bounds)
        for k in np.flatnonzero(unsure):
            stop = self.setpoint(q[k], qd[k], qdd[k], vmax, amax, jmax, along=along, floors=floors)
            if stop is not None:
                return PathRefusal(stop, float(k * dt), stop.distance_mm, moving=True)
        return None

    # ------------------------------------------------------------------ helpers
    def _worst(self, d: np.ndarray, needed: np.ndarray | float, floors: np.ndarray | None = None) -> Stop | None:
        """The pair with the least room (distance - floor - needed), if it has none."""
        floor = self.margins if floors is None else floors
        short = d - floor - needed
        k = int(np.argmin(short))
        if short[k] > 0:
            return None
        need = needed[k] if isinstance(needed, np.ndarray) else needed
        return Stop(self.model.pairs[k], float(d[k]), float(floor[k] + need), float(self.margins[k]), k)

    def _breach(self, d: np.ndarray, floors: np.ndarray | None) -> Stop:
        stop = self._worst(d, 0.0, floors)
        assert stop is not None  # ``_between`` found a pair at or below its floor
        return stop

    def _lower_bounds(self, q: np.ndarray, floors: np.ndarray | None = None) -> np.ndarray:
        """A lower bound of each sample's least room (mm), measuring few of them: from a
        measured sample, the next ones have at least its room minus how far any pair came
        nearer (``CellModel.travel``); the next one measured is the first whose bound has
        lost half of it."""
        top = self.margin if floors is None else float(floors.max())
        n = len(q)
        lower = np.empty(n)
        k = 0
        while k < n:
            lower[k] = room = self.model.nearest(q[k]) - top
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
