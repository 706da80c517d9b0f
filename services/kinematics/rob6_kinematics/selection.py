"""Configuration selection of the Cartesian moves (the original's "min change" rule).

Reverse-engineered from the original rob6server's transcripts
(``conformance/<robot>/motion_minchange.jsonl``, ``motion_ptp.jsonl``,
``motion_routetest.jsonl``); it reproduces every recorded Cartesian move of kr16, ad850
and kr3rt (chosen joints and ``true``/``false``), see ``tests/kinematics/test_selection.py``.

The rule
========
Given the pose, a status pattern (hand/elbow/arm word each explicit, ``toggle…`` or
``noToggle…``), the current joints ``c``, the turn limits, the max change per joint, the
min-change weights ``w`` and the allowed status pattern:

1. Candidates are the IK branches in the fixed order ``STATUS_ORDER``
   (``flip`` before ``noflip``, ``up`` before ``down``, ``lefty`` before ``righty``).
2. A branch must match the pattern by its IK label: an explicit word must equal the
   branch's word, ``noToggle…`` must equal the current status (the status formulas of
   robots.md applied to ``c``), ``toggle…`` matches anything.
3. Each joint of the branch is replaced by the value congruent to it modulo 360° that is
   nearest to ``c_j`` among the values strictly inside the turn limits (this is where J4/J6,
   kr16's J1 and ad850's J2 get their ±360°; exactly 180° either way → c_j + 180). No such
   value → branch rejected. The branch is rejected if any ``|q_j − c_j|`` exceeds the max
   change (the max change is inclusive).
4. The allowed-status pattern is checked on the status *computed from the resulting joints*
   (``noToggle…`` = same as the current status). (On kr16/ad850/kr3rt this equals the IK
   label; the original's kaw_fs shows that the allowed check uses the computed status.)
5. Cost = **weighted maximum** of the joint changes, ``max_j w_j·|q_j − c_j|`` (not the sum,
   not the squares). The branch with the smallest cost wins; on a tie (the usual case when
   J1 dominates, because branches of the same arm share J1) the **earlier branch in
   STATUS_ORDER** wins. No admissible branch → ``None`` (the protocol answers ``false``).

Fixed by the data: weighted max (the sum fails 47 of the 336 recorded Cartesian moves of
kr16/ad850/kr3rt, squares 37), nearest representative per joint (taking any representative
and breaking ties by enumeration fails 30), flip before noflip and up before down on ties.
Not fixed by the data (never tied there): lefty vs righty on a tie, and whether hand or elbow
is the major key when e.g. only ``noflip up`` and ``flip down`` tie; the order above is a
choice.

This explains all of REFERENCE 6.6's puzzles: with the default weights ``4 1 1 1 1 1`` a J1
change of 4° costs 16 and swamps the other joints, so ``noflip toggleElbow righty`` gives
``noflip up righty`` (both ``righty`` branches cost 4·176 = 704, ``up`` is earlier) and
``toggleHand up righty`` gives ``flip up righty``; weights ``100 1 1 1 1 1`` make every lefty
branch cost 400 → the first, ``flip up lefty``; ``1 100 100 1 1 1`` tie the two ``down lefty``
branches → ``flip down lefty``.

Per command (what the transcripts show)
=======================================
- ``MoveMinChangeRowWiseStatus <12> <status>``, ``MovePTPHomRowWiseStatusTurn <12> <status>``,
  ``RoutetestRowWiseStatus <12> <status>``: the rule with the given pattern (missing words =
  ``toggle…``). The two move commands behave identically.
- ``MovePTPHomRowWise <12>`` (a trailing status is ignored): the rule with the fixed pattern
  ``toggleHand toggleElbow lefty`` (``PTP_HOM_PATTERN``) — it never picks a ``righty`` branch,
  even from a righty start where a righty branch is the exact current position (ad850), and
  with allowed ``… righty`` it answers ``false``.
- ``MovePTPJoints`` / ``RoutetestJoints``: ``joint_move_allowed`` (strict turn limits, inclusive
  max change, allowed status of the target joints with ``noToggle…`` = current status).
  ``MovePTPJointsStatus``: the same and ``status_matches(pattern, status(q), status(current))``.
- ``BackwardCalc``/``GetJointsRowWise``/``IsPossible`` pick their branch by the same rule but
  with the IK's own values (each joint shifted once by ∓360° only if outside the limits,
  ``shift_360=False``) and without the allowed status: this reproduces every answer of
  ik.jsonl on kr16, ad850, kr3rt, kaw_fs and the toggle cases of kinematics.jsonl (incl.
  ad850's zero pose, where ``toggle…`` ×3 gives the current joints 0 0 0 0 0 0).

kaw_fs: the original's status/ForwardCalc used a2 = −250 while its IK used +250, so its
``noToggle…`` and allowed checks compared IK branches with a status from the other geometry.
rob6 uses the +250 geometry for everything, so these same rules are self-consistent there and
deliberately differ from the kaw_fs transcripts wherever that inconsistency shows (see the
test for the exact list).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Protocol, cast

from rob6.status import STATUS_WORDS, TOGGLE_ALL, Status, parse_status, status_matches

if TYPE_CHECKING:
    import numpy.typing as npt

#: a status formula: joints (deg) -> "noflip up lefty" or its 3 words
StatusFn = Callable[[Sequence[float]], str | Sequence[str]]


class Solver(Protocol):
    """What ``select`` needs of a kinematics: the raw IK branches (see ``branches_of``).
    ``BRANCHES``, ``ik_one`` and the status formula are looked up when present."""

    def ik(self, T: npt.ArrayLike, /) -> npt.ArrayLike: ...


class _WithStatus(Protocol):
    def status(self, q: Sequence[float], /) -> str | Sequence[str]: ...

#: Tie-break order of the IK branches (earlier wins on equal cost): flip before noflip, up
#: before down, lefty before righty (each category's explicit words in STATUS_WORDS order).
STATUS_ORDER: tuple[Status, ...] = tuple(
    (h, e, a) for h in STATUS_WORDS[0][:2] for e in STATUS_WORDS[1][:2] for a in STATUS_WORDS[2][:2])

#: Two costs closer than this are a tie (the original's ties are exact: same-arm
#: branches share J1 bit for bit; this only absorbs float noise of a different IK).
TIE_EPS = 1e-9


def _nearest_in_limits(v: float, c: float, lo: float, hi: float) -> float | None:
    """The value ≡ v (mod 360) nearest to c with lo < value < hi (strict), or None.

    Two values 180° either side of c (a flip/noflip switch at the same pose, J4 and J6):
    the upper one, c + 180 (the original's kaw_fs transcript, motion_ptp record 215: J4
    stayed at c + 180 and J6 took +360 to reach c + 180).
    """
    k0 = round((c - v) / 360.0)
    k_first = math.floor((lo - v) / 360.0) + 1  # smallest k with v + 360k > lo
    k_last = math.ceil((hi - v) / 360.0) - 1  # largest k with v + 360k < hi
    best = None
    best_d = math.inf
    for k in sorted({k0 - 1, k0, k0 + 1, k_first, k_last}, reverse=True):
        x = v + 360.0 * k
        if lo < x < hi:
            d = abs(x - c)
            if d < best_d - TIE_EPS:
                best, best_d = x, d
    return best


def select_from_solutions(
    solutions: Mapping[Status, Sequence[float] | None],
    pattern: Sequence[str],
    current_q: Sequence[float],
    turn_min: Sequence[float],
    turn_max: Sequence[float],
    max_change: Sequence[float],
    weights: Sequence[float],
    allowed_pattern: Sequence[str] | None,
    status_fn: Callable[[Sequence[float]], Status],
    *,
    shift_360: bool = True,
) -> list[float] | None:
    """The rule (module docstring) on precomputed IK branches.

    ``solutions`` maps each branch label (hand, elbow, arm) to its joints (degrees, as the
    IK reports them) or None. ``status_fn`` is the robot's status formula
    (``RobotModel.status``). ``allowed_pattern`` None = no restriction.
    Returns the chosen joints or None.
    """
    cur = [float(x) for x in current_q]
    cur_status = tuple(status_fn(cur))
    best: list[float] | None = None
    best_cost = math.inf
    for label in STATUS_ORDER:
        q = solutions.get(label)
        if q is None or not status_matches(pattern, label, cur_status):
            continue
        cand: list[float] = []
        for j in range(6):
            v = float(q[j])
            if math.isnan(v):
                break
            if shift_360:
                x = _nearest_in_limits(v, cur[j], turn_min[j], turn_max[j])
            else:  # BackwardCalc: the IK's value, shifted once by ∓360 if outside the limits
                x = v if turn_min[j] < v < turn_max[j] else v - math.copysign(360.0, v)
                if not (turn_min[j] < x < turn_max[j]):
                    x = None
            if x is None or abs(x - cur[j]) > max_change[j]:
                break
            cand.append(x)
        else:
            if allowed_pattern is not None and not status_matches(
                allowed_pattern, tuple(status_fn(cand)), cur_status
            ):
                continue
            cost = max(w * abs(x - c) for w, x, c in zip(weights, cand, cur, strict=True))
            if cost < best_cost - TIE_EPS:
                best, best_cost = cand, cost
    return best


def joint_move_allowed(
    target_q: Sequence[float],
    current_q: Sequence[float],
    turn_min: Sequence[float],
    turn_max: Sequence[float],
    max_change: Sequence[float],
    allowed_pattern: Sequence[str] | None,
    status_fn: Callable[[Sequence[float]], Status],
) -> bool:
    """``MovePTPJoints``/``RoutetestJoints`` check: strict turn limits, inclusive max change,
    allowed status of the target joints (``noToggle…`` = status of the current joints)."""
    for j in range(6):
        v = float(target_q[j])
        if not (turn_min[j] < v < turn_max[j]):
            return False
        if abs(v - float(current_q[j])) > max_change[j]:
            return False
    if allowed_pattern is None:
        return True
    return status_matches(allowed_pattern, tuple(status_fn(target_q)), tuple(status_fn(current_q)))


def branches_of(kin: Solver, pose12: Sequence[float]) -> dict[Status, list[float] | None]:
    """The 8 IK branches of one pose keyed by status label.

    ``kin.ik(T)`` must return (N, 8, 6) degrees (NaN = no solution) in the order of
    ``kin.BRANCHES`` if it has one, else ``opw.BRANCHES`` (hand major, noflip first), as
    ``opw.ik`` does: the raw branches, each joint in (−180, 180], *without* the turn limits
    (the ±360° representatives are chosen here).  A ``kin`` with ``ik_one`` (``calc.Kinematics``:
    the same branches without numpy's per-call overhead) gives them as lists, None = no solution.
    """
    import numpy as np

    from . import opw

    labels = getattr(kin, "BRANCHES", None) or opw.BRANCHES
    ik_one = getattr(kin, "ik_one", None)
    if ik_one is not None:
        return {_label(label): q for label, q in zip(labels, ik_one(pose12), strict=True)}
    arr = np.asarray(kin.ik(np.asarray(pose12, dtype=float).reshape(1, 12)), dtype=float)
    arr = arr.reshape(-1, 8, 6)[0]
    out: dict[Status, list[float] | None] = {}
    for label, q in zip(labels, arr, strict=True):
        ok = bool(np.all(np.isfinite(q)))
        out[_label(label)] = [float(x) for x in q] if ok else None
    return out


def _label(label: str | Sequence[str]) -> Status:
    hand, elbow, arm = label.split() if isinstance(label, str) else label
    return hand, elbow, arm


def _status_tuple(fn: StatusFn) -> Callable[[Sequence[float]], Status]:
    """Wrap a status function that may answer "noflip up lefty" or a 3-tuple."""

    def status(q: Sequence[float]) -> Status:
        st = fn(q)
        hand, elbow, arm = st.split() if isinstance(st, str) else st
        return hand, elbow, arm

    return status


def select(
    kin: Solver,
    T12: Sequence[float],
    pattern: Sequence[str],
    current_q: Sequence[float],
    turn_min: Sequence[float],
    turn_max: Sequence[float],
    max_change: Sequence[float],
    weights: Sequence[float],
    allowed_pattern: Sequence[str] | None = TOGGLE_ALL,
    *,
    shift_360: bool = True,
    status_fn: StatusFn | None = None,
) -> list[float] | None:
    """Configuration choice of a Cartesian move (module docstring).

    ``kin.ik(T)`` gives the 8 raw branches (no turn limits applied; see ``branches_of``) of
    ``T12`` (12 numbers, row-wise 3x4); the status formula is ``status_fn``, else
    ``kin.robot_status``, ``kin.robot.status`` or ``kin.status`` (a "noflip up lefty" string
    is accepted). Returns the chosen joints or None (``false``).
    Patterns may be 1–3 words in any order (normalised here; ValueError if invalid).
    For ``MovePTPHomRowWise`` pass ``PTP_HOM_PATTERN``; for BackwardCalc-style branch choice
    ``shift_360=False`` and ``allowed_pattern=None``.
    """
    if status_fn is None:
        status_fn = getattr(kin, "robot_status", None)  # calc.Kinematics (geometry-aware)
    if status_fn is None:
        # none of those: the docstring's last resort, kin.status (AttributeError without it)
        status_fn = getattr(getattr(kin, "robot", None), "status", None) or cast(_WithStatus, kin).status
    try:
        pat = parse_status(pattern)
        allowed = None if allowed_pattern is None else parse_status(allowed_pattern)
    except ValueError as exc:
        raise ValueError(f"incorrect status pattern {pattern!r} / {allowed_pattern!r}: {exc}") from None
    return select_from_solutions(
        branches_of(kin, T12),
        pat,
        current_q,
        turn_min,
        turn_max,
        max_change,
        weights,
        allowed,
        _status_tuple(status_fn),
        shift_360=shift_360,
    )
