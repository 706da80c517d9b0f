"""rob6's kaw_fs joints versus the Kawasaki controller's, as the kawasaki link maps them.

The table (deploy/kawasaki/README.md, "Joints"): controller = (q1, q2 + 90, -q3, -q4, -q5, -q6)
degrees. Checked against an independent FS03N chain, not rob6's model: the joint axes as
Kawasaki describes its arms (its ROS package khi_robot, whose joint values are the
controller's own: JT1 about the downward vertical, JT2 and JT3 about horizontal axes turning
opposite ways, the upper arm and forearm upright at 0, JT4/JT6 along the forearm and flange,
JT5 about a horizontal axis), with the FS03N's lengths from robots.md (d1 250, a1 120,
a2 250, d4 250, d6 80). The chain is written as screw axes at the upright zero, a different
formulation from rob6's Denavit-Hartenberg model; both have their base at the J1 axis on
the floor, x forward, z up, so flange positions compare directly, orientations up to the
fixed difference of the two flange frames.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from rob6.robots import get_robot
from rob6_driver.links.kawasaki_codec import (
    CONTROLLER_MAX_DEG,
    CONTROLLER_MIN_DEG,
    from_controller_deg,
    outside_controller_range,
    point,
    to_controller_deg,
)
from rob6_kinematics.calc import Kinematics

ROBOT = get_robot("kaw_fs")
D1, A1, A2, D4, D6 = 250.0, 120.0, 250.0, 250.0, 80.0

#: (axis, a point on it) at the controller's zero, the arm upright, facing +x
SCREWS = [
    ((0, 0, -1), (0, 0, 0)),  # JT1: positive turns clockwise seen from above
    ((0, 1, 0), (A1, 0, D1)),  # JT2: positive leans the upper arm forward
    ((0, -1, 0), (A1, 0, D1 + A2)),  # JT3: turns the other way round
    ((0, 0, 1), (A1, 0, 0)),  # JT4: along the forearm
    ((0, -1, 0), (A1, 0, D1 + A2 + D4)),  # JT5: the wrist
    ((0, 0, 1), (A1, 0, 0)),  # JT6: the flange
]
FLANGE_AT_ZERO = np.array([A1, 0.0, D1 + A2 + D4 + D6])


def _rotation(axis: tuple[float, float, float], angle: float) -> np.ndarray:
    w = np.asarray(axis, float)
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    rotation: np.ndarray = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
    return rotation


def controller_flange(q_controller_deg: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The FS03N's flange (rotation, position mm) for the controller's joint angles."""
    transform = np.eye(4)
    for (axis, on_axis), angle in zip(SCREWS, np.radians(q_controller_deg), strict=True):
        r = _rotation(axis, angle)
        step = np.eye(4)
        step[:3, :3] = r
        step[:3, 3] = np.asarray(on_axis, float) - r @ np.asarray(on_axis, float)
        transform = transform @ step
    return transform[:3, :3], transform[:3, :3] @ FLANGE_AT_ZERO + transform[:3, 3]


def rob6_flange(kin: Kinematics, q_deg: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pose = kin.fk(np.asarray(q_deg, float))[0]
    return pose[:, :3], pose[:, 3]


def test_the_documented_table() -> None:
    assert to_controller_deg([0.0] * 6).tolist() == [0.0, 90.0, 0.0, 0.0, 0.0, 0.0]
    assert to_controller_deg([10, 20, 30, 40, 50, 60]).tolist() == [10.0, 110.0, -30.0, -40.0, -50.0, -60.0]
    assert from_controller_deg([10.0, 110.0, -30.0, -40.0, -50.0, -60.0]).tolist() == [10, 20, 30, 40, 50, 60]
    assert not np.signbit(from_controller_deg([0.0, 90.0, 0.0, 0.0, 0.0, 0.0])).any()
    rng = np.random.default_rng(3)
    q = np.round(rng.uniform(-150, 150, (50, 6)), 3)
    assert np.allclose(from_controller_deg(to_controller_deg(q)), q, atol=1e-9)
    assert point(7, [0, 0, 0, 0, 0, 0], 0.048, False) == b"P 7 0.000 90.000 0.000 0.000 0.000 0.000 48 0\n"


def test_the_arm_stretched_forward_is_where_both_say() -> None:
    """rob6's zero (robots.md: flange at (700, 0, 250)) is the controller's (0, 90, 0, 0, 0, 0)."""
    kin = Kinematics(ROBOT)
    _, ours = rob6_flange(kin, np.zeros(6))
    _, theirs = controller_flange(to_controller_deg(np.zeros(6)))
    assert ours == pytest.approx([700.0, 0.0, 250.0], abs=1e-9)
    assert theirs == pytest.approx([700.0, 0.0, 250.0], abs=1e-9)


def test_forward_kinematics_agree_through_the_convention() -> None:
    kin = Kinematics(ROBOT)
    rng = np.random.default_rng(15)
    lo, hi = np.array(ROBOT.turn_min), np.array(ROBOT.turn_max)
    r0_ours, _ = rob6_flange(kin, np.zeros(6))
    r0_theirs, _ = controller_flange(to_controller_deg(np.zeros(6)))
    offset = r0_theirs.T @ r0_ours  # the two flange frames' fixed difference
    for _ in range(200):
        q = rng.uniform(lo * 0.9, hi * 0.9)
        r_ours, p_ours = rob6_flange(kin, q)
        r_theirs, p_theirs = controller_flange(to_controller_deg(q))
        assert p_ours == pytest.approx(p_theirs, abs=1e-6)
        assert r_ours == pytest.approx(r_theirs @ offset, abs=1e-9)


@pytest.mark.parametrize("sign, offset", [
    ((-1, 1, -1, -1, -1, -1), (0, 90, 0, 0, 0, 0)),  # q1 the other way round
    ((1, -1, -1, -1, -1, -1), (0, 90, 0, 0, 0, 0)),  # q2
    ((1, 1, 1, -1, -1, -1), (0, 90, 0, 0, 0, 0)),  # q3
    ((1, 1, -1, 1, -1, -1), (0, 90, 0, 0, 0, 0)),  # q4
    ((1, 1, -1, -1, 1, -1), (0, 90, 0, 0, 0, 0)),  # q5
    ((1, 1, -1, -1, -1, 1), (0, 90, 0, 0, 0, 0)),  # q6
    ((1, 1, -1, -1, -1, -1), (0, -90, 0, 0, 0, 0)),  # the J2 offset the other way
    ((1, 1, -1, -1, -1, -1), (0, 0, 0, 0, 0, 0)),  # no J2 offset
    ((1, 1, -1, -1, -1, -1), (0, 90, 90, 0, 0, 0)),  # a J3 offset
])
def test_the_check_would_catch_another_convention(sign: tuple[int, ...], offset: tuple[int, ...]) -> None:
    kin = Kinematics(ROBOT)
    rng = np.random.default_rng(1)
    qs = rng.uniform(-50, 50, (6, 6))
    r0_ours, _ = rob6_flange(kin, np.zeros(6))
    r0_theirs, _ = controller_flange(np.array(sign) * 0 + np.array(offset))
    fixed = r0_theirs.T @ r0_ours
    differs = False
    for q in qs:
        r_ours, p_ours = rob6_flange(kin, q)
        r_theirs, p_theirs = controller_flange(np.array(sign) * q + np.array(offset))
        differs |= not (np.allclose(p_ours, p_theirs, atol=1e-3) and np.allclose(r_ours, r_theirs @ fixed, atol=1e-6))
    assert differs


def test_the_ranges_rob6_and_the_controller_share() -> None:
    """rob6's kaw_fs table copies the data sheet's numbers, which are the controller's: in rob6's
    convention the controller allows q2 in -150 .. 60 and q3 in -120 .. 150. Every position
    rob6's limits allow maps into the controller's range except q3 below -120, which the link
    refuses to send."""
    lo = np.minimum(to_controller_deg(ROBOT.turn_min), to_controller_deg(ROBOT.turn_max))
    hi = np.maximum(to_controller_deg(ROBOT.turn_min), to_controller_deg(ROBOT.turn_max))
    inside = (lo >= CONTROLLER_MIN_DEG) & (hi <= CONTROLLER_MAX_DEG)
    assert inside.tolist() == [True, True, False, True, True, True]
    assert (float(lo[2]), float(hi[2])) == (-120.0, 150.0)
    assert outside_controller_range([0, 0, -119.9, 0, 0, 0]) == ""
    assert outside_controller_range([0, 0, -121, 0, 0, 0]) == (
        "joint 3 at -121.000 is JT3 121.000 on the controller, outside its range -150 .. 120")
