"""URDF files, the Pinocchio model and the numpy FK agree."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest

from rob6.robots import get_robot
from rob6_kinematics import opw
from rob6_kinematics.calc import Kinematics
from rob6_kinematics.urdf import GEOMETRIES, generate, urdf_dir

ROBOTS = list(GEOMETRIES)
ZERO_POS = {"kr16": (1768, 0, 640), "kr3": (710, 0, 350), "ad850": (925, 0, 425), "kaw_fs": (700, 0, 250)}


@pytest.mark.parametrize("robot", ROBOTS)
def test_committed_urdf_is_generated(robot: str) -> None:
    path = urdf_dir() / f"{robot}.urdf"
    assert path.read_text() == generate(get_robot(GEOMETRIES[robot]), robot), (
        "regenerate with: python -m rob6_kinematics.urdf"
    )


@pytest.mark.parametrize("robot", ROBOTS)
def test_urdf_structure(robot: str) -> None:
    path = urdf_dir() / f"{robot}.urdf"
    root = ET.parse(path).getroot()
    assert root.tag == "robot" and root.get("name") == robot
    joints = root.findall("joint")
    rev = [j for j in joints if j.get("type") == "revolute"]
    assert [j.get("name") for j in rev] == [f"joint_{i}" for i in range(1, 7)]
    r = get_robot(GEOMETRIES[robot])
    for i, j in enumerate(rev):
        lim = j.find("limit")
        assert lim is not None
        assert math.isclose(float(lim.attrib["lower"]), math.radians(r.turn_min[i]), abs_tol=1e-9)
        assert math.isclose(float(lim.attrib["upper"]), math.radians(r.turn_max[i]), abs_tol=1e-9)
        assert float(lim.attrib["velocity"]) > 0 and float(lim.attrib["effort"]) > 0
    links = {link.get("name") for link in root.findall("link")}
    assert {"base_link", "flange"} | {f"link_{i}" for i in range(1, 7)} <= links
    assert all(link.find("visual") is not None for link in root.findall("link"))

    model = pin.buildModelFromUrdf(str(path))
    assert model.nq == 6 and model.existFrame("flange")
    geom = pin.buildGeomFromUrdf(model, str(path), pin.GeometryType.VISUAL)
    assert geom.ngeoms >= 10


@pytest.mark.parametrize("robot", ROBOTS)
def test_flange_convention_at_zero(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    for T in (k.fk(np.zeros(6))[0], k.pin.fk(np.zeros(6))):
        assert np.allclose(T[:, :3], [[0, 0, -1], [0, -1, 0], [-1, 0, 0]], atol=1e-12)
        assert np.allclose(T[:, 3], ZERO_POS[robot], atol=1e-9)
    # positive q1 turns clockwise seen from above (y < 0)
    assert k.fk([10, 0, 0, 0, 0, 0])[0, 1, 3] < 0


@pytest.mark.parametrize("robot", ROBOTS)
def test_fk_variants_agree_with_pinocchio(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    q = np.random.default_rng(7).uniform(-180, 180, size=(300, 6))
    T = k.fk(q)
    assert np.abs(T - k.fk_fast(q)).max() < 1e-9
    assert np.abs(T - opw.fk_dh(k.g, q)).max() < 1e-9
    assert np.abs(T - k.pin.fk_batch(q)).max() < 1e-9


@pytest.mark.parametrize("robot", ROBOTS)
def test_jacobian_matches_finite_differences(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    q = np.array([10.0, -60.0, 80.0, 20.0, 40.0, 30.0])
    J = k.jacobian(q)
    h = 1e-6  # deg
    T0 = k.fk(q)[0]
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        T1 = k.fk(q + dq)[0]
        v = (T1[:, 3] - T0[:, 3]) / np.radians(h)
        W = (T1[:, :3] - T0[:, :3]) @ T0[:, :3].T / np.radians(h)  # skew(omega)
        w = np.array([W[2, 1], W[0, 2], W[1, 0]])
        assert np.allclose(J[:3, i], v, atol=1e-3 * (1 + np.abs(v).max()))
        assert np.allclose(J[3:, i], w, atol=1e-5)


@pytest.mark.parametrize("robot", ROBOTS)
def test_manipulability_vanishes_at_singularities(robot: str) -> None:
    k = Kinematics(get_robot(robot))
    generic = k.manipulability([10, -60, 80, 20, 40, 30])
    assert generic > 1e-4
    assert k.manipulability([10, -60, 80, 20, 0, 30]) < 1e-9 * max(1.0, generic)  # wrist
    beta = math.degrees(math.atan2(k.g.a3, k.g.d4))
    assert k.manipulability([10, -60, beta, 20, 40, 30]) < 1e-9  # stretched elbow
    assert k.pin.condition([10, -60, 80, 20, 0, 30]) > 1e8
