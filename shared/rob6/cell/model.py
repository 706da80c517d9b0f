"""The cell as Pinocchio/coal geometry: the arm's capsules, the tool, the zones, and their distances.

The arm's parts are the links of the robot's URDF (``rob6/urdf``), each made of the shapes
that enclose the real arm (``rob6.cell.arms``: capsules, spheres, the base's box), grown by
the cell's padding for that part (``arm_padding``); the URDF's cylinders are the live view's
drawing only. The tool's spheres and capsules ride on the
flange frame. A keep-out half-space is a coal ``Halfspace``, a keep-out box a ``Box``, a
keep-in box the six half-spaces outside its faces. The pairs measured: every moving part
against every zone it does not ignore (the base never: it cannot move), and, with
self-collision on, every two parts that are neither near in the chain (``NEAR_IN_CHAIN``)
nor touching at the zero position nor allowed by the file. ``distances(q)`` is one ``pinocchio.computeDistances`` call: signed, in mm.

``lever`` bounds how far a part can move when a joint turns: for each part and joint the
distance from that joint's origin to the part's farthest point, summed link by link along
the chain, so it holds in every configuration (mm per rad). ``guard`` uses it to bound what
a stop travels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..messages import Cell, Zone
from ..robots import RobotModel
from .arms import ArmShape, arm_shapes
from .file import CellError

N_JOINTS = 6
#: the joint a part rides on: base 0, link_k k, the tool 6 (on the flange)
TOOL_JOINT = 6
#: parts this near along the chain (the base, link_1 ... link_6, the tool) are not measured
#: against each other: a joint's limits keep its neighbours apart, and the URDF's simple
#: shapes overlap there (the elbow's offset, the wrist) where the real links pass beside
#: each other. Two apart still: the upper arm and the forearm fold past each other within
#: the Viper's joint limits.
NEAR_IN_CHAIN = 2


@dataclass(frozen=True)
class Pair:
    """One measured pair: ``part`` against ``other``, a zone (``keep`` out or in) or a part (``keep`` "")."""

    part: str
    other: str
    keep: str  # "out" | "in" for a zone, "" for another part of the arm (self-collision)

    @property
    def zone(self) -> bool:
        return bool(self.keep)


class CellModel:
    """The robot's kinematics (from its URDF) with the cell's geometry; not thread-safe (one per thread)."""

    def __init__(self, robot: RobotModel, cell: Cell) -> None:
        self.robot, self.cell = robot, cell
        urdf = robot.urdf
        self.model = pin.buildModelFromXML(urdf)
        self.data = self.model.createData()
        self.geometry = pin.GeometryModel()
        self._part_of: list[str] = []  # geometry object -> its part
        self._extent: dict[str, float] = {}  # part -> farthest point from its joint's origin (m)
        self._radial: dict[str, float] = {}  # part -> farthest point from its joint's axis (m)
        self._joint: dict[str, int] = {}  # part -> the joint it rides on
        for part, shapes in arm_shapes(robot.geometry).items():
            joint = 0 if part == "base" else self.model.getJointId(f"joint_{part.removeprefix('link_')}")
            for piece in shapes:
                geometry, placement = _arm_shape(piece, arm_padding(cell, part))
                self._add(part, joint, placement, geometry)
        flange = self.model.frames[self.model.getFrameId("flange")]
        self.warnings: list[str] = []  # said at start (the driver's log)
        for shape in cell.tool:
            if max(shape.a[2], shape.b[2] if shape.b is not None else -math.inf) > 0.0:
                self.warnings.append(f"tool shape {shape.name!r} reaches z > 0 of the flange frame, inside the wrist: "
                                     f"a tool sticks out along -z (docs/SAFETY_ZONES.md)")
            geometry, local = _tool_shape(shape.radius, shape.a, shape.b)
            self._add(shape.name, TOOL_JOINT, flange.placement * local, geometry)
        self.parts = list(dict.fromkeys(self._part_of))
        first_zone = len(self.geometry.geometryObjects)
        zone_objects: list[tuple[Zone, int]] = []
        for zone in cell.zones:
            for geometry, placement in _zone_shapes(zone):
                zone_objects.append((zone, self.geometry.addGeometryObject(
                    pin.GeometryObject(f"zone:{zone.name}", 0, placement, geometry))))
        self.pairs: list[Pair] = []
        self.unchecked: list[str] = []  # pairs of parts not measured, each with why (GetCell lists them)
        self._pair_parts: list[tuple[int, int]] = []  # indices into parts; -1: a zone
        parts_index = {name: i for i, name in enumerate(self.parts)}
        for k in range(first_zone):
            part = self._part_of[k]
            if part == "base":
                continue
            for zone, z in zone_objects:
                if part not in zone.ignore:
                    self._pair(k, z, Pair(part, zone.name, zone.keep), parts_index[part], -1)
        if cell.self_collision:
            self._self_pairs(first_zone, parts_index)
        self.geometry_data = pin.GeometryData(self.geometry)
        for request in self.geometry_data.distanceRequests:
            request.enable_signed_distance = True
        self.lever = self._levers()  # (parts, 6) mm per rad
        self._pair_lever = self._pair_levers()  # (pairs, 6) mm per rad

    # ------------------------------------------------------------------ building
    def _add(self, part: str, joint: int, placement: pin.SE3, geometry: coal.CollisionGeometry) -> None:
        self.geometry.addGeometryObject(pin.GeometryObject(f"{part}#{len(self._part_of)}", joint, placement, geometry))
        self._part_of.append(part)
        self._joint[part] = joint
        self._extent[part] = max(self._extent.get(part, 0.0), _reach(geometry, placement))
        self._radial[part] = max(self._radial.get(part, 0.0), _radial(geometry, placement))

    def _pair(self, a: int, b: int, pair: Pair, part_a: int, part_b: int) -> None:
        self.geometry.addCollisionPair(pin.CollisionPair(a, b))
        self.pairs.append(pair)
        self._pair_parts.append((part_a, part_b))

    def _self_pairs(self, count: int, parts_index: dict[str, int]) -> None:
        """Every two parts' objects, but those within ``NEAR_IN_CHAIN`` of each other along
        the chain, two links of the arm touching at the zero position and the file's allowed
        pairs: each of those is listed in ``unchecked`` with why. A tool shape touching a link
        at the zero position is refused (``CellError``) unless the file allows the pair."""
        allowed = {frozenset(pair) for pair in self.cell.allowed_pairs}
        tool = {shape.name for shape in self.cell.tool}
        skipped: dict[frozenset[str], str] = {}

        def place(part: str) -> int:  # along the chain: the base 0, link_k k, the tool after link_6
            return N_JOINTS + 1 if part in tool else self._joint[part]

        probe = pin.GeometryModel()
        for obj in self.geometry.geometryObjects[:count]:
            probe.addGeometryObject(obj)
        candidates = []
        for a in range(count):
            for b in range(a + 1, count):
                pa, pb = self._part_of[a], self._part_of[b]
                if pa == pb:
                    continue
                if frozenset((pa, pb)) in allowed:
                    skipped[frozenset((pa, pb))] = "allowed by the cell file"
                    continue
                if abs(place(pa) - place(pb)) <= NEAR_IN_CHAIN:
                    skipped[frozenset((pa, pb))] = "near in the chain: the joint between them keeps them apart"
                    continue
                candidates.append((a, b))
                probe.addCollisionPair(pin.CollisionPair(a, b))
        probe_data = pin.GeometryData(probe)
        pin.computeDistances(self.model, self.data, probe, probe_data, np.zeros(self.model.nq))
        touching = {frozenset((self._part_of[a], self._part_of[b]))
                    for (a, b), result in zip(candidates, probe_data.distanceResults, strict=True)
                    if result.min_distance <= self.cell.margin_mm / 1000.0}
        for names in touching:
            shape = next((name for name in sorted(names) if name in tool), None)
            if shape is not None:
                other = next(iter(names - {shape}), shape)
                raise CellError(f"cell file {self.cell.source}: tool shape {shape!r} touches {other} at the zero "
                                f"position (within the {self.cell.margin_mm:g} mm margin), so the pair cannot be "
                                f"checked: move or shrink the shape, or add [{other}, {shape}] to arm: allowed_pairs "
                                f"if they may touch")
            skipped[names] = "touching at the zero position (the model's shapes overlap there)"
        for pair in candidates:
            # the one further along the chain first: "tool tip with base"
            a, b = sorted(pair, key=lambda k: -place(self._part_of[k]))
            pa, pb = self._part_of[a], self._part_of[b]
            if frozenset((pa, pb)) not in touching:
                self._pair(a, b, Pair(pa, pb, ""), parts_index[pa], parts_index[pb])
        self.unchecked = [f"{' with '.join(sorted(pair, key=lambda p: -place(p)))}: {why}"
                          for pair, why in sorted(skipped.items(), key=lambda item: sorted(item[0]))]

    def _levers(self) -> np.ndarray:
        """(parts, 6): how far (mm) a point of the part can move per radian of each joint, in
        any configuration: for a joint before the part's own, the link lengths from that joint
        to the part's joint plus the part's reach from its joint; for the part's own joint, the
        part's farthest point from that joint's axis (it turns about it: a forearm spinning about
        its own axis moves by its radius, not its length). Every joint turns about the z axis of
        its frame (rob6/urdf)."""
        lengths = [float(np.linalg.norm(self.model.jointPlacements[j].translation)) for j in range(N_JOINTS + 1)]
        lever = np.zeros((len(self.parts), N_JOINTS))
        for i, part in enumerate(self.parts):
            joint = self._joint[part]
            for j in range(1, joint):
                lever[i, j - 1] = 1000.0 * (sum(lengths[j + 1:joint + 1]) + self._extent[part])
            if joint >= 1:
                lever[i, joint - 1] = 1000.0 * self._radial[part]
        return lever

    def _pair_levers(self) -> np.ndarray:
        """(pairs, 6): how much nearer a pair's two sides come per radian of each joint (mm)."""
        rows = []
        for part_a, part_b in self._pair_parts:
            row = self.lever[part_a].copy()
            if part_b >= 0:  # two parts: the later one moves against the earlier by the joints between them
                a, b = sorted((part_a, part_b), key=lambda i: self._joint[self.parts[i]])
                row = self.lever[b].copy()
                row[:self._joint[self.parts[a]]] = 0.0
            rows.append(row)
        return np.array(rows).reshape(-1, N_JOINTS)

    # ------------------------------------------------------------------ measuring
    def nearest(self, q_deg: np.ndarray) -> float:
        """The least signed distance of all pairs (mm; < 0: inside) with the joints at ``q_deg``:
        one ``computeDistances``, whose answer names the nearest pair (reading every pair's
        result from Python costs 2-3 us each, five times the computation)."""
        return self.nearest_pair(q_deg)[0]

    def nearest_pair(self, q_deg: np.ndarray) -> tuple[float, Pair]:
        """``nearest``, and which pair it is."""
        k = pin.computeDistances(self.model, self.data, self.geometry, self.geometry_data, np.radians(q_deg))
        return float(self.geometry_data.distanceResults[k].min_distance) * 1000.0, self.pairs[k]

    def distances(self, q_deg: np.ndarray, pairs: np.ndarray | None = None) -> np.ndarray:
        """Signed distance of every pair, or of those indexed by ``pairs`` (mm; < 0: inside),
        with the joints at ``q_deg``."""
        pin.computeDistances(self.model, self.data, self.geometry, self.geometry_data, np.radians(q_deg))
        results = self.geometry_data.distanceResults
        if pairs is None:
            return np.fromiter((r.min_distance for r in results), float, len(self.pairs)) * 1000.0
        return np.fromiter((results[k].min_distance for k in pairs.tolist()), float, len(pairs)) * 1000.0

    def travel(self, dq_deg: np.ndarray) -> np.ndarray:
        """For each pair, how much nearer its two sides can come while the joints turn by at most
        ``|dq_deg|`` each (mm). A part against a zone: every joint up to the part's moves it. Two
        parts: only the joints between them move one against the other (those before move both
        alike). ``dq_deg`` (..., 6) gives (..., pairs)."""
        needed: np.ndarray = np.radians(np.abs(dq_deg)) @ self._pair_lever.T
        return needed


def arm_padding(cell: Cell, part: str) -> float:
    """The padding (mm) the cell adds around ``part`` of the arm: its own, or the cell's default."""
    return cell.arm_padding_parts.get(part, cell.arm_padding_mm)


def _arm_shape(shape: ArmShape, pad_mm: float) -> tuple[coal.CollisionGeometry, pin.SE3]:
    """A shape of the arm (``rob6.cell.arms``), grown by ``pad_mm`` on every side, in its joint's frame (m)."""
    if shape.kind == "box":
        assert shape.size is not None
        size = (np.array(shape.size) + 2.0 * pad_mm) / 1000.0
        return coal.Box(*size), pin.SE3(np.eye(3), np.array(shape.a) / 1000.0)
    return _tool_shape(shape.radius + pad_mm, list(shape.a), None if shape.b is None else list(shape.b))


def _tool_shape(radius_mm: float, a_mm: list[float], b_mm: list[float] | None) -> tuple[coal.CollisionGeometry, pin.SE3]:
    a = np.array(a_mm) / 1000.0
    if b_mm is None:
        return coal.Sphere(radius_mm / 1000.0), pin.SE3(np.eye(3), a)
    b = np.array(b_mm) / 1000.0
    axis = b - a
    length = float(np.linalg.norm(axis))
    rotation = _z_to(axis / length) if length > 1e-12 else np.eye(3)
    return coal.Capsule(radius_mm / 1000.0, length), pin.SE3(rotation, (a + b) / 2.0)


def _z_to(direction: np.ndarray) -> np.ndarray:
    """A rotation that turns the z axis onto ``direction`` (unit)."""
    rotation: np.ndarray = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), direction).matrix()
    return rotation


def _zone_shapes(zone: Zone) -> list[tuple[coal.CollisionGeometry, pin.SE3]]:
    """The coal shapes of a zone, in the base frame (m)."""
    if zone.half_space is not None:
        normal = np.array(zone.half_space.normal)
        offset = float(normal @ np.array(zone.half_space.point)) / 1000.0
        return [(coal.Halfspace(normal, offset), pin.SE3.Identity())]
    assert zone.box is not None  # file.py: exactly one shape
    low, high = np.array(zone.box.min) / 1000.0, np.array(zone.box.max) / 1000.0
    rotation = pin.rpy.rpyToMatrix(*(math.radians(v) for v in zone.box.rpy_deg))
    centre = (low + high) / 2.0
    if zone.keep == "out":
        return [(coal.Box(*(high - low)), pin.SE3(rotation, centre))]
    shapes = []  # keep in: outside each face is solid
    half = (high - low) / 2.0
    for axis in range(3):
        for sign in (1.0, -1.0):
            outward = sign * rotation[:, axis]
            # solid where outward . x > outward . centre + half: coal's Halfspace(n, d) is n . x < d
            shapes.append((coal.Halfspace(-outward, -(float(outward @ centre) + half[axis])), pin.SE3.Identity()))
    return shapes


def _radial(geometry: coal.CollisionGeometry, placement: pin.SE3) -> float:
    """The farthest a point of ``geometry`` (at ``placement`` in its joint's frame) is from that
    joint's axis, the frame's z axis (m): a convex shape's farthest point from a line is at a
    vertex (a box) or at an end of its segment plus the radius (a capsule, a sphere)."""
    t, rotation = np.asarray(placement.translation), np.asarray(placement.rotation)
    if isinstance(geometry, coal.Capsule):
        half = rotation[:, 2] * float(geometry.halfLength)
        return max(float(np.linalg.norm((t + half)[:2])), float(np.linalg.norm((t - half)[:2]))) + float(geometry.radius)
    if isinstance(geometry, coal.Sphere):
        return float(np.linalg.norm(t[:2])) + float(geometry.radius)
    if isinstance(geometry, coal.Box):
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * np.asarray(geometry.halfSide)
        return float(np.linalg.norm((t + corners @ rotation.T)[:, :2], axis=1).max())
    raise ValueError(f"no radius about an axis for a {type(geometry).__name__}")


def _reach(geometry: coal.CollisionGeometry, placement: pin.SE3) -> float:
    """The farthest a point of ``geometry`` (at ``placement`` in its joint's frame) is from that joint's origin (m)."""
    centre = float(np.linalg.norm(placement.translation))
    if isinstance(geometry, coal.Capsule):
        return centre + float(geometry.halfLength) + float(geometry.radius)
    if isinstance(geometry, coal.Sphere):
        return centre + float(geometry.radius)
    if isinstance(geometry, coal.Box):
        return centre + float(np.linalg.norm(geometry.halfSide))
    raise ValueError(f"no reach for a {type(geometry).__name__}")
