"""Protocol semantics of rob6_kinematics.calc (ForwardCalc, BackwardCalc, patterns)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from rob6.robots import get_robot
from rob6_kinematics.calc import TIE_ORDER, Kinematics
from rob6_kinematics.opw import BRANCHES

K = {r: Kinematics(get_robot(r)) for r in ("kr16", "kr3", "ad850", "kaw_fs")}
P1_KR16 = [-0.788518, 0.399854, -0.467285, 1272.955930, -0.568459, -0.763835, 0.305633,
           -259.728047, -0.234720, 0.506629, 0.829598, 870.777994]
ZERO = np.zeros(6)


def fmt(xs: Iterable[float] | None) -> str:
    assert xs is not None, "no solution"
    return " ".join("%f" % x for x in xs)


def forward(k: Kinematics, q: list[float]) -> tuple[list[float], str]:
    """ForwardCalc of joints that it answers (not ``false``)."""
    result = k.forward_calc(q)
    assert result is not None
    return result


# ------------------------------------------------------------------ ForwardCalc
def test_forward_calc_reference_example() -> None:
    mat, status = forward(K["kr16"], [10, 0, 0, 0, 0, 0])
    assert fmt(mat) == ("0.000000 -0.173648 -0.984808 1741.140107 0.000000 -0.984808 0.173648 "
                        "-307.009978 -1.000000 -0.000000 -0.000000 640.000000")
    assert status == "noflip up lefty"


def test_forward_calc_number_counts() -> None:
    k = K["kr16"]
    assert k.forward_calc([]) is None
    assert k.forward_calc([10, 0, 0, 0, 0, 0, 7, 8]) == k.forward_calc([10, 0, 0, 0, 0, 0])
    mat, _ = forward(k, [10])  # frame of joint 1 (REFERENCE 6.5)
    assert fmt(mat) == ("0.984808 0.000000 0.173648 256.050016 -0.173648 0.000000 0.984808 "
                        "-45.148526 0.000000 -1.000000 0.000000 675.000000")
    # kaw_fs: a single number fills J2 with the hardware midpoint 45 > 20 -> false
    assert K["kaw_fs"].forward_calc([10]) is None
    assert K["kaw_fs"].forward_calc([10, -20]) is not None


def test_forward_calc_strict_limits() -> None:
    k = K["kr16"]
    assert k.forward_calc([0, 20, 0, 0, 0, 0]) is None  # J2 max 20 is not allowed
    assert k.forward_calc([0, 19.999999, 0, 0, 0, 0]) is not None
    assert k.forward_calc([0, 0, 0, 0, 0, 0], turn_min=[-1] * 6, turn_max=[1] * 6) is not None
    assert k.forward_calc([2, 0, 0, 0, 0, 0], turn_min=[-1] * 6, turn_max=[1] * 6) is None
    assert k.forward_calc([float("nan"), 0, 0, 0, 0, 0]) is None


def test_kaw_fs_forward_calc_is_plus_250() -> None:
    mat, status = forward(K["kaw_fs"], [0, 0, 0, 0, 0, 0])
    assert np.allclose(np.array(mat)[[3, 7, 11]], [700, 0, 250])
    assert status == "noflip down lefty"


# ------------------------------------------------------------------ patterns
def test_no_toggle_keeps_current_status() -> None:
    k = K["kr16"]
    cur = [-84, -75, -41, -60, 27, 38]  # noflip down lefty
    assert k.resolve_pattern("noToggleHand noToggleElbow noToggleArm", cur) == [BRANCHES.index("noflip down lefty")]
    assert sorted(k.resolve_pattern("flip toggleElbow noToggleArm", cur)) == sorted(
        [BRANCHES.index("flip up lefty"), BRANCHES.index("flip down lefty")])


# ------------------------------------------------------------------ BackwardCalc
def test_backward_calc_reference_examples() -> None:
    k = K["kr16"]
    assert fmt(k.backward_calc(P1_KR16, "noflip up lefty", ZERO)) == \
        "9.999998 -60.000000 80.000005 20.000037 39.999982 29.999977"
    assert fmt(k.backward_calc(P1_KR16, "flip up lefty", ZERO)) == \
        "9.999998 -60.000000 80.000005 -159.999963 -39.999982 -150.000023"
    assert k.backward_calc(P1_KR16, "noflip down lefty", ZERO) is None
    # wrist singularity (robots.md): flip == noflip, q4 = 0
    mat, _ = forward(k, [10, 0, 0, 0, 0, 0])
    mat = [float("%f" % x) for x in mat]  # what a client sends back
    a = k.backward_calc(mat, "noflip up lefty", ZERO)
    assert fmt(a) == "10.000001 -0.000055 0.000110 0.000000 -0.000055 0.000000"
    assert k.backward_calc(mat, "flip up lefty", ZERO) == a


def test_backward_calc_failures() -> None:
    k = K["kr16"]
    far = list(P1_KR16)
    far[3] = 5000.0
    assert k.backward_calc(far, "noflip up lefty", ZERO) is None  # out of reach
    assert k.backward_calc([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0], "noflip up lefty", ZERO) is None
    zero_rot = [0, 0, 0, 1272.95593, 0, 0, 0, -259.728047, 0, 0, 0, 870.777994]
    assert all(k.backward_calc(zero_rot, s, ZERO) is None for s in BRANCHES)
    # turn limits (ik.jsonl: SetJointsMaxTurnMax 1 1 1 1 1 1 -> false)
    assert k.backward_calc(P1_KR16, "noflip up lefty", ZERO, turn_max=[1] * 6) is None


def test_max_change_is_inclusive() -> None:
    k = K["kr16"]
    q = np.array(k.backward_calc(P1_KR16, "noflip up lefty", ZERO))
    cur = np.array([0.0, -50, 70, 10, 30, 20])
    change = np.abs(q - cur)
    assert k.backward_calc(P1_KR16, "noflip up lefty", cur, max_change=change) is not None
    tighter = change.copy()
    tighter[2] = np.nextafter(change[2], 0)
    assert k.backward_calc(P1_KR16, "noflip up lefty", cur, max_change=tighter) is None
    assert not k.is_possible(P1_KR16, "noflip up lefty", cur, max_change=tighter)


def test_shift_by_360_into_the_limits() -> None:
    k = K["ad850"]  # J2 -190 .. 20
    q = np.array([5.0, -185.0, 30.0, 10.0, 30.0, 10.0])
    T = k.fk(q)[0].ravel()
    got = k.backward_calc(T, k.status(q), ZERO)
    assert got is not None and np.allclose(got, q, atol=1e-9)


def test_stretched_elbow_up_equals_down() -> None:
    k = K["kr3"]  # q3 = 0 is stretched (a3 = 0)
    T = k.fk([10, -30, 0, 20, 40, 30])[0].ravel()
    up = k.backward_calc(T, "noflip up lefty", ZERO)
    down = k.backward_calc(T, "noflip down lefty", ZERO)
    assert up is not None and down is not None and np.allclose(up, down)


def test_toggle_rule_examples() -> None:
    """The selection rule documented in Kinematics.backward_calc (ik.jsonl cases)."""
    k = K["kr16"]
    p2 = [-0.409282, 0.838520, 0.359683, -51.974354, 0.909251, 0.342075, 0.237164,
          101.572356, 0.075829, 0.424109, -0.902431, 2100.259435]
    assert fmt(k.backward_calc(p2, "toggleHand toggleElbow toggleArm", ZERO)) == \
        "-87.999989 -112.766571 32.019318 41.898354 -31.727336 -65.430959"  # flip up lefty
    assert fmt(k.backward_calc(P1_KR16, "toggleHand toggleElbow toggleArm", ZERO)) == \
        "9.999998 -60.000000 80.000005 20.000037 39.999982 29.999977"  # noflip up lefty
    ad = K["ad850"]
    zero_pose, _ = forward(ad, [0, 0, 0, 0, 0, 0])
    zero_pose = [float("%f" % x) for x in zero_pose]
    zero_joints = ad.backward_calc(zero_pose, "toggleHand toggleElbow toggleArm", ZERO)
    assert zero_joints is not None and np.allclose(zero_joints, 0, atol=1e-9)
    assert [BRANCHES[b] for b in TIE_ORDER[:3]] == ["flip up lefty", "flip up righty", "flip down lefty"]
    # the weights decide: with a heavy J5 the noflip branch (|q5| equal) ties, J4 decides
    assert fmt(k.backward_calc(p2, "toggleHand up lefty", ZERO, weights=[0, 0, 0, 1, 0, 0])) == \
        "-87.999989 -112.766571 32.019318 41.898354 -31.727336 -65.430959"
    assert fmt(k.backward_calc(p2, "toggleHand toggleElbow lefty", ZERO, weights=[0, 1, 1, 0, 0, 0])) == \
        "-87.999989 -77.999998 -38.000008 116.000047 -23.000014 -146.000053"  # flip down lefty


def test_ik_shapes_and_batch() -> None:
    k = K["kr16"]
    q = np.random.default_rng(3).uniform(-150, 150, size=(50, 6))
    T = k.fk(q)
    assert T.shape == (50, 3, 4) and k.fk(q[0]).shape == (1, 3, 4)
    Q = k.ik(T)
    assert Q.shape == (50, 8, 6)
    assert np.all((Q[np.isfinite(Q)] > -180) & (Q[np.isfinite(Q)] <= 180))
    assert k.ik(T.reshape(50, 12)).shape == (50, 8, 6)
    assert k.BRANCHES == BRANCHES and len(set(BRANCHES)) == 8


def test_status() -> None:
    assert K["kr16"].status(ZERO) == "noflip up lefty"
    assert K["kr3"].status(ZERO) == "noflip down lefty"
    assert K["ad850"].status([0, 0, 12.6, 0, -1, 0]) == "flip up lefty"
    assert K["kr16"].status_batch([[0, 0, 0, 0, 0, 0], [0, 0, -10, 0, -1, 0]]).tolist() == [0, 6]


def test_bench_smoke() -> None:
    from rob6_kinematics.bench import bench_ik

    r = bench_ik("kr3", n_batch=200, n_single=10, n_clik=2, repeat=1)
    assert r["batch_ik_poses_per_s"] > 0 and r["single_ik_poses_per_s"] > 0 and r["clik_poses_per_s"] > 0
    assert r["clik_success_rate"] == 1.0 and r["batch_solved_rate"] == 1.0
