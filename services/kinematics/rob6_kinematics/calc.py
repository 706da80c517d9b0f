"""Kinematics with the semantics of the original rob6server's protocol commands.

``Kinematics`` wraps one robot (``rob6.robots.RobotModel``):

* ``fk`` / ``ik`` — vectorised numpy FK and the 8-branch closed-form IK (``opw``);
* ``forward_calc`` — ``ForwardCalc`` incl. the partial-frame quirk for < 6 numbers;
* ``backward_calc`` / ``is_possible`` — ``BackwardCalc`` = ``GetJointsRowWise``,
  ``IsPossible``: branch selection from a status pattern, (-180, 180] joints,
  one +-360 shift into the limits, strict turn limits, inclusive max change;
* ``jacobian`` / ``manipulability`` — via Pinocchio (``model.PinModel``).

Angles in degrees, lengths in mm, poses as (3,4) matrices or 12 row-wise numbers.
No networking here; the gateway parses the text, this module computes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cached_property
from typing import TYPE_CHECKING, cast

import numpy as np
import numpy.typing as npt

from rob6.robots import RobotModel
from rob6.status import Status, parse_status, status_flags, status_matches, status_words

from . import opw
from .opw import BRANCH_INDEX, BRANCHES, DEG, FloatArray, Geometry

if TYPE_CHECKING:
    from .model import PinModel
from .selection import STATUS_ORDER

#: Tie-break order of the branches (indices into BRANCHES): flip before noflip, up
#: before down, lefty before righty -- selection.STATUS_ORDER.
TIE_ORDER = [BRANCH_INDEX[" ".join(status)] for status in STATUS_ORDER]
TIE_EPS = 1e-9


class Kinematics:
    """Kinematics of one robot type.

    ``geometry`` overrides the DH lengths (tests use it to reproduce the original's
    kaw_fs ForwardCalc with a2 = -250); by default both FK and IK use the robot's.
    """

    BRANCHES: tuple[str, ...] = BRANCHES

    def __init__(self, robot: RobotModel, geometry: Geometry | None = None):
        self.robot = robot
        self.g = geometry or Geometry.of(robot)
        self.turn_min = np.array(robot.turn_min, dtype=float)
        self.turn_max = np.array(robot.turn_max, dtype=float)
        self.max_change = np.array(robot.default_max_change, dtype=float)
        self.weights = np.array(robot.default_weights, dtype=float)  # min-change weights
        # plain-float copies for the single-pose (numpy-free) paths
        self._lo = self.turn_min.tolist()
        self._hi = self.turn_max.tolist()
        self._mc = self.max_change.tolist()
        self._w = self.weights.tolist()
        self._mid = ((np.asarray(robot.hw_min, float) + np.asarray(robot.hw_max, float)) / 2).tolist()

    # ------------------------------------------------------------------ FK / IK
    def fk(self, q: npt.ArrayLike) -> FloatArray:
        """Flange pose(s) of joints q (deg), (6,) or (N,6) -> (N,3,4), mm.

        Computed like the original (``opw.fk_compiled``): its ``%f`` text is the
        original's byte for byte.  ``fk_fast`` is the ~4x faster closed form
        (equal to ~1e-12 mm).
        """
        return opw.fk_compiled(self.g, q)

    def fk_fast(self, q: npt.ArrayLike) -> FloatArray:
        """Closed-form vectorised FK (same result as ``fk`` up to rounding)."""
        return opw.fk(self.g, q)

    def ik(self, T: npt.ArrayLike) -> FloatArray:
        """All 8 closed-form solutions, (N,3,4)/(N,12) -> (N,8,6) deg in (-180,180].

        NaN where a branch has no solution; branch order ``BRANCHES``.  No limits.
        """
        return opw.ik(self.g, T)

    def ik_one(self, T: npt.ArrayLike) -> list[list[float] | None]:
        """``ik`` of one pose without numpy's per-call overhead (``opw.ik_one``):
        8 branches, each 6 joints (deg) or None."""
        return opw.ik_one(self.g, T)

    def ik_limited(self, T: npt.ArrayLike, turn_min: npt.ArrayLike | None = None, turn_max: npt.ArrayLike | None = None) -> FloatArray:
        """``ik`` with the original's limit handling, vectorised: each joint outside
        its turn limits is shifted once by -+360 deg; a branch with a joint not
        strictly inside the limits afterwards becomes NaN."""
        lo = self.turn_min if turn_min is None else np.asarray(turn_min, float)
        hi = self.turn_max if turn_max is None else np.asarray(turn_max, float)
        return apply_limits(self.ik(T), lo, hi)

    def status(self, q: npt.ArrayLike) -> str:
        """Status words of joints q (deg), e.g. ``"noflip up lefty"``."""
        return " ".join(self.robot_status(q))

    def robot_status(self, q: npt.ArrayLike) -> Status:
        """Status words of joints q (deg) in this kinematics' geometry."""
        v = _floats6(q)
        return status_words(*status_flags(self.g, math.radians(v[1]), math.radians(v[2]), v[4]))

    def status_batch(self, q: npt.ArrayLike) -> npt.NDArray[np.int_]:
        """Vectorised status as branch indices (N,) (index into ``BRANCHES``)."""
        Q = opw.as_joints(q)
        flags: tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_], npt.NDArray[np.bool_]] = status_flags(
            self.g, Q[:, 1] * DEG, Q[:, 2] * DEG, Q[:, 4], sin=np.sin, cos=np.cos)
        flip, up, lefty = flags
        return 4 * flip + 2 * ~up + ~lefty

    # ------------------------------------------------------------------ ForwardCalc
    def partial_frame(self, q_deg: npt.ArrayLike, n: int) -> FloatArray:
        """Frame of joint n (1..6) of the original's compiled chain, (3,4).

        The chain (robots.md "ForwardCalc quirks"): A1..An with
        theta = [-q1, q2, q3+90, q4, q5, q6], d4 -> -d4, d6 -> -d6, a3 -> -a3, the
        same twists, and no final Ry(180); n = 6 is the flange pose.
        """
        # numpy's stubs type an integer index as Any: it is the first (3,4) frame
        return cast(FloatArray, opw.fk_compiled(self.g, np.asarray(q_deg, float).reshape(1, 6), n)[0])

    def forward_calc(self, numbers: Sequence[float], turn_min: npt.ArrayLike | None = None,
                     turn_max: npt.ArrayLike | None = None) -> tuple[list[float], str] | None:
        """``ForwardCalc``: -> (list of 12 floats, status string) or None (``false``).

        ``numbers`` are the leading numbers that parsed (the gateway stops at the
        first one that does not).  0 numbers -> None; more than 6 -> extras ignored.
        With N < 6 numbers the missing joints are the midpoints of the hardware
        ranges (J2 max = the hardware value, not 20), all 6 are limit-checked, and
        the frame of joint N of the compiled chain is returned; the status line is
        then the status of the filled joint vector (meaningless, as in the original).
        Turn limits are strict: min < q < max.
        """
        nums = [float(x) for x in list(numbers)[:6]]
        n = len(nums)
        if n == 0:
            return None
        lo = self._lo if turn_min is None else _floats6(turn_min)
        hi = self._hi if turn_max is None else _floats6(turn_max)
        q = nums + self._mid[n:]
        if not all(lo[j] < q[j] < hi[j] for j in range(6)):  # also False for NaN
            return None
        return opw.fk_compiled_one(self.g, q, n), self.status(q)

    # ------------------------------------------------------------------ BackwardCalc
    def resolve_pattern(self, pattern: str | Sequence[str], current_q: npt.ArrayLike) -> list[int]:
        """Branch indices (``BRANCHES`` order) admitted by a status pattern at the
        current joints (``noToggle…`` = the current status' word)."""
        pat = parse_status(pattern.split() if isinstance(pattern, str) else pattern)
        cur = self.robot_status(current_q)
        return [i for i, branch in enumerate(BRANCHES) if status_matches(pat, branch.split(), cur)]

    def backward_calc(
        self,
        matrix: npt.ArrayLike,
        pattern: str | Sequence[str],
        current_q: npt.ArrayLike,
        turn_min: npt.ArrayLike | None = None,
        turn_max: npt.ArrayLike | None = None,
        max_change: npt.ArrayLike | None = None,
        weights: npt.ArrayLike | None = None,
    ) -> list[float] | None:
        """``BackwardCalc`` / ``GetJointsRowWise``: -> list of 6 joints (deg) or None.

        ``matrix``: 12 row-wise numbers (or (3,4)); ``pattern``: 1-3 status words
        (string or list, any order, see ``rob6.status.parse_status``); ``current_q``: the
        robot's current joints; limits, max change and min-change weights default
        to the robot's defaults (weights ``4 1 1 1 1 1``).

        Each IK branch is solved in closed form (``opw.ik``: joints in (-180, 180],
        wrist-singularity rule, stretched-elbow clamp), then every joint outside
        its turn limits is shifted once by -+360 deg, and the branch is possible
        when all joints are strictly inside the limits and no joint changes by more
        than ``max_change`` from ``current_q`` (change == max_change is allowed).

        Pattern -> branch.  Explicit words fix a category, ``noToggle…`` fixes it
        to the category of ``current_q``'s status, ``toggle…`` leaves it free.  Of
        the admitted possible branches the one with the smallest **weighted maximum
        joint change** ``max_j w_j |q_j - current_j|`` wins; ties (within 1e-9 —
        common, since the branches of one arm share J1 and ``4 |dq1|`` usually
        dominates) go to the earlier branch in ``TIE_ORDER``: flip before noflip, up
        before down, lefty before righty.  This is the rule of the Cartesian moves
        (``selection.py``) without their +-360 representatives.

        Found from every toggle case of the transcripts (15 BackwardCalc /
        GetJointsRowWise cases with more than one possible branch on kr16, kr3,
        ad850, kaw_fs; all from current position 0):  e.g. kr16
        FK(-88 -78 -38 -64 23 34) + ``toggleHand toggleElbow toggleArm`` ->
        ``flip up lefty`` (all lefty branches cost 4*88; the first of the tie wins,
        although ``noflip down lefty`` has the smaller summed change); ad850
        FK(10 -60 80 20 40 30) -> ``noflip up lefty`` (cost 80 against 100.6 of the
        current configuration ``noflip down lefty``); ad850 FK(0) -> the current
        joints (cost 0).  A sum / squared-sum cost contradicts these cases.  The
        weights the original used here are not observable (never changed before a
        BackwardCalc in the transcripts); the defaults are assumed.
        """
        cur = _floats6(current_q)
        cands = self._check_one(self.ik_one(_matrix12(matrix)), cur, turn_min, turn_max, max_change)
        allowed = set(self.resolve_pattern(pattern, cur))
        w = self._w if weights is None else _floats6(weights)
        best, best_cost = None, math.inf
        for b in TIE_ORDER:
            q = cands[b]
            if q is None or b not in allowed:
                continue
            cost = max(w[j] * abs(q[j] - cur[j]) for j in range(6))
            if cost < best_cost - TIE_EPS:
                best, best_cost = q, cost
        return best

    def is_possible(self, matrix: npt.ArrayLike, pattern: str | Sequence[str], current_q: npt.ArrayLike,
                    turn_min: npt.ArrayLike | None = None, turn_max: npt.ArrayLike | None = None, max_change: npt.ArrayLike | None = None) -> bool:
        """``IsPossible`` = BackwardCalc would return joints (independent of weights)."""
        cur = _floats6(current_q)
        cands = self._check_one(self.ik_one(_matrix12(matrix)), cur, turn_min, turn_max, max_change)
        return any(cands[b] is not None for b in self.resolve_pattern(pattern, cur))

    def candidates(self, matrix: npt.ArrayLike, current_q: npt.ArrayLike, turn_min: npt.ArrayLike | None = None,
                   turn_max: npt.ArrayLike | None = None, max_change: npt.ArrayLike | None = None) -> FloatArray:
        """(8,6) solutions after the limit shift, limit and max-change checks, in
        ``BRANCHES`` order; NaN rows are not possible."""
        cands = self._check_one(self.ik_one(_matrix12(matrix)), _floats6(current_q), turn_min, turn_max, max_change)
        return np.array([[math.nan] * 6 if q is None else q for q in cands])

    def _check_one(self, raw: Sequence[list[float] | None], cur: list[float], turn_min: npt.ArrayLike | None,
                   turn_max: npt.ArrayLike | None, max_change: npt.ArrayLike | None) -> list[list[float] | None]:
        """``_check`` on ``ik_one``'s branches in plain floats (None = not possible)."""
        lo = self._lo if turn_min is None else _floats6(turn_min)
        hi = self._hi if turn_max is None else _floats6(turn_max)
        mc = self._mc if max_change is None else _floats6(max_change)
        out: list[list[float] | None] = []
        for branch in raw:
            q = branch
            if q is not None:
                q = [v - 360.0 if v >= hi[j] else (v + 360.0 if v <= lo[j] else v) for j, v in enumerate(q)]
                if not all(lo[j] < q[j] < hi[j] and not abs(q[j] - cur[j]) > mc[j] for j in range(6)):
                    q = None
            out.append(q)
        return out

    def _check(self, raw: FloatArray, current_q: npt.ArrayLike, turn_min: npt.ArrayLike | None,
               turn_max: npt.ArrayLike | None, max_change: npt.ArrayLike | None) -> FloatArray:
        lo = self.turn_min if turn_min is None else np.asarray(turn_min, float)
        hi = self.turn_max if turn_max is None else np.asarray(turn_max, float)
        mc = self.max_change if max_change is None else np.asarray(max_change, float)
        Q = apply_limits(raw, lo, hi)
        cur = np.asarray(current_q, float).reshape(6)
        with np.errstate(invalid="ignore"):
            too_far = np.any(np.abs(Q - cur) > mc, axis=1)
        Q[too_far] = np.nan
        return Q

    # ------------------------------------------------------------------ Pinocchio
    @cached_property
    def pin(self) -> PinModel:
        from .model import PinModel

        return PinModel(self.robot, self.g)

    def jacobian(self, q: npt.ArrayLike) -> FloatArray:
        """Flange Jacobian (6,6) at q (deg), LOCAL_WORLD_ALIGNED, rows (v [mm/rad], w [rad/rad])."""
        return self.pin.jacobian(q)

    def manipulability(self, q: npt.ArrayLike) -> float:
        """Yoshikawa manipulability sqrt(det(J J^T)) of the flange Jacobian (m, rad)."""
        return self.pin.manipulability(q)


def _floats6(x: npt.ArrayLike) -> list[float]:
    """6 plain floats from a sequence / array (numpy broadcasting rules otherwise)."""
    if isinstance(x, (list, tuple)) and len(x) == 6:
        return [float(v) for v in x]
    return cast(list[float], np.broadcast_to(
        np.asarray(x, dtype=float).reshape(-1) if np.ndim(x) > 1 else np.asarray(x, dtype=float), (6,)).tolist())


def _matrix12(m: npt.ArrayLike) -> list[float]:
    """12 row-wise floats of a pose (12 numbers or (3,4))."""
    if isinstance(m, (list, tuple)) and len(m) == 12:
        return [float(v) for v in m]
    return np.asarray(m, dtype=float).reshape(12).tolist()


def apply_limits(raw: npt.ArrayLike, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Shift each joint outside (lo, hi) once by -+360, then NaN the branches that
    are still not strictly inside.  Q: (..., 6) degrees."""
    Q = np.array(raw, dtype=float, copy=True)
    Q = np.where(Q >= hi, Q - 360.0, np.where(Q <= lo, Q + 360.0, Q))
    inside = np.all((lo < Q) & (Q < hi), axis=-1)
    Q[~inside] = np.nan
    return Q
