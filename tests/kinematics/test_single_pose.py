"""The numpy-free single-pose path (``opw.ik_one``, ``opw.fk_compiled_one`` and the
``Kinematics`` commands built on them) gives the numbers of the vectorised path.

Joints to 1e-9 deg and no-solution exactly (None <-> NaN); in particular the sign
of J4 / J5 / J6 at +-180, which numpy's rounding noise decides.  ForwardCalc's
``%f`` text byte for byte.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pytest

from rob6.robots import ROBOT_TYPES, get_robot
from rob6_kinematics import opw
from rob6_kinematics.calc import TIE_EPS, TIE_ORDER, Kinematics, apply_limits
from rob6_kinematics.opw import FloatArray

TOL = 1e-9
SPECIAL = [0.0, 90.0, -90.0, 180.0, -180.0, 45.0, 10.0]


def poses_joints(k: Kinematics, seed: int, n: int = 300) -> np.ndarray:
    """Random joints, 'nice' joints (0, +-90, +-180 ...), and mixtures of both."""
    rng = np.random.default_rng(seed)
    rand = rng.uniform(-180, 180, (n, 6))
    nice = rng.choice(SPECIAL, size=(n, 6))
    mix = np.where(rng.random((n, 6)) < 0.5, nice, rand)
    # singular wrist (q5 = 0 and next to the 1e-4 threshold), stretched / folded elbow
    beta = math.degrees(math.atan2(k.g.a3, k.g.d4))
    sing = mix.copy()
    sing[:, 4] = rng.choice([0.0, 1e-9, -1e-7, 5.7e-3, 180.0], size=n)
    stretched = mix.copy()
    stretched[:, 2] = rng.choice([beta, beta + 180.0, beta - 180.0, beta + 1e-6, beta - 2e-8], size=n)
    return np.concatenate([rand, nice, mix, sing, stretched])


def all_poses(k: Kinematics, seed: int) -> np.ndarray:
    T = k.fk(poses_joints(k, seed)).reshape(-1, 12)
    far = T.copy()
    far[:, [3, 7, 11]] *= 10.0  # out of reach
    return np.concatenate([T, np.round(T, 6), far])


def assert_same(one: Sequence[Sequence[float] | None], ref: FloatArray, ctx: object) -> None:
    assert len(one) == 8
    for b in range(8):
        r = ref[b]
        if one[b] is None:
            assert not np.all(np.isfinite(r)), (ctx, b, r)
        else:
            assert np.all(np.isfinite(r)), (ctx, b, one[b], r)
            assert np.max(np.abs(np.array(one[b]) - r)) <= TOL, (ctx, b, one[b], r)


@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_ik_one_equals_ik(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    T = all_poses(k, seed=sum(map(ord, robot)))
    Q = opw.ik(k.g, T)
    for t, ref in zip(T, Q, strict=True):
        assert_same(opw.ik_one(k.g, t.tolist()), ref, t.tolist())
    assert len(T) > 4000


def test_ik_one_needs_the_exact_wrist_at_180() -> None:
    """Without the exact (fma) wrist rotation some J4/J6 come out at -180 where
    numpy says +180 (or the reverse): the case the exact recomputation is for."""
    k = Kinematics(get_robot("kr16"))
    T = k.fk(np.array([[0, -90, 90, 0, 45, 0], [30, -60, 100, 180, 30, 0], [0, 0, 0, 0, 90, 180]]))
    Q = opw.ik(k.g, T)
    hits = 0
    for t, ref in zip(T.reshape(-1, 12), Q, strict=True):
        assert_same(opw.ik_one(k.g, t.tolist()), ref, t.tolist())
        hits += int(np.sum(np.isclose(np.abs(ref[:, 3:]), 180.0)))
    assert hits > 0


def test_ik_one_degenerate_input() -> None:
    g = opw.Geometry.of(get_robot("kr16"))
    assert opw.ik_one(g, [0.0] * 12) == [None] * 8  # zero rotation
    t = k16_pose = Kinematics(get_robot("kr16")).fk([10, -60, 80, 20, 40, 30])[0]
    for bad in (math.nan, math.inf):
        x = t.reshape(12).tolist()
        x[3] = bad
        assert opw.ik_one(g, x) == [None] * 8
        x = t.reshape(12).tolist()
        x[0] = bad  # only J6 uses x: those branches have no finite solution
        with np.errstate(invalid="ignore"):
            assert_same(opw.ik_one(g, x), opw.ik(g, x)[0], x)
    # shapes: (3,4), (4,4), numpy
    ref = opw.ik(g, k16_pose)[0]
    assert_same(opw.ik_one(g, k16_pose), ref, "3x4")
    assert_same(opw.ik_one(g, np.vstack([k16_pose, [0, 0, 0, 1]])), ref, "4x4")
    with pytest.raises(ValueError):
        opw.ik_one(g, np.zeros((2, 12)))


@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_fk_compiled_one_equals_fk_compiled(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    q = poses_joints(k, seed=7 + len(robot), n=200)
    q = np.concatenate([q, np.round(q, 3)])
    for n in range(1, 7):
        ref = opw.fk_compiled(k.g, q, n).reshape(-1, 12)
        for qi, r in zip(q.tolist(), ref, strict=True):
            one = opw.fk_compiled_one(k.g, qi, n)
            assert " ".join("%f" % x for x in one) == " ".join("%f" % x for x in r), (qi, n)
            assert np.max(np.abs(np.array(one) - r)) <= 1e-9


# ------------------------------------------------------------------ Kinematics commands
def backward_reference(k: Kinematics, T: npt.ArrayLike, words: Sequence[str], cur: FloatArray, lo: FloatArray,
                       hi: FloatArray, mc: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray | None]:
    """The vectorised BackwardCalc (before the single-pose path)."""
    Q = apply_limits(opw.ik(k.g, np.asarray(T).reshape(1, 12))[0], lo, hi)
    with np.errstate(invalid="ignore"):
        Q[np.any(np.abs(Q - cur) > mc, axis=1)] = np.nan
    allowed = set(k.resolve_pattern(words, cur))
    best, best_cost = None, np.inf
    for b in TIE_ORDER:
        if b in allowed and np.all(np.isfinite(Q[b])):
            cost = float(np.max(w * np.abs(Q[b] - cur)))
            if cost < best_cost - TIE_EPS:
                best, best_cost = Q[b], cost
    return Q, best


@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_commands_equal_vectorised(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    rng = np.random.default_rng(99)
    qs = poses_joints(k, seed=3, n=40)
    T = k.fk(qs).reshape(-1, 12)
    for i, t in enumerate(T):
        cur = qs[rng.integers(len(qs))] if i % 2 else np.zeros(6)
        if i % 3 == 0:
            lo, hi = k.turn_min, k.turn_max
            mc, w = k.max_change, k.weights
            kw = {}
        else:
            lo = np.maximum(k.turn_min, -rng.uniform(150, 360, 6))
            hi = np.minimum(k.turn_max, rng.uniform(150, 360, 6))
            mc = rng.uniform(50, 400, 6)
            w = rng.uniform(0.5, 4, 6)
            kw = dict(turn_min=list(lo), turn_max=list(hi), max_change=list(mc))
        words = "toggleHand toggleElbow toggleArm" if i % 4 else BRANCH_WORDS[i % 8]
        Q, best = backward_reference(k, t, words, cur, lo, hi, mc, w)
        got = k.backward_calc(t.tolist(), words, cur, weights=list(w), **kw)
        assert (got is None) == (best is None), (t.tolist(), words)
        if got is not None:
            assert np.max(np.abs(np.array(got) - best)) <= TOL
        assert k.is_possible(t, words, list(cur), **kw) == (best is not None)
        cands = k.candidates(t.tolist(), cur, **kw)
        assert np.array_equal(np.isnan(cands), np.isnan(Q))
        assert np.nanmax(np.abs(cands - Q), initial=0.0) <= TOL


BRANCH_WORDS = list(opw.BRANCHES)


@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_forward_calc_text_equals_vectorised(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    qs = poses_joints(k, seed=5, n=30)
    mid = (np.asarray(k.robot.hw_min, float) + np.asarray(k.robot.hw_max, float)) / 2
    for q in qs:
        for n in (6, 3, 1):
            nums = list(q[:n])
            full = np.concatenate([q[:n], mid[n:]])
            got = k.forward_calc(nums)
            if not np.all((k.turn_min < full) & (full < k.turn_max)):
                assert got is None
                continue
            ref = opw.fk_compiled(k.g, full, n)[0].reshape(12)
            assert got is not None
            assert " ".join("%f" % x for x in got[0]) == " ".join("%f" % x for x in ref)
            assert got[1] == k.status(full)


class _VectorisedOnly:
    """A kin without ik_one: selection.branches_of takes the vectorised path."""

    def __init__(self, k: Kinematics) -> None:
        self.k = k
        self.BRANCHES = k.BRANCHES
        self.robot_status = k.robot_status

    def ik(self, T: npt.ArrayLike) -> FloatArray:
        return self.k.ik(T)


@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_select_single_pose_equals_vectorised(robot: str) -> None:
    from rob6_kinematics import selection

    k = Kinematics(get_robot(robot))
    v = _VectorisedOnly(k)
    rng = np.random.default_rng(11)
    qs = poses_joints(k, seed=4, n=20)
    for i, t in enumerate(k.fk(qs).reshape(-1, 12).tolist()):
        cur = list(qs[rng.integers(len(qs))])
        words = ["toggleHand", "toggleElbow", "toggleArm"] if i % 3 else BRANCH_WORDS[i % 8].split()
        args = (words, cur, list(k.turn_min), list(k.turn_max), list(k.max_change), list(k.weights))
        for shift in (True, False):
            a = selection.select(k, t, *args, shift_360=shift)
            b = selection.select(v, t, *args, shift_360=shift)
            assert (a is None) == (b is None), (t, words)
            if a is not None:
                assert np.max(np.abs(np.array(a) - np.array(b))) <= TOL
