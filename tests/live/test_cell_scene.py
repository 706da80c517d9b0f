"""The cell drawn for the 3D panel (``cell_scene``): where each zone and tool shape is, in
Foxglove's own message types, and the nearest zone's colour following the clearance."""

from __future__ import annotations

import math
from typing import Any

import foxglove.messages as fm
import msgspec
import pytest

from rob6.messages import Box, Cell, Clearance, HalfSpace, ToolShape, Zone
from rob6.rotations import quat_conjugate, quat_from_rpy, quat_mul
from rob6_recorder.cell_scene import (
    AMBER,
    BASE_FRAME,
    FLANGE_FRAME,
    GREEN,
    GREY,
    RED,
    SLAB_MM,
    SLAB_THICKNESS_MM,
    CellScene,
)
from rob6_recorder.writer import CELL_TOPIC, CLEARANCE_TOPIC

TILTED = [0.0, math.sqrt(0.5), math.sqrt(0.5)]
CELL = Cell(source="test", margin_mm=5.0, zones=[
    Zone(name="floor", keep="out", half_space=HalfSpace(point=[0.0, 0.0, -20.0], normal=[0.0, 0.0, 1.0])),
    Zone(name="wall", keep="out", half_space=HalfSpace(point=[0.0, 0.0, 1000.0], normal=TILTED)),
    Zone(name="table", keep="out", box=Box(min=[500.0, -200.0, 0.0], max=[900.0, 200.0, 300.0], rpy_deg=[0.0, 0.0, 30.0])),
    Zone(name="cell", keep="in", box=Box(min=[-1500.0, -1000.0, -50.0], max=[1500.0, 1000.0, 2000.0])),
], tool=[ToolShape(name="gripper", radius=20.0, a=[0.0, 0.0, 0.0], b=[0.0, 0.0, 120.0]),
         ToolShape(name="tip", radius=10.0, a=[0.0, 0.0, 150.0])])
T_NS = 1_700_000_000_123_456_789


def _scene(clearances: tuple[Clearance, ...] = ()) -> dict[str, Any]:
    scene = CellScene()
    out = scene.update(CELL_TOPIC, msgspec.json.encode(CELL), T_NS)
    for clearance in clearances:
        out = scene.update(CLEARANCE_TOPIC, msgspec.json.encode(clearance), T_NS + 1)
    assert out is not None
    return out


def _entities(scene: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {e["id"]: e for e in scene["entities"]}


def _rotate(q: dict[str, float], v: list[float]) -> list[float]:
    w = (q["w"], q["x"], q["y"], q["z"])
    r = quat_mul(quat_mul(w, (0.0, v[0], v[1], v[2])), quat_conjugate(w))
    return list(r[1:])


# ------------------------------------------------------------------ Foxglove's own types
#: field name -> Foxglove's class of it (the SDK rejects a keyword its schema does not have)
_CLASSES: dict[str, Any] = {
    "deletions": fm.SceneEntityDeletion, "entities": fm.SceneEntity, "cubes": fm.CubePrimitive,
    "spheres": fm.SpherePrimitive, "cylinders": fm.CylinderPrimitive, "lines": fm.LinePrimitive,
    "pose": fm.Pose, "position": fm.Vector3, "orientation": fm.Quaternion, "size": fm.Vector3,
    "color": fm.Color, "colors": fm.Color, "points": fm.Point3, "metadata": fm.KeyValuePair,
}


def _foxglove(cls: Any, fields: dict[str, Any]) -> Any:
    """The SDK's message built from our JSON: every field name and type must be Foxglove's."""
    kwargs: dict[str, Any] = {}
    for name, value in fields.items():
        if name in ("timestamp", "lifetime"):
            kwargs[name] = (fm.Timestamp if name == "timestamp" else fm.Duration)(value["sec"], value["nsec"])
        elif name == "type":  # an enum's number
            enum = fm.SceneEntityDeletionType if cls is fm.SceneEntityDeletion else fm.LinePrimitiveLineType
            (kwargs[name],) = [m for m in vars(enum).values() if isinstance(m, enum) and m.value == value]
        elif isinstance(value, list) and name in _CLASSES:
            kwargs[name] = [_foxglove(_CLASSES[name], item) for item in value]
        elif isinstance(value, dict):
            kwargs[name] = _foxglove(_CLASSES[name], value)
        else:
            kwargs[name] = value
    return cls(**kwargs)


def test_the_scene_is_a_foxglove_scene_update() -> None:
    scene = _scene((Clearance(t=1.0, distance_mm=50.0, part="tip", other="table"),))
    message = _foxglove(fm.SceneUpdate, scene)
    assert message.encode()  # Foxglove's encoder takes it
    deletion, = scene["deletions"]  # each update replaces everything drawn before it
    assert deletion["type"] == 1 and deletion["timestamp"] == {"sec": T_NS // 10**9, "nsec": T_NS % 10**9 + 1}
    assert {e["id"] for e in scene["entities"]} == {"zone:floor", "zone:wall", "zone:table", "zone:cell", "tool"}
    assert all(e["lifetime"] == {"sec": 0, "nsec": 0} and e["timestamp"] == deletion["timestamp"]
               for e in scene["entities"])  # until replaced; not older than the deletion


def test_zones_are_drawn_where_the_cell_puts_them() -> None:
    entities = _entities(_scene())
    assert {e["frame_id"] for i, e in entities.items() if i.startswith("zone:")} == {BASE_FRAME}

    # a half-space: a slab on its forbidden side, its top face on the plane
    for name, point, normal in (("floor", [0, 0, -20.0], [0, 0, 1.0]), ("wall", [0, 0, 1000.0], TILTED)):
        (slab,) = entities[f"zone:{name}"]["cubes"]
        assert slab["size"] == pytest.approx({"x": SLAB_MM / 1000, "y": SLAB_MM / 1000, "z": SLAB_THICKNESS_MM / 1000})
        axis = _rotate(slab["pose"]["orientation"], [0.0, 0.0, 1.0])
        assert axis == pytest.approx(normal)  # its thickness along the normal
        centre = [slab["pose"]["position"][k] * 1000 for k in "xyz"]
        top = [c + n * SLAB_THICKNESS_MM / 2 for c, n in zip(centre, normal, strict=True)]
        assert sum((t - p) * n for t, p, n in zip(top, point, normal, strict=True)) == pytest.approx(0, abs=1e-9)
        assert sum(c * n for c, n in zip(centre, normal, strict=True)) < sum(
            p * n for p, n in zip(point, normal, strict=True))  # below the plane: the forbidden side

    # a keep-out box: a cube at its centre, turned by its rpy
    (cube,) = entities["zone:table"]["cubes"]
    assert cube["pose"]["position"] == pytest.approx({"x": 0.7, "y": 0.0, "z": 0.15})
    assert cube["size"] == pytest.approx({"x": 0.4, "y": 0.4, "z": 0.3})
    w, x, y, z = quat_from_rpy(0.0, 0.0, math.radians(30.0))
    assert cube["pose"]["orientation"] == pytest.approx({"x": x, "y": y, "z": z, "w": w})

    # a keep-in box: its twelve edges, so what is inside stays visible
    assert entities["zone:cell"]["cubes"] == []
    (edges,) = entities["zone:cell"]["lines"]
    assert edges["type"] == 2 and len(edges["points"]) == 24  # a line list: two points per edge
    ends = [[p[k] * 1000 for k in "xyz"] for p in edges["points"]]
    assert {tuple(round(abs(v)) for v in end) for end in ends} == {(1500, 1000, 1025)}  # corners about the centre
    lengths = sorted(round(math.dist(a, b)) for a, b in zip(ends[::2], ends[1::2], strict=True))
    assert lengths == [2000] * 4 + [2050] * 4 + [3000] * 4
    assert edges["pose"]["position"] == pytest.approx({"x": 0.0, "y": 0.0, "z": 0.975})


def test_the_tool_rides_on_the_flange() -> None:
    tool = _entities(_scene())["tool"]
    assert tool["frame_id"] == FLANGE_FRAME and tool["frame_locked"] is True
    centres = sorted(tuple(round(s["pose"]["position"][k] * 1000, 6) for k in "xyz") for s in tool["spheres"])
    assert centres == [(0, 0, 0), (0, 0, 120), (0, 0, 150)]  # the capsule's two ends and the tip
    assert sorted(s["size"]["x"] * 1000 for s in tool["spheres"]) == pytest.approx([20, 40, 40])
    (cylinder,) = tool["cylinders"]
    assert cylinder["pose"]["position"] == pytest.approx({"x": 0.0, "y": 0.0, "z": 0.06})
    assert cylinder["size"] == pytest.approx({"x": 0.04, "y": 0.04, "z": 0.12})
    assert _rotate(cylinder["pose"]["orientation"], [0.0, 0.0, 1.0]) == pytest.approx([0.0, 0.0, 1.0])


def _colours(scene: dict[str, Any]) -> dict[str, tuple[float, ...]]:
    out = {}
    for entity_id, e in _entities(scene).items():
        if entity_id.startswith("zone:"):
            (shape,) = e["cubes"] or e["lines"]
            out[entity_id[5:]] = tuple(shape["color"][c] for c in "rgb")
    return out


def _rgb(rgba: tuple[float, ...]) -> tuple[float, ...]:
    return tuple(rgba[:3])


@pytest.mark.parametrize(("distance", "expected"), [(250.0, GREEN), (100.0, AMBER), (60.0, AMBER), (5.0, RED),
                                                    (-3.0, RED)])
def test_the_nearest_zone_is_coloured_by_its_distance(distance: float, expected: tuple[float, ...]) -> None:
    scene = _scene((Clearance(t=1.0, distance_mm=distance, part="tip", other="table"),))
    colours = _colours(scene)
    assert colours.pop("table") == _rgb(expected)
    assert set(colours.values()) == {_rgb(GREY)}  # the others stay grey
    metadata = {m["key"]: m["value"] for m in _entities(scene)["zone:table"]["metadata"]}
    assert metadata == {"keep": "out", "distance_mm": f"{distance:.1f}", "nearest_part": "tip"}


def test_the_colour_follows_the_latest_clearance() -> None:
    table = Clearance(t=1.0, distance_mm=40.0, part="tip", other="table")
    assert _colours(_scene((table,)))["table"] == _rgb(AMBER)
    moved_on = Clearance(t=1.1, distance_mm=4.0, part="link_3", other="cell")  # keep-in: 4 mm from leaving
    assert _colours(_scene((table, moved_on))) == {"floor": _rgb(GREY), "wall": _rgb(GREY), "table": _rgb(GREY),
                                                     "cell": _rgb(RED)}
    itself = Clearance(t=1.2, distance_mm=30.0, part="link_6", other="link_2", zone=False)  # no zone nearest
    assert set(_colours(_scene((table, itself))).values()) == {_rgb(GREY)}


def test_a_new_cell_starts_grey_and_what_cannot_be_read_changes_nothing() -> None:
    scene = CellScene()
    near = msgspec.json.encode(Clearance(t=1.0, distance_mm=40.0, part="tip", other="table"))
    assert scene.update(CLEARANCE_TOPIC, near, T_NS) is None  # no cell yet: nothing to draw
    assert scene.update(CELL_TOPIC, b"{not json", T_NS) is None
    assert scene.update("/driver/joint_state", b"{}", T_NS) is None
    assert scene.update(CELL_TOPIC, msgspec.json.encode(CELL), T_NS) is not None
    assert scene.update(CLEARANCE_TOPIC, near, T_NS) is not None
    assert scene.update(CLEARANCE_TOPIC, b'{"t": 1}', T_NS) is None  # not a clearance: kept as it was
    assert scene.nearest is not None and scene.nearest.other == "table"
    again = scene.update(CELL_TOPIC, msgspec.json.encode(CELL), T_NS + 5)
    assert again is not None and set(_colours(again).values()) == {_rgb(GREY)}
