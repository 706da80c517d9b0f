"""Cell files: every value checked at start-up, every error naming its line; the shipped default."""

from __future__ import annotations

from pathlib import Path

import pytest

from rob6.cell import CellError, default_cell, load_cell
from rob6.cell.file import parse_cell
from rob6.robots import ROBOTS

FULL = """\
margin_mm: 8
zones:
  - name: table
    keep: out
    half_space: {point: [0, 0, 120], normal: [0, 0, 2]}
  - name: fixture
    keep: out
    box: {min: [500, -100, 120], max: [700, 100, 300], rpy_deg: [0, 0, 30]}
    ignore: [tool tip]
  - name: cell
    keep: in
    box: {min: [-1500, -1500, -100], max: [1500, 1500, 2500]}
tool:
  - {name: gripper, capsule: {from: [0, 0, 0], to: [0, 0, -120], radius: 40}}
  - {name: tool tip, sphere: {center: [0, 0, -150], radius: 10}}
arm:
  self_collision: false
  padding_mm: 10
  allowed_pairs: [[link_2, gripper]]
"""


def test_a_full_cell_is_read_with_every_value() -> None:
    cell = parse_cell(FULL, "lab.yaml")
    assert cell.source == "lab.yaml" and cell.from_file and cell.margin_mm == 8.0
    table, fixture, room = cell.zones
    assert table.keep == "out" and table.half_space is not None
    assert table.half_space.normal == [0.0, 0.0, 1.0] and table.half_space.point == [0.0, 0.0, 120.0]
    assert fixture.box is not None and fixture.box.rpy_deg == [0.0, 0.0, 30.0] and fixture.ignore == ["tool tip"]
    assert room.keep == "in" and room.box is not None and room.box.rpy_deg == [0.0, 0.0, 0.0]
    gripper, tip = cell.tool
    assert gripper.b == [0.0, 0.0, -120.0] and gripper.radius == 40.0
    assert tip.b is None and tip.a == [0.0, 0.0, -150.0]
    assert not cell.self_collision and cell.arm_padding_mm == 10.0 and cell.allowed_pairs == [["link_2", "gripper"]]


@pytest.mark.parametrize(("text", "error"), [
    ("margin_mm: -1\n", "line 1: margin_mm must be at least 0, not -1"),
    ("margin_mm: 5\nzonez: []\n", "line 2: unknown key 'zonez' in the file (expected margin_mm, zones, tool, arm)"),
    ("zones:\n  - name: t\n    keep: out\n    half_space: {point: [0, 0], normal: [0, 0, 1]}\n",
     "line 4: point must be three numbers, not [0, 0]"),
    ("zones:\n  - name: t\n    keep: sideways\n    box: {min: [0, 0, 0], max: [1, 1, 1]}\n",
     "line 3: zone 't': keep must be out or in, not 'sideways'"),
    ("zones:\n  - name: t\n    keep: out\n    box: {min: [0, 0, 0], max: [1, 0, 1]}\n",
     "line 4: zone 't': max must be above min on every axis"),
    ("zones:\n  - name: t\n    keep: in\n    half_space: {point: [0, 0, 0], normal: [0, 0, 1]}\n",
     "line 4: zone 't': a keep-in zone must be a box"),
    ("zones:\n  - name: t\n    keep: out\n    half_space: {point: [0, 0, 0], normal: [0, 0, 0]}\n",
     "line 4: zone 't': the normal is zero"),
    ("zones:\n  - name: t\n    keep: out\n", "line 2: zone 't' needs exactly one shape: half_space or box"),
    ("zones:\n  - keep: out\n    box: {min: [0, 0, 0], max: [1, 1, 1]}\n", "line 2: every zone needs a name"),
    ("zones:\n  - name: t\n    keep: out\n    box: {min: [0, 0, 0], max: [1, 1, 1]}\n    ignore: [link_9]\n",
     "line 5: zone 't': ignore: no part is called 'link_9'"),
    ("zones:\n  - {name: t, keep: out, box: {min: [0, 0, 0], max: [1, 1, 1]}}\n"
     "  - {name: t, keep: out, box: {min: [0, 0, 0], max: [1, 1, 1]}}\n", "line 3: zone name 't' is taken by another zone"),
    ("tool:\n  - {name: link_2, sphere: {center: [0, 0, 0], radius: 1}}\n", "line 2: tool shape name 'link_2' is taken by a part of the arm"),
    ("tool:\n  - {name: tip, sphere: {center: [0, 0, 0], radius: 0}}\n", "radius must be above 0, not 0"),
    ("tool:\n  - {name: tip, cube: {}}\n", "line 2: unknown key 'cube' in a tool shape"),
    ("arm: {self_collision: yes please}\n", "line 1: self_collision must be true or false, not 'yes please'"),
    ("arm:\n  allowed_pairs: [[link_2, link_2]]\n", "line 2: an allowed pair names two different parts"),
    ("zones: [\n", "line 2: not YAML"),
])
def test_a_bad_value_is_refused_naming_its_line(text: str, error: str) -> None:
    with pytest.raises(CellError) as refused:
        parse_cell(text, "lab.yaml")
    assert str(refused.value).startswith("cell file lab.yaml")
    assert error in str(refused.value), str(refused.value)


def test_a_missing_file_says_so(tmp_path: Path) -> None:
    with pytest.raises(CellError, match=r"cell file .*nothing\.yaml: cannot be read"):
        load_cell(tmp_path / "nothing.yaml")


@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_every_robot_type_ships_a_default_the_floor_and_self_collision(robot: str) -> None:
    cell = default_cell(ROBOTS[robot])
    assert cell.source == f"default {robot}" and not cell.from_file and cell.self_collision and cell.margin_mm == 5.0
    (floor,) = cell.zones
    assert floor.half_space is not None and floor.half_space.normal == [0.0, 0.0, 1.0] and floor.keep == "out"
