"""An arm already within a zone's margin can always be moved out: away and slowly, never deeper.

The arm starts with the tool tip 2 mm above the table (the margin is 5 mm), as after a jog on
the pendant, a controller's stop that overshot, or a zone added to the cell file. Heights
come from the closed-form kinematics (``zone_rig``), not from the guard's model.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rob6.cell import CellModel, Guard, load_cell
from rob6.cell.guard import ESCAPE_DIP_MM, ESCAPE_SPEED_MM_S
from rob6.robots import get_robot
from rob6_driver.motion import MotionCore
from rob6_driver.zones import ZoneGuard
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import JointLimits, SampledTrajectory, TrajectoryPlanner
from tests.cell.zone_rig import HOVER_S, Rig, rig

ROBOTS = ("kr16", "kr3", "ad850", "kaw_fs")
INSIDE_MM = 2.0  # the tip's height above the table at the start: within the 5 mm margin


def _plan(robot: str, start: list[float], end: list[float], share: float = 1.0) -> tuple[SampledTrajectory, JointLimits]:
    config = MotionSettings(robot)
    limits = JointLimits.from_config(config)
    config.speed = [v * share for v in config.speed]
    plan = TrajectoryPlanner(robot).plan_ptp(start, end, config)
    assert plan.ok and plan.trajectory is not None
    return plan.trajectory, limits


def _setup(robot: str, tmp: Path) -> tuple[Rig, Path, list[float]]:
    r = rig(robot)
    return r, r.write(tmp), r.q(r.s_at(INSIDE_MM))


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_ptp_away_from_the_table_runs_slowly_and_one_deeper_is_refused(robot: str, tmp_path: Path) -> None:
    r, cell, start = _setup(robot, tmp_path)
    guard = Guard(CellModel(get_robot(robot), load_cell(cell)))
    up, deeper = r.q(HOVER_S), r.q(r.s_at(0.5))
    # at the configured speed the way out is too fast; the planner plans it at the share the guard gives
    fast, limits = _plan(robot, start, up)
    refusal = guard.path(fast.q, fast.qd, fast.qdd, fast.dt, limits.vmax, limits.amax, limits.jmax)
    assert refusal is not None and f"it may leave at {ESCAPE_SPEED_MM_S:g} mm/s at most" in refusal.message()
    share = guard.escape_share(np.array(start), limits.vmax)
    assert 0.0 < share < 1.0
    slow, _ = _plan(robot, start, up, share)
    assert guard.path(slow.q, slow.qd, slow.qdd, slow.dt, limits.vmax, limits.amax, limits.jmax) is None
    # deeper is refused, however slowly, and the refusal says how to get out
    down, _ = _plan(robot, start, deeper, share)
    refusal = guard.path(down.q, down.qd, down.qdd, down.dt, limits.vmax, limits.amax, limits.jmax)
    assert refusal is not None
    assert "tool tip" in refusal.message() and "it may only move away from it" in refusal.message()
    # the driver runs the way out to its end; the tip never goes deeper than it started
    core = MotionCore(robot, q0=start, zones=ZoneGuard(get_robot(robot), load_cell(cell)))
    motion = core.execute(slow.q, core.dt, slow.qd, slow.qdd)
    states = np.array([s.q for s in core.run(len(slow.q) + 5)])
    assert motion.done.is_set() and motion.ok, motion.reason
    clearance = r.tip_clearance(states)
    assert clearance.min() >= INSIDE_MM - ESCAPE_DIP_MM - 0.05
    assert clearance[-1] > 50.0
    # ... and refuses the deeper one up front
    core = MotionCore(robot, q0=start, zones=ZoneGuard(get_robot(robot), load_cell(cell)))
    motion = core.execute(down.q, core.dt, down.qd, down.qdd)
    assert motion.done.is_set() and not motion.ok and "may only move away" in motion.reason
    assert core.state().q.tolist() == start


@pytest.mark.parametrize("robot", ROBOTS)
def test_an_alter_stream_may_lead_the_arm_out_never_further_in(robot: str, tmp_path: Path) -> None:
    r, cell, start = _setup(robot, tmp_path)
    zones = ZoneGuard(get_robot(robot), load_cell(cell))
    core = MotionCore(robot, q0=start, zones=zones)
    core.online(start)  # the link reports the arm here: the driver says where it is
    assert zones.escaping
    assert core.enable_alter(synchronized=True)[0]
    ok, why = core.set_target(r.q(r.s_at(0.5)))
    assert not ok and "tool tip" in why and "to get out, move tool tip away from keep-out 'table'" in why
    # the refusal stays, with the same reason, while the target does
    assert core.set_target(r.q(r.s_at(0.5))) == (False, why)
    up = np.array(r.q(HOVER_S))
    states = []
    for k in range(1, int(6.0 / core.dt)):
        f = min(1.0, k * core.dt / 2.0)
        ok, why = core.set_target((np.array(start) + f * (up - np.array(start))).tolist())
        assert ok, why
        states.append(core.step().q)
    clearance = r.tip_clearance(np.array(states))
    assert clearance.min() >= INSIDE_MM - ESCAPE_DIP_MM - 0.05
    assert np.abs(states[-1] - up).max() < 1e-6  # out and at the target
    assert not zones.escaping  # out of the margin: the normal rule again
    speeds = np.abs(np.diff(clearance)) / core.dt
    assert speeds.max() <= ESCAPE_SPEED_MM_S * 1.01  # the tip rose no faster than a way out may


@pytest.mark.parametrize("robot", ("kr16", "kaw_fs"))
def test_a_driver_started_within_the_margin_says_where_in_one_line(robot: str, tmp_path: Path,
                                                                    caplog: pytest.LogCaptureFixture) -> None:
    _, cell, start = _setup(robot, tmp_path)
    zones = ZoneGuard(get_robot(robot), load_cell(cell))
    where = zones.observe(np.array(start))
    assert where.startswith("tool tip 2 mm from keep-out 'table', within the 5 mm margin")
    assert where.endswith(f"it may only move away from it, at {ESCAPE_SPEED_MM_S:g} mm/s at most")


def test_a_zone_that_asks_for_more_room_gets_it(tmp_path: Path) -> None:
    """A zone's own ``margin_mm`` (a controller's stopping distance) is the room kept from it."""
    r = rig("kr16")
    text = r.cell_yaml().replace("    keep: out\n", "    keep: out\n    margin_mm: 40\n", 1)
    path = tmp_path / "cell.yaml"
    path.write_text(text)
    guard = Guard(CellModel(get_robot("kr16"), load_cell(path)))
    assert guard.pose(np.array(r.q(r.s_at(45.0)))) is None
    stop = guard.pose(np.array(r.q(r.s_at(30.0))))
    assert stop is not None and stop.describe().startswith("tool tip 30 mm from keep-out 'table', within the 40 mm margin")
