"""LIN planning: straight line, limits, rejection before motion (singularity, reach, config)."""

from collections.abc import Sequence

import numpy as np
import pytest

from rob6.robots import RobotModel, get_robot
from rob6_driver.motion import MotionCore
from rob6_planner.config import MotionSettings
from rob6_planner.lin_planner import IkFn, LinOptions, plan_lin
from rob6_planner.trajectory import SampledTrajectory, TrajectoryPlanner, finite_difference_violations
from tests.motion.motion_kin import fk, make_ik


def rot_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def setup(robot: str = "kr16", q0: Sequence[float] = (10, -80, 100, 20, 40, 30)
          ) -> tuple[RobotModel, MotionSettings, TrajectoryPlanner, np.ndarray, np.ndarray, IkFn]:
    r = get_robot(robot)
    start = np.array(q0, float)
    return r, MotionSettings(r), TrajectoryPlanner(r), start, fk(r, start)[0], make_ik(r, start)


def line_deviation(r: RobotModel, tr: SampledTrajectory, T0: np.ndarray, T1: np.ndarray) -> tuple[float, np.ndarray]:
    P = fk(r, tr.q)[:, :, 3]
    u = (T1[:, 3] - T0[:, 3]) / np.linalg.norm(T1[:, 3] - T0[:, 3])
    d = P - T0[:, 3]
    along = d @ u
    return np.linalg.norm(d - np.outer(along, u), axis=1).max(), along


def test_lin_is_straight_and_within_limits() -> None:
    r, c, p, q0, T0, ik = setup()
    T1 = T0.copy()
    T1[:, 3] += [200, 150, -100]
    T1[:, :3] = rot_z(20) @ T0[:, :3]
    res = plan_lin(p, q0, T0, T1, c, ik)
    assert res.ok, res.reason
    tr = res.trajectory
    assert tr is not None
    dev, along = line_deviation(r, tr, T0, T1)
    assert dev < 1e-6  # mm
    assert np.all(np.diff(along) >= -1e-9)  # monotone progress, no back-tracking
    assert np.abs(fk(r, tr.q[-1])[0] - T1).max() < 1e-6
    lim = p.limits(c)
    assert finite_difference_violations(np.vstack([tr.q, tr.q[-1:]]), tr.dt, lim.vmax, lim.amax) == []
    # the sim accepts and executes it without a violation
    sim = MotionCore(r, q0=q0)
    m = sim.execute(tr.q, tr.dt, tr.qd, tr.qdd)
    sim.run_until_idle()
    assert m.ok and sim.violation_count == 0
    # orientation follows the slerp: the rotation angle about z grows monotonically
    R = fk(r, tr.q)[:, :, :3]
    rel = R @ T0[:, :3].T  # rotation in the base frame: Rz(angle)
    angle = np.degrees(np.arctan2(rel[:, 1, 0], rel[:, 0, 0]))
    assert angle[0] == pytest.approx(0, abs=1e-6) and angle[-1] == pytest.approx(20, abs=1e-6)
    assert np.all(np.diff(angle) >= -1e-9)
    assert np.abs(rel[:, 2, 2] - 1).max() < 1e-9  # about z only: no wobble


def test_lin_speed_is_limited_by_the_slowest_joint() -> None:
    r, c, p, q0, T0, ik = setup()
    T1 = T0.copy()
    T1[:, 3] += [0, 300, 0]
    fast = plan_lin(p, q0, T0, T1, c, ik)
    c.set_speed([x / 4 for x in c.speed])
    slow = plan_lin(p, q0, T0, T1, c, ik)
    assert fast.ok and slow.ok
    assert fast.trajectory is not None and slow.trajectory is not None
    assert slow.trajectory.duration > 2.5 * fast.trajectory.duration
    lim = p.limits(c)
    peak = np.abs(np.diff(slow.trajectory.q, axis=0)).max(axis=0) / slow.trajectory.dt
    assert (peak / lim.vmax).max() > 0.8  # uses most of the allowed speed


def test_lin_through_the_wrist_singularity_is_rejected() -> None:
    # constant orientation, the arm moves so that q5 must pass through 0
    r, c, p, qa, Ta, ik = setup(q0=(0, -90, 90, 0, 10, 0))
    Tb = fk(r, [0, -90, 110, 0, -10, 0])[0]
    Tb[:, :3] = Ta[:, :3]
    res = plan_lin(p, qa, Ta, Tb, c, ik)
    assert not res.ok and res.trajectory is None
    assert "wrist singularity" in res.reason


def test_lin_rejections() -> None:
    r, c, p, q0, T0, ik = setup()
    far = T0.copy()
    far[:, 3] += [3000, 0, 0]
    res = plan_lin(p, q0, T0, far, c, ik)
    assert not res.ok and "unreachable" in res.reason
    # a turn limit on the way (J1 goes from 10 towards ~30 deg)
    T1 = T0.copy()
    T1[:, 3] += [0, -400, 0]
    assert plan_lin(p, q0, T0, T1, c, ik).ok
    c.set_single_turn_min(1, 0.0)
    c.set_single_turn_max(1, 12.0)
    res = plan_lin(p, q0, T0, T1, c, ik)
    assert not res.ok and "turn limits" in res.reason, res.reason
    c.reset_turn()
    c.set_max_change([5] * 6)
    res = plan_lin(p, q0, T0, T1, c, ik)
    assert not res.ok and "max change" in res.reason
    c.reset_max_change()
    # a manipulability callable with a threshold everything fails
    res = plan_lin(p, q0, T0, T1, c, ik, manip_fn=lambda Q: np.zeros(len(Q)),
                   options=LinOptions(manip_min=0.1))
    assert not res.ok and "manipulability" in res.reason
    # no motion
    res = plan_lin(p, q0, T0, T0, c, ik)
    assert res.ok and res.trajectory is not None and res.trajectory.n == 1


def test_lin_start_must_match_the_current_joints() -> None:
    r, c, p, q0, T0, ik = setup()
    T1 = T0.copy()
    T1[:, 3] += [50, 0, 0]
    res = plan_lin(p, q0 + [0, 0, 0, 0, 0, 1.0], T0, T1, c, ik)
    assert not res.ok and "start pose" in res.reason
