"""The cell drawn for Foxglove's 3D panel: its zones and the tool as a ``foxglove.SceneUpdate``, the zone nearest the arm coloured by distance.

The live view (``live.LiveView``) feeds it the recorded ``/cell`` (the driver's ``Cell``) and
``/driver/clearance`` (the nearest pair while the arm moves) and publishes what it returns on
``/cell/scene``, so a live session and a recording played back (``rob6-log play``) look alike.

Drawn in the robot's base frame (the URDF's root, metres), each zone one entity
(``zone:<name>``): a keep-out box a translucent cube; a keep-out half-space a large thin slab
on its forbidden side, its top face on the plane; a keep-in box its twelve edges, so the arm
inside stays visible. The tool's spheres and capsules ride on the flange frame (one entity,
``tool``, frame-locked). The zone the latest clearance names is green when far, amber within
``NEAR_MM`` and red within the cell's margin (or inside); the others are grey. Every update is
the whole scene (a deletion of everything before it, then every entity): a few entities, at
most 10 a second, and a panel opened late needs only the last one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import msgspec

from rob6.messages import Cell, Clearance, ToolShape, Zone
from rob6.rotations import Quaternion, quat_axis_angle, quat_from_rpy

from .schemas import stamp
from .writer import CELL_TOPIC, CLEARANCE_TOPIC

SCENE_TOPIC = "/cell/scene"
#: the robot's base frame and its flange, as the URDFs name them (rob6/urdf; the /tf frames)
BASE_FRAME = "base_link"
FLANGE_FRAME = "flange"
#: the nearest zone turns amber this near (mm), red within the cell's margin
NEAR_MM = 100.0
#: a half-space is drawn as a square slab this wide and this thick (mm)
SLAB_MM = 4000.0
SLAB_THICKNESS_MM = 10.0

Rgba = tuple[float, float, float, float]
GREY: Rgba = (0.55, 0.6, 0.7, 0.35)
GREEN: Rgba = (0.2, 0.75, 0.3, 0.45)
AMBER: Rgba = (1.0, 0.65, 0.0, 0.55)
RED: Rgba = (0.9, 0.1, 0.1, 0.65)
TOOL: Rgba = (0.8, 0.8, 0.8, 0.7)

_cell = msgspec.json.Decoder(Cell)
_clearance = msgspec.json.Decoder(Clearance)


def colour(distance_mm: float, margin_mm: float) -> Rgba:
    """The nearest zone's colour at ``distance_mm`` (< 0: inside)."""
    if distance_mm <= margin_mm:
        return RED
    return AMBER if distance_mm <= NEAR_MM else GREEN


class CellScene:
    """The scene of the latest cell, coloured by the latest clearance; not thread-safe (the
    live view calls it under its own lock)."""

    def __init__(self) -> None:
        self.cell: Cell | None = None
        self.nearest: Clearance | None = None

    def update(self, topic: str, payload: bytes, t_ns: int) -> dict[str, Any] | None:
        """The scene after a ``/cell`` or ``/driver/clearance`` record (its JSON), or None:
        another topic, a record that cannot be read, or no cell yet."""
        try:
            if topic == CELL_TOPIC:
                self.cell, self.nearest = _cell.decode(payload), None
            elif topic == CLEARANCE_TOPIC:
                self.nearest = _clearance.decode(payload)
            else:
                return None
        except (msgspec.DecodeError, msgspec.ValidationError):
            return None
        return self.scene(t_ns) if self.cell is not None else None

    def scene(self, t_ns: int) -> dict[str, Any]:
        """Every entity of the cell, replacing whatever was drawn before ``t_ns``."""
        assert self.cell is not None
        t = stamp(t_ns)
        entities = [self._zone(zone, t) for zone in self.cell.zones]
        if self.cell.tool:
            entities.append(_entity("tool", FLANGE_FRAME, t, _tool(self.cell.tool), frame_locked=True))
        return {"deletions": [{"timestamp": t, "type": 1, "id": ""}], "entities": entities}

    def _zone(self, zone: Zone, t: dict[str, int]) -> dict[str, Any]:
        assert self.cell is not None
        metadata: dict[str, str] = {"keep": zone.keep}
        rgba = GREY
        near = self.nearest
        if near is not None and near.zone and near.other == zone.name:
            rgba = colour(near.distance_mm, self.cell.margin_mm)
            metadata.update(distance_mm=f"{near.distance_mm:.1f}", nearest_part=near.part)
        if zone.half_space is not None:
            shapes = {"cubes": [_slab(zone.half_space.point, zone.half_space.normal, rgba)]}
        elif zone.keep == "out":
            shapes = {"cubes": [_box(zone, rgba)]}
        else:
            shapes = {"lines": [_edges(zone, rgba)]}
        return _entity(f"zone:{zone.name}", BASE_FRAME, t, shapes, metadata=metadata)


def _entity(entity_id: str, frame: str, t: dict[str, int], shapes: dict[str, list[dict[str, Any]]], *,
            frame_locked: bool = False, metadata: dict[str, str] | None = None) -> dict[str, Any]:
    return {"timestamp": t, "frame_id": frame, "id": entity_id, "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": frame_locked,
            "metadata": [{"key": k, "value": v} for k, v in (metadata or {}).items()],
            **{kind: shapes.get(kind, []) for kind in ("cubes", "spheres", "cylinders", "lines")}}


def _m(mm: Sequence[float]) -> dict[str, float]:
    return {"x": mm[0] / 1000.0, "y": mm[1] / 1000.0, "z": mm[2] / 1000.0}


def _pose(position_mm: Sequence[float], rotation: Quaternion = (1.0, 0.0, 0.0, 0.0)) -> dict[str, Any]:
    w, x, y, z = rotation
    return {"position": _m(position_mm), "orientation": {"x": x, "y": y, "z": z, "w": w}}


def _rgba(rgba: Rgba) -> dict[str, float]:
    return dict(zip("rgba", rgba, strict=True))


def _z_to(direction: Sequence[float]) -> Quaternion:
    """The rotation that turns the z axis onto ``direction`` (unit)."""
    axis = (-direction[1], direction[0], 0.0)  # z x direction
    if math.hypot(*axis) < 1e-12:
        return (1.0, 0.0, 0.0, 0.0) if direction[2] > 0 else quat_axis_angle((1.0, 0.0, 0.0), math.pi)
    return quat_axis_angle(axis, math.acos(max(-1.0, min(1.0, direction[2]))))


def _slab(point: Sequence[float], normal: Sequence[float], rgba: Rgba) -> dict[str, Any]:
    """A half-space: a thin square slab on its forbidden side (against the normal), its top
    face on the plane, centred below the base's origin."""
    offset = sum(p * n for p, n in zip(point, normal, strict=True))  # the plane: normal . x = offset
    centre = [n * (offset - SLAB_THICKNESS_MM / 2.0) for n in normal]
    return {"pose": _pose(centre, _z_to(normal)), "size": _m([SLAB_MM, SLAB_MM, SLAB_THICKNESS_MM]),
            "color": _rgba(rgba)}


def _box_frame(zone: Zone) -> tuple[list[float], list[float], Quaternion]:
    assert zone.box is not None
    low, high = zone.box.min, zone.box.max
    centre = [(lo + hi) / 2.0 for lo, hi in zip(low, high, strict=True)]
    size = [hi - lo for lo, hi in zip(low, high, strict=True)]
    return centre, size, quat_from_rpy(*(math.radians(v) for v in zone.box.rpy_deg))


def _box(zone: Zone, rgba: Rgba) -> dict[str, Any]:
    centre, size, rotation = _box_frame(zone)
    return {"pose": _pose(centre, rotation), "size": _m(size), "color": _rgba(rgba)}


#: the corners (index = 4 sx + 2 sy + sz, each 0 or 1) that an edge of a box joins
_EDGES = [(a, a | bit) for a in range(8) for bit in (1, 2, 4) if not a & bit]


def _edges(zone: Zone, rgba: Rgba) -> dict[str, Any]:
    """A keep-in box: its twelve edges (a line list, two points each), 2 px wide."""
    centre, size, rotation = _box_frame(zone)
    half = [s / 2.0 for s in size]
    corners = [[sx * half[0], sy * half[1], sz * half[2]] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    points = []
    for a, b in _EDGES:
        points += [_m(corners[a]), _m(corners[b])]
    return {"type": 2, "pose": _pose(centre, rotation), "thickness": 2.0, "scale_invariant": True,
            "points": points, "color": _rgba((*rgba[:3], 1.0)), "colors": [], "indices": []}


def _tool(shapes: list[ToolShape]) -> dict[str, list[dict[str, Any]]]:
    """The tool's spheres, and each capsule as a cylinder with a sphere at either end."""
    spheres, cylinders = [], []
    for shape in shapes:
        diameter = _m([2.0 * shape.radius] * 3)
        ends = [shape.a] if shape.b is None else [shape.a, shape.b]
        spheres += [{"pose": _pose(end), "size": diameter, "color": _rgba(TOOL)} for end in ends]
        if shape.b is not None:
            axis = [b - a for a, b in zip(shape.a, shape.b, strict=True)]
            length = math.sqrt(sum(v * v for v in axis))
            if length > 0:
                middle = [(a + b) / 2.0 for a, b in zip(shape.a, shape.b, strict=True)]
                cylinders.append({"pose": _pose(middle, _z_to([v / length for v in axis])),
                                  "size": _m([2.0 * shape.radius, 2.0 * shape.radius, length]),
                                  "bottom_scale": 1.0, "top_scale": 1.0, "color": _rgba(TOOL)})
    return {"spheres": spheres, "cylinders": cylinders}
