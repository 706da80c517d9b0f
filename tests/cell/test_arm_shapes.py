"""The guard models the robot, not its drawing: shapes that enclose each real arm, padding per
part, and the docs' example cells usable on every robot type."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from rob6.cell import CellError, CellModel, Guard, default_cell
from rob6.cell.arms import ArmShape, arm_shapes
from rob6.cell.file import ARM_PARTS, parse_cell
from rob6.messages import Cell
from rob6.robots import ROBOT_TYPES, ROBOTS, get_robot

GEOMETRIES = sorted({robot.geometry for robot in ROBOTS.values()})
DOCS = Path(__file__).resolve().parents[2] / "docs"

#: points of the ROS-Industrial KR 16-2 collision meshes (kuka_experimental kuka_kr16_support,
#: meshes/kr16_2/collision/*.stl), in rob6's joint frames (mm): each mesh's farthest along every axis
KR16_MESH_EXTREMES = {
    "base": [[-402, 177, 109], [282, 62, 6], [-43, 268, 35], [-101, -268, 6], [140, -165, 397], [-159, 230, 0]],
    "link_1": [[393, 21, 600], [260, -49, 846], [-237, 47, 384], [-7, -270, 397], [338, 249, 713], [-270, 0, 417],
               [-7, 270, 397]],
    "link_2": [[773, 1, -150], [-8, -110, -140], [206, 29, -277], [-8, 110, -140], [-91, 1, -83], [525, 13, -77]],
    "link_3": [[-108, 403, 28], [75, 14, 213], [-15, -356, -36], [-42, -68, -117], [115, 28, -23], [-172, -108, -2]],
    "link_4": [[0, -31, 733], [53, -56, 402], [77, 0, 463], [2, 77, 463], [2, -77, 402], [-77, 0, 402]],
    "link_5": [[-23, 39, -94], [37, 148, -5], [33, 31, 106], [60, 19, 95], [16, -59, 74], [-60, -15, 95]],
    "link_6": [[18, -26, 158], [-2, -39, 152], [-39, 0, 152], [-2, 39, 152], [17, -35, 146], [39, 0, 152]],
}
#: the KR 3 R540 collision meshes' radii about each link's axis (mm, REFERENCES.md): the smaller
#: arms' shapes are at least this wide
R540_RADII = {"link_1": 120, "link_2": 115, "link_4": 85, "link_5": 57, "link_6": 28}

#: poses every type can take (within every type's joint limits): the start, reaching out, turned
ORDINARY_POSES = [[0, 0, 0, 0, 0, 0], [-30, -40, 60, 0, -30, 0], [-60, -20, 30, 90, 45, 0]]


def _inside(shape: ArmShape, point: np.ndarray, tolerance: float = 1e-9) -> bool:
    a = np.array(shape.a)
    if shape.kind == "box":
        assert shape.size is not None
        return bool(np.all(np.abs(point - a) <= np.array(shape.size) / 2 + tolerance))
    b = a if shape.b is None else np.array(shape.b)
    ab = b - a
    t = 0.0 if not ab.any() else float(np.clip((point - a) @ ab / (ab @ ab), 0.0, 1.0))
    return bool(np.linalg.norm(point - (a + t * ab)) <= shape.radius + tolerance)


def _lowest(shape: ArmShape) -> float:
    if shape.kind == "box":
        assert shape.size is not None
        return shape.a[2] - shape.size[2] / 2
    return min(shape.a[2], (shape.b or shape.a)[2]) - shape.radius


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_every_part_has_shapes_each_with_its_source(geometry: str) -> None:
    shapes = arm_shapes(geometry)
    assert set(shapes) == set(ARM_PARTS)
    assert all(shape.source for part in shapes.values() for shape in part)


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_nothing_of_the_base_or_link_1_lies_below_the_mounting_plane(geometry: str) -> None:
    # link_1's frame is the base's turned about z (the URDF's joint_1 at the origin): its z is
    # the base's at every joint-1 angle
    assert '<origin xyz="0 0 0" rpy="0 0 0"/>\n    <axis xyz="0 0 -1"/>' in get_robot(geometry).urdf
    for part in ("base", "link_1"):
        assert min(_lowest(shape) for shape in arm_shapes(geometry)[part]) >= 0.0, part


def test_the_kr16_shapes_enclose_the_ros_industrial_collision_meshes() -> None:
    shapes = arm_shapes("kr16")
    for part, points in KR16_MESH_EXTREMES.items():
        for point in points:
            # the points are rounded to the mm
            assert any(_inside(shape, np.array(point, float), 0.9) for shape in shapes[part]), (part, point)


@pytest.mark.parametrize("geometry", ["kr3", "ad850", "kaw_fs"])
def test_the_smaller_arms_are_at_least_as_wide_as_the_kr3_r540s_housings(geometry: str) -> None:
    for part, radius in R540_RADII.items():
        assert max(shape.radius for shape in arm_shapes(geometry)[part]) >= radius, part


@pytest.mark.parametrize("geometry", GEOMETRIES)
def test_the_shapes_are_wider_than_the_drawing(geometry: str) -> None:
    """The URDF's cylinders (what the guard used before) were a fraction of the housings."""
    drawn = [float(r) for r in re.findall(r'cylinder radius="([0-9.]+)"', get_robot(geometry).urdf)]
    widest = max(shape.radius for part in arm_shapes(geometry).values() for shape in part)
    assert widest > 1000.0 * max(drawn)


# ------------------------------------------------------------------ padding per part
def _floor_cell(padding: str) -> Cell:
    return parse_cell(f"""\
zones:
  - {{name: floor, keep: out, half_space: {{point: [0, 0, 0], normal: [0, 0, 1]}}, ignore: [link_1]}}
arm:
  self_collision: false
  padding_mm: {padding}
""", "padded.yaml")


def test_padding_per_part_grows_only_the_parts_it_names() -> None:
    plain = _floor_cell("0")
    padded = _floor_cell("{link_4: 20, link_6: 30, default: 2}")
    assert padded.arm_padding_mm == 2.0 and padded.arm_padding_parts == {"link_4": 20.0, "link_6": 30.0}
    q = np.array([0.0, -30.0, 100.0, 0.0, 20.0, 0.0])
    before = dict(zip([p.part for p in CellModel(get_robot("kr16"), plain).pairs],
                      CellModel(get_robot("kr16"), plain).distances(q), strict=True))
    model = CellModel(get_robot("kr16"), padded)
    after = dict(zip([p.part for p in model.pairs], model.distances(q), strict=True))
    assert after["link_4"] == pytest.approx(before["link_4"] - 20.0, abs=1e-6)
    assert after["link_6"] == pytest.approx(before["link_6"] - 30.0, abs=1e-6)
    assert after["link_2"] == pytest.approx(before["link_2"] - 2.0, abs=1e-6)


def test_one_number_still_pads_every_part() -> None:
    cell = _floor_cell("7")
    assert cell.arm_padding_mm == 7.0 and cell.arm_padding_parts == {}


@pytest.mark.parametrize(("padding", "error"), [
    ("{link_9: 20}", "line 5: unknown key 'link_9' in padding_mm"),
    ("{link_3: -1}", "line 5: link_3 must be at least 0"),
    ("{default: many}", "line 5: default must be a number"),
])
def test_a_bad_padding_is_refused_naming_its_line(padding: str, error: str) -> None:
    with pytest.raises(CellError, match=re.escape(error)):
        _floor_cell(padding)


# ------------------------------------------------------------------ the docs' examples
def _doc_cells() -> list[tuple[str, str]]:
    cells = []
    for doc in sorted(DOCS.glob("*.md")):
        for block in re.findall(r"```yaml\n(.*?)```", doc.read_text(), re.S):
            if re.search(r"^(zones|tool|arm|margin_mm):", block, re.M):
                cells.append((doc.name, block))
    return cells


def test_the_docs_have_an_example_cell() -> None:
    assert any(name == "SAFETY_ZONES.md" for name, _ in _doc_cells())


@pytest.mark.parametrize("robot", ROBOT_TYPES)
@pytest.mark.parametrize(("doc", "text"), _doc_cells(), ids=lambda v: v if v.endswith(".md") else "")
def test_every_example_cell_of_the_docs_admits_ordinary_poses_on_every_robot_type(robot: str, doc: str,
                                                                                  text: str) -> None:
    guard = Guard(CellModel(get_robot(robot), parse_cell(text, doc)))
    for q in ORDINARY_POSES:
        stop = guard.pose(np.array(q, float))
        assert stop is None, f"{doc} on {robot} refuses {q}: {stop.describe()}"


@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_a_keep_in_just_below_the_base_admits_the_arm(robot: str) -> None:
    """The issue's case: kr16's old link_1 drum reached 167 mm below the base."""
    cell = parse_cell("""\
zones:
  - {name: cell, keep: in, box: {min: [-3000, -3000, -10], max: [3000, 3000, 3000]}}
""", "keep-in.yaml")
    assert Guard(CellModel(get_robot(robot), cell)).pose(np.zeros(6)) is None



@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_every_pose_the_original_reports_is_admitted_by_the_default_cell(robot: str) -> None:
    """The shapes are not fatter than the arm the original drove: each ``GetPositionJoints``
    answer of its transcripts is a pose it reached, and the default cell admits it."""
    guard = Guard(CellModel(get_robot(robot), default_cell(get_robot(robot))))
    transcripts = Path(__file__).resolve().parents[1] / "transcripts" / robot
    poses = set()
    for path in transcripts.glob("*.jsonl"):
        for line in path.read_text().splitlines():
            step = json.loads(line)
            if step.get("send", "").startswith("GetPositionJoints") and "reply" in step:
                numbers = step["reply"].split()
                if len(numbers) == 6 and all(re.fullmatch(r"-?[0-9.]+", n) for n in numbers):
                    poses.add(tuple(float(n) for n in numbers))
    assert poses
    refused = {q: stop.describe() for q in poses if (stop := guard.pose(np.array(q))) is not None}
    assert not refused, refused
