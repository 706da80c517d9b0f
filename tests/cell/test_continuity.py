"""Nothing passes a zone between two samples: a 5 mm pin swung across an 8 mm sheet at the protocol's speed bound.

The sheet stands where the pin's tip crosses the widest gap between two samples of a PTP
planned at the speed bound, so every sample keeps the margin and only the way between them
goes through it. Where the tip is comes from rob6's closed-form kinematics
(``rob6_kinematics.opw``), not from the guard's Pinocchio model.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rob6.cell import CellModel, Guard, load_cell
from rob6.robots import get_robot
from rob6_driver.motion import MotionCore
from rob6_driver.zones import ZoneGuard
from rob6_kinematics.opw import Geometry, fk
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import JointLimits, SampledTrajectory, TrajectoryPlanner

ROBOTS = ("kr16", "kr16rt", "kr3", "ad850", "kaw_fs")
#: no margin (a file may say so): nothing but continuity keeps the pin out
PIN_MM, PIN_RADIUS_MM, SHEET_MM, MARGIN_MM = 250.0, 2.5, 8.0, 0.0


def _tips(robot: str, q: np.ndarray) -> np.ndarray:
    T = fk(Geometry.of(get_robot(robot)), np.asarray(q, float).reshape(-1, 6))
    tips: np.ndarray = T[:, :3, 3] - PIN_MM * T[:, :3, 2]  # along the flange's -z: out of it
    return tips


def _swing(robot: str) -> tuple[SampledTrajectory, MotionSettings]:
    """A joint-1 swing of the outstretched arm, at the protocol's speed and acceleration bounds."""
    config = MotionSettings(robot)
    config.speed = list(config.speed_bound)
    config.accel = [config.robot.max_accel_bound] * 6
    start, end = [-150.0, -20.0, 30.0, 0.0, 80.0, 0.0], [150.0, -20.0, 30.0, 0.0, 80.0, 0.0]
    plan = TrajectoryPlanner(robot).plan_ptp(start, end, config)
    assert plan.ok and plan.trajectory is not None
    return plan.trajectory, config


def _gap(tips: np.ndarray, centre: np.ndarray, normal: np.ndarray) -> float:
    """How far (mm) the pin's tip sphere keeps from the sheet at the least, over the tips (N, 3)
    beside the sheet's face (its centre within 100 mm across and its height)."""
    across = np.cross([0.0, 0.0, 1.0], normal)
    offset = tips - centre
    beside = (np.abs(offset @ across) <= 100.0) & (offset[:, 2] >= -60.0) & (offset[:, 2] <= 40.0)
    gaps = np.abs(offset[beside] @ normal) - SHEET_MM / 2 - PIN_RADIUS_MM
    return float(gaps.min()) if len(gaps) else math.inf


def _sheet(robot: str, q: np.ndarray, tmp: Path) -> tuple[Path, np.ndarray, np.ndarray, float]:
    """A cell with the sheet across the widest step of the tip: (file, its centre, its
    normal, the step in mm)."""
    tips = _tips(robot, q)
    steps = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    k = int(np.argmax(steps))
    centre, normal = (tips[k] + tips[k + 1]) / 2, (tips[k + 1] - tips[k]) / steps[k]
    yaw = math.degrees(math.atan2(normal[1], normal[0]))
    low, high = centre + [-SHEET_MM / 2, -100.0, -60.0], centre + [SHEET_MM / 2, 100.0, 40.0]
    path = tmp / "sheet.yaml"
    path.write_text(f"""\
margin_mm: {MARGIN_MM}
zones:
  - name: sheet
    keep: out
    box: {{min: [{low[0]:.3f}, {low[1]:.3f}, {low[2]:.3f}], max: [{high[0]:.3f}, {high[1]:.3f}, {high[2]:.3f}], rpy_deg: [0, 0, {yaw:.6f}]}}
tool:
  - {{name: pin, capsule: {{from: [0, 0, {-PIN_MM + 30:.1f}], to: [0, 0, {-PIN_MM:.1f}], radius: {PIN_RADIUS_MM}}}}}
arm:
  self_collision: false
""")
    return path, centre, normal, float(steps[k])


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_pin_swung_across_a_thin_sheet_at_the_speed_bound_is_refused(robot: str, tmp_path: Path) -> None:
    trajectory, config = _swing(robot)
    path, centre, normal, step = _sheet(robot, trajectory.q, tmp_path)
    # every sample keeps the margin: only the way between two goes through the sheet
    assert _gap(_tips(robot, trajectory.q), centre, normal) > MARGIN_MM
    print(f"{robot}: the tip moves up to {step:.1f} mm per {get_robot(robot).cycle_s * 1000:g} ms cycle")
    guard = Guard(CellModel(get_robot(robot), load_cell(path)))
    limits = JointLimits.from_config(config)
    refusal = guard.path(trajectory.q, trajectory.qd, trajectory.qdd, trajectory.dt, limits.vmax, limits.amax,
                         limits.jmax)
    assert refusal is not None
    assert refusal.message().startswith(("path enters keep-out 'sheet'", "path comes within the 0 mm margin of keep-out 'sheet'"))
    # the driver does not rely on the planner: its own check of the poses refuses it too
    core = MotionCore(robot, q0=trajectory.q[0], zones=ZoneGuard(get_robot(robot), load_cell(path)))
    core.set_limits(max_speed=config.speed, max_accel=config.accel)
    motion = core.execute(trajectory.q, core.dt, trajectory.qd, trajectory.qdd)
    assert motion.done.is_set() and not motion.ok
    assert motion.reason.startswith("trajectory refused: at ") and "'sheet'" in motion.reason
    assert core.state().q.tolist() == trajectory.q[0].tolist()


@pytest.mark.parametrize("robot", ROBOTS)
def test_the_same_swing_streamed_in_alter_stops_before_the_sheet(robot: str, tmp_path: Path) -> None:
    trajectory, config = _swing(robot)
    path, centre, normal, _ = _sheet(robot, trajectory.q, tmp_path)
    core = MotionCore(robot, q0=trajectory.q[0], zones=ZoneGuard(get_robot(robot), load_cell(path)))
    core.set_limits(max_speed=config.speed, max_accel=config.accel)
    assert core.enable_alter(synchronized=True)[0]
    states = []
    for row in [*trajectory.q, *[trajectory.q[-1]] * int(2.0 / core.dt)]:
        core.set_target(row.tolist())
        states.append(core.step().q)
    tips = _tips(robot, np.array(states))
    assert _gap(tips, centre, normal) > 0.0  # never in the sheet
    assert np.abs(states[-1] - trajectory.q[-1]).max() > 1.0  # it stopped short of the end, before the sheet
    assert not core.state().moving


@pytest.mark.parametrize("robot", ("kr16", "ad850"))
def test_a_stop_on_a_straight_ptp_stays_on_its_line(robot: str) -> None:
    """The driver's stop on a point-to-point move runs along the move's line (the poses the
    cell checked), whatever joint limits bind: no joint braked on its own."""
    config = MotionSettings(robot)
    config.speed = list(config.speed_bound)
    start, end = np.array([-60.0, -80.0, 100.0, -90.0, 40.0, 170.0]), np.array([60.0, -40.0, 80.0, 90.0, 80.0, -170.0])
    plan = TrajectoryPlanner(robot).plan_ptp(start, end, config)
    assert plan.ok and plan.trajectory is not None
    core = MotionCore(robot, q0=start, zones=ZoneGuard(get_robot(robot), load_cell(_floor_only())))
    core.set_limits(max_speed=config.speed)
    t = plan.trajectory
    motion = core.execute(t.q, core.dt, t.qd, t.qdd)
    core.run(len(t.q) // 3)
    stop = core.stop("client gone")
    states = np.array([s.q for s in core.run(int(3.0 / core.dt))])
    assert stop.done.is_set() and motion.done.is_set() and not motion.ok
    unit = (end - start) / np.linalg.norm(end - start)
    offsets = states - start
    off_line = np.abs(offsets - (offsets @ unit)[:, None] * unit).max()
    assert off_line < 1e-6, f"the stop left the line by {off_line} deg"


def _floor_only() -> Path:
    from rob6.cell.file import DEFAULT_FILE
    return DEFAULT_FILE
