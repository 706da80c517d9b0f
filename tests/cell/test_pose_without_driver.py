"""IsPossible needs no driver: before the driver's cell is known, the planner asks the cell it was started with."""

from __future__ import annotations

from pathlib import Path

import pytest

from harness.system import zenoh_router
from rob6.bus import Bus
from rob6.robots import get_robot
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import JointLimits
from rob6_planner.zones import CellUnknown, PathCheck
from tests.cell.zone_rig import rig


def test_the_default_cell_answers_as_the_original_without_a_driver() -> None:
    with zenoh_router("pose-no-driver") as settings:
        bus = Bus(settings, "planner")
        try:
            check = PathCheck(bus, get_robot("kr16"))
            assert check.pose([0.0, 30.0, 60.0, 0.0, 90.0, 0.0]) == ""  # below the floor: the original said true
            with pytest.raises(CellUnknown):  # a path still needs the driver's own cell
                check.escape_share([0.0] * 6, JointLimits.from_config(MotionSettings("kr16")))
        finally:
            bus.close()


def test_a_lab_cell_the_planner_was_started_with_answers_without_a_driver(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    r = rig("kr16")
    monkeypatch.setenv("ROB6_CELL", str(r.write(tmp_path)))
    with zenoh_router("pose-no-driver-lab") as settings:
        bus = Bus(settings, "planner")
        try:
            check = PathCheck(bus, get_robot("kr16"))
            assert check.pose(r.q(r.s_at(50.0))) == ""
            assert check.pose(r.q(r.s_at(-20.0))).startswith("pose in the cell's way: tool tip 20 mm inside keep-out 'table'")
        finally:
            bus.close()
