"""The cell's model says what it does not check: a tool shape touching the arm at q = 0 is refused, never dropped silently.

Also: a tool shape inside the wrist is warned about, GetCell's list of unmeasured pairs
names each with why, and a cell whose setpoint check cannot fit the cycle is refused at start.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rob6.cell import CellError, CellModel, Guard, load_cell
from rob6.robots import get_robot
from rob6_driver.zones import ZoneGuard

#: a 130 mm-radius gripper: at q = 0 it wraps link_5 (kr16's wrist)
WIDE = """\
tool:
  - {name: gripper, capsule: {from: [0, 0, 0], to: [0, 0, -150], radius: 130}}
"""


def _cell(tmp: Path, text: str) -> Path:
    path = tmp / "cell.yaml"
    path.write_text(text)
    return path


def test_a_wide_gripper_touching_the_wrist_at_zero_is_refused_naming_the_pair(tmp_path: Path) -> None:
    with pytest.raises(CellError, match=r"tool shape 'gripper' touches link_\d at the zero position .*"
                                        r"add \[link_\d, gripper\] to arm: allowed_pairs"):
        CellModel(get_robot("kr16"), load_cell(_cell(tmp_path, WIDE)))


def test_allowed_by_the_file_it_is_listed_as_unchecked(tmp_path: Path) -> None:
    """Only the file's word lets such a pair go unmeasured, and GetCell's list says so; the
    gripper is still measured against the rest of the arm."""
    model = CellModel(get_robot("kr16"), load_cell(_cell(tmp_path, WIDE + "arm:\n  allowed_pairs: [[link_4, gripper]]\n")))
    assert "gripper with link_4: allowed by the cell file" in model.unchecked
    assert {pair.other for pair in model.pairs if pair.part == "gripper" and not pair.zone} == {"base", "link_1", "link_2", "link_3"}
    folded = Guard(model).pose(np.array([0.0, -90.0, 90.0, 0.0, 115.0, 0.0]))
    assert folded is None  # folded into link_4, which the file allowed: the lab's word, listed above


def test_every_unmeasured_pair_of_the_default_cell_says_why(tmp_path: Path) -> None:
    model = CellModel(get_robot("kr16"), load_cell(_cell(tmp_path, "margin_mm: 5\n")))
    assert model.unchecked
    assert all(line.split(": ", 1)[1] in ("near in the chain: the joint between them keeps them apart",
                                          "touching at the zero position (the model's shapes overlap there)")
               for line in model.unchecked)
    assert "link_3 with link_1: near in the chain: the joint between them keeps them apart" in model.unchecked


def test_a_tool_inside_the_wrist_is_warned_about(tmp_path: Path) -> None:
    model = CellModel(get_robot("kr16"), load_cell(_cell(tmp_path, "tool:\n  - {name: probe, sphere: {center: [0, 0, 40], radius: 5}}\n")))
    assert model.warnings == ["tool shape 'probe' reaches z > 0 of the flange frame, inside the wrist: a tool sticks "
                              "out along -z (docs/SAFETY_ZONES.md)"]


def test_a_cell_whose_check_cannot_fit_the_cycle_is_refused_at_start(tmp_path: Path) -> None:
    cell = load_cell(_cell(tmp_path, "margin_mm: 5\n"))
    zones = ZoneGuard(get_robot("kr16rt"), cell)
    assert 0.0 < zones.worst_check_s
    with pytest.raises(CellError, match=r"one setpoint's check takes up to \d+\.\d\d ms here, more than 0\.00 ms "
                                        r"\(50% of the kr16rt's 4 ms cycle\)"):
        ZoneGuard(get_robot("kr16rt"), cell, budget_s=zones.worst_check_s / 100)
