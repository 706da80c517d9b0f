"""rob6's ad850 joints versus the Adept controller's, as the simple_message link maps them.

The table (deploy/adept/README.md section 5): controller = (-q1, q2, q3 + 90, -q4, q5, -q6)
degrees, radians on the wire. It is checked here two ways: the documented values and
ranges, and forward kinematics -- rob6's own kinematics of the ad850 against a chain
built from the ROS-Industrial Viper URDF (adept_viper_s650_support/urdf/
viper_s650_macro.xacro: joint origins and axes; its joint values are the controller's,
the V+ program converts only units) with the s850's lengths. The two bases and flanges
need not coincide, so the comparison uses what a rigid change of frame keeps: distances
between flange positions, the signed volume they span (a mirrored sign convention flips
it) and the angles between flange orientations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pytest

from rob6.robots import get_robot
from rob6_driver.links.simple_message import (
    from_controller_deg,
    from_wire,
    to_controller_deg,
    to_wire,
)
from rob6_kinematics.calc import Kinematics

ROBOT = get_robot("ad850")


def test_the_documented_table() -> None:
    assert to_controller_deg([0.0] * 6).tolist() == [0.0, 0.0, 90.0, 0.0, 0.0, 0.0]
    assert to_controller_deg([10, 20, 30, 40, 50, 60]).tolist() == [-10.0, 20.0, 120.0, -40.0, 50.0, -60.0]
    wire = to_wire([10, 20, 30, 40, 50, 60])
    assert wire == pytest.approx([math.radians(x) for x in (-10, 20, 120, -40, 50, -60)], abs=1e-12)
    assert from_wire(wire + [0.0] * 4).tolist() == pytest.approx([10, 20, 30, 40, 50, 60], abs=1e-9)
    rng = np.random.default_rng(3)
    q = rng.uniform(-170, 170, (50, 6))
    assert np.allclose(from_controller_deg(to_controller_deg(q)), q, atol=1e-12)


def test_positions_read_from_the_wire_carry_what_float32_carries() -> None:
    as_float32 = np.float32(math.radians(90.0))  # the controller's J3 at rob6's 0
    q = from_wire([0.0, 0.0, float(as_float32), 0.0, 0.0, 0.0])
    assert q.tolist() == [0.0] * 6 and not np.signbit(q).any()


def test_the_ranges_map_onto_the_controllers() -> None:
    """rob6's hardware ranges of the ad850 are the controller's joint ranges (Adept's data)."""
    lo, hi = to_controller_deg(ROBOT.hw_min), to_controller_deg(ROBOT.hw_max)
    ranges = [(float(a), float(b)) for a, b in zip(np.minimum(lo, hi), np.maximum(lo, hi), strict=True)]
    assert ranges == [(-170.0, 170.0), (-190.0, 45.0), (-29.0, 259.0), (-190.0, 190.0), (-120.0, 120.0),
                      (-360.0, 360.0)]


# ---------------------------------------------------------------------- forward kinematics
#: (origin of the joint in the previous link's frame, axis), the Viper URDF's structure;
#: lengths (mm) of the s850 (rob6's ad850 model): d1 335 (where along the J1 axis does not
#: matter), a1 75, a2 365, a3 90 (the URDF's -x offset of joint 4), d4 405 (the URDF splits
#: it between joints 4 and 5), d6 80
URDF_CHAIN = [((0, 0, 0), "z"), ((75, 0, 335), "y"), ((365, 0, 0), "y"), ((-90, 0, 0), "z"),
              ((0, 0, 405), "y"), ((0, 0, 80), "z")]


def _rot(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    if axis == "z":
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def urdf_flange(q_controller_deg: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    rotation, position = np.eye(3), np.zeros(3)
    for (origin, axis), angle in zip(URDF_CHAIN, np.radians(q_controller_deg), strict=True):
        position = position + rotation @ np.array(origin, float)
        rotation = rotation @ _rot(axis, angle)
    return rotation, position


def rob6_flange(kin: Kinematics, q_deg: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    pose = kin.fk(np.asarray(q_deg, float))[0]
    return pose[:, :3], pose[:, 3]


def invariants(flanges: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[float]:
    """Distances, the signed volume and the angles between orientations of four flanges."""
    (r0, p0), *rest = flanges
    values = [float(np.linalg.norm(p - p0)) for _, p in rest]
    values.append(float(np.linalg.det(np.stack([p - p0 for _, p in rest]))) / 1e6)
    values += [math.degrees(math.acos(np.clip((np.trace(r0.T @ r) - 1) / 2, -1, 1))) for r, _ in rest]
    return values


def test_forward_kinematics_agree_through_the_convention() -> None:
    kin = Kinematics(ROBOT)
    rng = np.random.default_rng(15)
    lo, hi = np.array(ROBOT.turn_min), np.array(ROBOT.turn_max)
    for _ in range(100):
        qs = rng.uniform(lo * 0.9, hi * 0.9, (4, 6))
        ours = invariants([rob6_flange(kin, q) for q in qs])
        theirs = invariants([urdf_flange(to_controller_deg(q)) for q in qs])
        assert ours == pytest.approx(theirs, abs=1e-6)


@pytest.mark.parametrize("sign, offset", [
    ((1, 1, 1, 1, 1, 1), (0, 0, 90, 0, 0, 0)),  # mirrored: q1, q4, q6 the other way round
    ((-1, 1, 1, 1, 1, -1), (0, 0, 90, 0, 0, 0)),  # q4 alone
    ((-1, 1, 1, -1, 1, 1), (0, 0, 90, 0, 0, 0)),  # q6 alone
    ((-1, -1, 1, -1, 1, -1), (0, 0, 90, 0, 0, 0)),  # q2
    ((-1, 1, 1, -1, 1, -1), (0, 0, -90, 0, 0, 0)),  # the J3 offset the other way
])
def test_the_check_would_catch_another_convention(sign: tuple[int, ...], offset: tuple[int, ...]) -> None:
    kin = Kinematics(ROBOT)
    rng = np.random.default_rng(1)
    qs = rng.uniform(-100, 100, (4, 6))
    other = [np.array(sign) * q + np.array(offset) for q in qs]
    ours = invariants([rob6_flange(kin, q) for q in qs])
    assert not np.allclose(ours, invariants([urdf_flange(c) for c in other]), atol=1e-3)
