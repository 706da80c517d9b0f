"""URDF generator for the rob6 robots (one file per geometry).

The kinematic tree is the DH chain of ``robots.md`` written as URDF joints, so the
``flange`` frame of the URDF is exactly the pose the protocol reports (converted to
metres):

* ``base_link`` is the robot base frame (x forward at q1 = 0, z up, origin at the
  foot of the J1 axis).
* ``joint_i`` is revolute about z of its joint frame with ``axis = (0, 0, s_i)``,
  s = [-1, 1, 1, -1, 1, -1], so the URDF joint value **is** the robot's joint
  angle q_i (in radians) and the URDF limits are the default turn limits.
* ``link_i`` frames are the DH frames before the ``Tz(d_i) Tx(a_i) Rx(alpha_i)``
  part; the constant angle offset of J3 (-90 deg) sits in ``joint_3``'s origin.
* ``flange`` (fixed joint ``flange_joint``): ``Tz(d6) Ry(180 deg)`` from
  ``link_6`` — z points INTO the flange (towards the wrist), as in the original.

Visuals are simple cylinders along the DH offsets plus a box base, enough for
Foxglove / RViz; inertials are rough (uniform rods) and only there so that tools
that expect them are satisfied.

``python -m rob6_kinematics.urdf [DIR]`` (re)writes ``DIR/<geometry>.urdf``
(default: ``shared/rob6/urdf`` of the installed ``rob6`` package).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from rob6.robots import URDF_DIR, RobotModel

from .opw import DH_ALPHA, DH_OFFSETS, DH_SIGNS, FloatArray

#: geometries that get a URDF and the robot type whose parameters they use
GEOMETRIES = {"kr16": "kr16", "kr3": "kr3", "ad850": "ad850", "kaw_fs": "kaw_fs"}

_COLOURS = {
    "kuka": ("kuka_orange", "1.0 0.4 0.0 1.0"),
    "adept": ("adept_white", "0.9 0.9 0.92 1.0"),
    "kawasaki": ("kawasaki_white", "0.95 0.95 0.95 1.0"),
}
_DARK = ("joint_grey", "0.25 0.25 0.28 1.0")


def urdf_dir() -> Path:
    return URDF_DIR


def _f(x: float) -> str:
    """Shortest text that round-trips the float exactly (metres / radians)."""
    x = float(x)
    if abs(x) < 1e-15:
        return "0"
    if x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _vec(v: Iterable[float]) -> str:
    return " ".join(_f(x) for x in v)


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw (R = Rz(y) Ry(p) Rx(r)) of a rotation matrix."""
    p = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if math.isclose(abs(p), math.pi / 2, abs_tol=1e-12):
        r = 0.0
        y = math.atan2(-R[0, 1], R[1, 1])
    else:
        r = math.atan2(R[2, 1], R[2, 2])
        y = math.atan2(R[1, 0], R[0, 0])
    return r, p, y


def _rx(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], float)


def _rz(a: float) -> FloatArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], float)


def _cyl_z(z0: float, z1: float, radius: float, material: str, x: float = 0.0) -> str:
    length = abs(z1 - z0)
    if length < 1e-6:
        return ""
    return (
        f'    <visual>\n      <origin xyz="{_vec((x, 0, (z0 + z1) / 2))}" rpy="0 0 0"/>\n'
        f'      <geometry><cylinder radius="{_f(radius)}" length="{_f(length)}"/></geometry>\n'
        f'      <material name="{material}"/>\n    </visual>\n'
    )


def _cyl_x(x0: float, x1: float, z: float, radius: float, material: str) -> str:
    length = abs(x1 - x0)
    if length < 1e-6:
        return ""
    return (
        f'    <visual>\n      <origin xyz="{_vec(((x0 + x1) / 2, 0, z))}" rpy="0 {_f(math.pi / 2)} 0"/>\n'
        f'      <geometry><cylinder radius="{_f(radius)}" length="{_f(length)}"/></geometry>\n'
        f'      <material name="{material}"/>\n    </visual>\n'
    )


def _inertial(mass: float, com: Iterable[float], length: float, radius: float) -> str:
    # uniform rod about its own axis, crude but positive definite
    ixx = mass * (3 * radius**2 + max(length, radius) ** 2) / 12.0
    izz = mass * radius**2 / 2.0
    return (
        f'    <inertial>\n      <origin xyz="{_vec(com)}" rpy="0 0 0"/>\n'
        f'      <mass value="{_f(mass)}"/>\n'
        f'      <inertia ixx="{_f(ixx)}" ixy="0" ixz="0" iyy="{_f(ixx)}" iyz="0" izz="{_f(izz)}"/>\n'
        f"    </inertial>\n"
    )


def generate(robot: RobotModel, name: str | None = None) -> str:
    """URDF text of one robot (``rob6.robots.RobotModel``)."""
    name = name or robot.geometry
    mm = 1e-3
    d = [robot.d1 * mm, 0.0, 0.0, robot.d4 * mm, 0.0, robot.d6 * mm]
    a = [robot.a1 * mm, robot.a2 * mm, robot.a3 * mm, 0.0, 0.0, 0.0]
    reach = (abs(robot.a1) + abs(robot.a2) + math.hypot(robot.a3, robot.d4)) * mm
    r_arm = max(0.02, 0.045 * reach / 1.0)
    r_joint = 1.3 * r_arm
    r_wrist = 0.7 * r_arm
    colour, rgba = _COLOURS[robot.vendor]
    rated = [v / 0.0012 for v in robot.default_speed]  # deg/s (defaults = 10 % rated)

    out = [
        '<?xml version="1.0"?>\n',
        f"<!-- Generated by rob6_kinematics.urdf from rob6.robots ({robot.name}); do not edit.\n",
        "     Joint values are the robot's joint angles (rad); flange z points INTO the flange. -->\n",
        f"<robot name={quoteattr(name)}>\n",
        f'  <material name="{colour}"><color rgba="{rgba}"/></material>\n',
        f'  <material name="{_DARK[0]}"><color rgba="{_DARK[1]}"/></material>\n',
    ]
    # base
    base_h = 0.35 * robot.d1 * mm
    out.append('  <link name="base_link">\n')
    out.append(
        f'    <visual>\n      <origin xyz="{_vec((0, 0, base_h / 2))}" rpy="0 0 0"/>\n'
        f'      <geometry><box size="{_vec((3 * r_joint, 3 * r_joint, base_h))}"/></geometry>\n'
        f'      <material name="{_DARK[0]}"/>\n    </visual>\n'
    )
    out.append("  </link>\n")

    parent = "base_link"
    # transform from parent link frame to joint i frame: Tz Tx Rx of the previous
    # DH row, then the constant offset Rz(o_i)
    prev_xyz = (0.0, 0.0, 0.0)
    prev_R = np.eye(3)
    for i in range(6):
        R = prev_R @ _rz(DH_OFFSETS[i])
        rpy = rpy_from_matrix(R)
        lo = math.radians(robot.turn_min[i])
        hi = math.radians(robot.turn_max[i])
        vel = math.radians(rated[i])
        link = f"link_{i + 1}"
        out.append(f'  <joint name="joint_{i + 1}" type="revolute">\n')
        out.append(f'    <parent link="{parent}"/>\n    <child link="{link}"/>\n')
        out.append(f'    <origin xyz="{_vec(prev_xyz)}" rpy="{_vec(rpy)}"/>\n')
        out.append(f'    <axis xyz="0 0 {_f(DH_SIGNS[i])}"/>\n')
        out.append(
            f'    <limit lower="{_f(lo)}" upper="{_f(hi)}" effort="1000" velocity="{_f(vel)}"/>\n'
        )
        out.append("  </joint>\n")

        # link i: joint housing + the d_i (along z) and a_i (along x) offsets
        rad = r_arm if i < 3 else r_wrist
        out.append(f'  <link name="{link}">\n')
        out.append(_cyl_z(-rad, rad, r_joint if i < 3 else 1.2 * r_wrist, _DARK[0]))
        out.append(_cyl_z(0.0, d[i], rad, colour))
        out.append(_cyl_x(0.0, a[i], d[i], rad, colour))
        seg = abs(d[i]) + abs(a[i])
        mass = max(0.5, 60.0 * seg)  # kg, ~60 kg per metre of arm
        com = (a[i] / 2, 0.0, d[i] / 2) if seg else (0.0, 0.0, 0.0)
        out.append(_inertial(mass, com, seg, rad))
        out.append("  </link>\n")

        parent = link
        prev_xyz = (a[i], 0.0, d[i])
        prev_R = _rx(DH_ALPHA[i])

    # flange: Tz(d6) was consumed by link_6's row (prev_xyz), Rx(alpha6 = 0); then Ry(180)
    Rf = prev_R @ np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], float)
    out.append('  <joint name="flange_joint" type="fixed">\n')
    out.append(f'    <parent link="{parent}"/>\n    <child link="flange"/>\n')
    out.append(f'    <origin xyz="{_vec(prev_xyz)}" rpy="{_vec(rpy_from_matrix(Rf))}"/>\n')
    out.append("  </joint>\n")
    out.append('  <link name="flange">\n')
    # flange disc: in the flange frame z points back into the wrist
    out.append(_cyl_z(0.0, 0.01, 1.1 * r_wrist, _DARK[0]))
    out.append("  </link>\n")
    out.append("</robot>\n")
    return "".join(x for x in out if x)


def write_all(directory: Path | None = None) -> list[Path]:
    from rob6.robots import get_robot

    directory = Path(directory) if directory else urdf_dir()
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for geom, robot_name in GEOMETRIES.items():
        p = directory / f"{geom}.urdf"
        p.write_text(generate(get_robot(robot_name), geom))
        paths.append(p)
    return paths


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    for p in write_all(Path(argv[0]) if argv else None):
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
