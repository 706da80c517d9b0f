"""The 3D messages computed from a joint state: per-link ``/tf`` from the URDF, the flange pose from FK.

What is derived and how often is ``derived_channels.py``'s business; this module computes.

``TfDeriver`` turns a joint state (``q`` in degrees) into a ``foxglove.FrameTransforms``
message with one transform per URDF joint (parent link -> child link), so Foxglove's
3D panel, which loads the URDF from ``/robot_description``, moves the robot. No FK
callable is needed for that: the joint origins and axes come from the URDF.

The i-th recorded joint angle drives the i-th movable (revolute/continuous/prismatic)
joint met walking the URDF tree from its root. ``joint_map`` (sign, offset in degrees
per axis) adapts the controller's zero/sign convention to the URDF's when they differ:
``urdf_angle = sign * q + offset``.

``flange_pose`` turns the optional forward-kinematics callable's result (the
protocol's 3x4 row-wise matrix, millimetres) into a ``foxglove.PosesInFrame`` in the
URDF root frame (metres).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rob6.rotations import (
    Quaternion,
    quat_axis_angle,
    quat_conjugate,
    quat_from_matrix,
    quat_from_rpy,
    quat_mul,
)

from .schemas import stamp

#: forward kinematics: joints (degrees) -> the pose (12 numbers, 3x4 row-wise, mm) or None
Fk = Callable[[list[float]], Sequence[Any] | None]


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy_quat: Quaternion
    axis: tuple[float, float, float]

    @property
    def movable(self) -> bool:
        return self.type in ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class UrdfModel:
    name: str
    root: str
    joints: tuple[UrdfJoint, ...]  # tree order from the root (depth first)

    @property
    def movable(self) -> tuple[UrdfJoint, ...]:
        return tuple(j for j in self.joints if j.movable)


def _floats(text: str | None, default: tuple[float, float, float]) -> tuple[float, float, float]:
    if not text:
        return default
    padded = [float(v) for v in text.split()] + list(default)  # missing values from the default
    return (padded[0], padded[1], padded[2])


def _link_of(joint: ET.Element, which: str) -> str:
    """The ``link`` of a joint's ``<parent>`` or ``<child>``."""
    el = joint.find(which)
    link = el.get("link") if el is not None else None
    if link is None:
        raise ValueError(f"URDF joint {joint.get('name')!r} has no {which} link")
    return link


def parse_urdf(text: str) -> UrdfModel:
    """The kinematic tree of a URDF (links, joints, origins, axes)."""
    root = ET.fromstring(text)
    joints: dict[str, UrdfJoint] = {}
    children: dict[str, list[UrdfJoint]] = {}
    for el in root.findall("joint"):
        origin = el.find("origin")
        axis = el.find("axis")
        parent, child = _link_of(el, "parent"), _link_of(el, "child")
        rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
        joint = UrdfJoint(
            name=el.get("name", ""), type=el.get("type", "fixed"), parent=parent, child=child,
            xyz=_floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0)),
            rpy_quat=quat_from_rpy(*rpy),
            axis=_floats(axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0)))
        joints[joint.name] = joint
        children.setdefault(parent, []).append(joint)
    links = [el.get("name", "") for el in root.findall("link")]
    child_links = {j.child for j in joints.values()}
    roots = [name for name in links if name not in child_links] or \
        [j.parent for j in joints.values() if j.parent not in child_links]
    base = roots[0] if roots else ""
    ordered: list[UrdfJoint] = []  # depth first: a chain comes out parent before child

    def walk(link: str) -> None:
        for joint in children.get(link, []):
            ordered.append(joint)
            walk(joint.child)

    walk(base)
    return UrdfModel(name=root.get("name", ""), root=base, joints=tuple(ordered))


class TfDeriver:
    """Joint state -> foxglove.FrameTransforms (one transform per URDF joint)."""

    def __init__(self, urdf: str, joint_map: Sequence[tuple[float, float]] | None = None,
                 frame_prefix: str = ""):
        self.model = parse_urdf(urdf)
        self.joint_map = list(joint_map) if joint_map else None
        self.prefix = frame_prefix
        self._movable_index = {j.name: i for i, j in enumerate(self.model.movable)}

    @property
    def root_frame(self) -> str:
        return self.prefix + self.model.root

    def transforms(self, q_deg: Sequence[float], t_ns: int) -> dict[str, Any]:
        ts = stamp(t_ns)
        out = []
        for joint in self.model.joints:
            rot = joint.rpy_quat
            xyz = joint.xyz
            idx = self._movable_index.get(joint.name)
            if idx is not None and idx < len(q_deg):
                value = float(q_deg[idx])
                if self.joint_map and idx < len(self.joint_map):
                    sign, offset = self.joint_map[idx]
                    value = sign * value + offset
                if joint.type == "prismatic":  # value in mm
                    d = value / 1000.0
                    n = math.sqrt(sum(a * a for a in joint.axis)) or 1.0
                    local = tuple(a / n * d for a in joint.axis)
                    # rotate the local offset into the parent frame by the origin rotation
                    lq = quat_mul(quat_mul(rot, (0.0, local[0], local[1], local[2])), quat_conjugate(rot))
                    xyz = (xyz[0] + lq[1], xyz[1] + lq[2], xyz[2] + lq[3])
                else:
                    rot = quat_mul(rot, quat_axis_angle(joint.axis, math.radians(value)))
            out.append({
                "timestamp": ts,
                "parent_frame_id": self.prefix + joint.parent,
                "child_frame_id": self.prefix + joint.child,
                "translation": {"x": xyz[0], "y": xyz[1], "z": xyz[2]},
                "rotation": {"x": rot[1], "y": rot[2], "z": rot[3], "w": rot[0]},
            })
        return {"transforms": out}


def pose_from_fk(result: Sequence[Any] | None) -> tuple[tuple[float, float, float], Quaternion] | None:
    """(position in m, orientation) from an FK result: 12 numbers (3x4 row-wise, mm),
    16 numbers (4x4), a nested 3x4/4x4 list, or ``None`` (unreachable)."""
    if result is None:
        return None
    flat: list[float]
    if len(result) in (3, 4) and isinstance(result[0], (list, tuple)):
        flat = [float(v) for row in result[:3] for v in row[:4]]
    else:
        flat = [float(v) for v in result]
        if len(flat) == 16:
            flat = flat[:12]
    if len(flat) != 12:
        return None
    rows = [flat[0:4], flat[4:8], flat[8:12]]
    pos = (rows[0][3] / 1000.0, rows[1][3] / 1000.0, rows[2][3] / 1000.0)
    return pos, quat_from_matrix([r[:3] for r in rows])


def flange_message(fk: Fk, q_deg: Sequence[float], t_ns: int, frame_id: str) -> dict[str, Any] | None:
    pose = pose_from_fk(fk(list(q_deg)))
    if pose is None:
        return None
    (x, y, z), (qw, qx, qy, qz) = pose
    return {"timestamp": stamp(t_ns), "frame_id": frame_id,
            "poses": [{"position": {"x": x, "y": y, "z": z},
                       "orientation": {"x": qx, "y": qy, "z": qz, "w": qw}}]}
