"""PTP planning: timing against the analytic jerk-limited profile, validation, limits."""

import math
from collections.abc import Sequence

import numpy as np
import pytest

from rob6.robots import ROBOT_TYPES
from rob6.units import JERK_RAMP_S, UNIT_CYCLE_S
from rob6_driver.motion import Motion, MotionCore
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import (
    SampledTrajectory,
    TrajectoryPlanner,
    check_target,
    finite_difference_violations,
    sample_at_time,
)


def analytic_time(d: float, v: float, a: float, j: float) -> float:
    """Minimum rest-to-rest time of a jerk-limited (7-phase) profile over distance d."""
    d = abs(d)
    if v * j >= a * a:  # the acceleration limit can be reached before the speed limit
        if d >= v * (v / a + a / j):
            return d / v + v / a + a / j  # reaches a and v (cruise)
    elif d >= 2 * v * math.sqrt(v / j):
        return d / v + 2 * math.sqrt(v / j)  # reaches v, not a
    # no cruise
    tau = (d / (2 * j)) ** (1 / 3)
    if j * tau <= a:
        return float(4 * tau)  # reaches neither
    vp = (-a / j + math.sqrt((a / j) ** 2 + 4 * d / a)) * a / 2  # reaches a, not v
    return 2 * (vp / a + a / j)


def run_ptp_in_sim(robot: str, q1: Sequence[float], config: MotionSettings | None = None
                   ) -> tuple[MotionCore, Motion, int, SampledTrajectory]:
    config = config or MotionSettings(robot)
    planner = TrajectoryPlanner(robot)
    sim = MotionCore(robot)
    res = planner.plan_ptp(sim.state().q, q1, config)
    assert res.ok, res.reason
    tr = res.trajectory
    assert tr is not None
    motion = sim.execute(tr.q, tr.dt, tr.qd, tr.qdd)
    cycles = 0
    while not motion.done.is_set():
        sim.step()
        cycles += 1
        assert cycles < 100000
    return sim, motion, cycles, tr


def test_30deg_a1_kr16_takes_the_analytic_time() -> None:
    c = MotionSettings("kr16")
    v = c.speed[0] / UNIT_CYCLE_S  # 15.6 deg/s
    a = c.accel[0] / UNIT_CYCLE_S**2  # 34.72 deg/s^2
    j = a / JERK_RAMP_S
    expected = analytic_time(30.0, v, a, j)
    assert expected == pytest.approx(30 / 15.6 + 15.6 / a + JERK_RAMP_S)  # ~2.4204 s
    sim, motion, cycles, tr = run_ptp_in_sim("kr16", [30, 0, 0, 0, 0, 0], c)
    assert motion.ok
    dt = sim.dt
    assert abs(cycles * dt - expected) <= 2 * dt, (cycles * dt, expected)
    assert np.allclose(sim.state().q, [30, 0, 0, 0, 0, 0], atol=1e-12)
    # and it really used the limits: peak speed and acceleration reached
    assert np.abs(tr.qd[:, 0]).max() == pytest.approx(v, rel=1e-9)
    assert np.abs(tr.qdd[:, 0]).max() == pytest.approx(a, rel=1e-9)
    assert sim.violation_count == 0


@pytest.mark.parametrize("d", [0.01, 0.3, 1.0, 2.0, 5.0, 30.0, 120.0])
@pytest.mark.parametrize("robot", ["kr16", "kr3rt", "ad850"])
def test_single_axis_duration_matches_analytic(robot: str, d: float) -> None:
    c = MotionSettings(robot)
    p = TrajectoryPlanner(robot)
    for joint in (0, 5):
        q1 = np.zeros(6)
        q1[joint] = d
        res = p.plan_ptp(np.zeros(6), q1, c)
        assert res.ok and res.trajectory is not None
        v = c.speed[joint] / UNIT_CYCLE_S
        a = c.accel[joint] / UNIT_CYCLE_S**2
        T = analytic_time(d, v, a, a / JERK_RAMP_S)
        dur = res.trajectory.duration
        assert T - 1e-9 <= dur <= T + p.dt + 1e-9  # rounded up to whole cycles


def test_sampling_matches_ruckig_and_respects_limits() -> None:
    rng = np.random.default_rng(3)
    for robot in ROBOT_TYPES:
        c = MotionSettings(robot)
        p = TrajectoryPlanner(robot)
        lim = p.limits(c)
        lo, hi = np.array(c.turn_min) * 0.9, np.array(c.turn_max) * 0.9
        for _ in range(20):
            q0, q1 = rng.uniform(lo, hi), rng.uniform(lo, hi)
            res = p.plan_ptp(q0, q1, c)
            assert res.ok, res.reason
            tr = res.trajectory
            assert tr is not None
            q, qd, qdd = sample_at_time(p._traj, tr.t)
            assert np.abs(q - tr.q).max() < 1e-9
            assert np.abs(qd - tr.qd).max() < 1e-9
            assert np.abs(tr.q[0] - q0).max() < 1e-12 and np.abs(tr.q[-1] - q1).max() == 0
            assert np.all(np.abs(tr.qd) <= lim.vmax * (1 + 1e-9) + 1e-12)
            assert np.all(np.abs(tr.qdd) <= lim.amax * (1 + 1e-9) + 1e-12)
            assert finite_difference_violations(np.vstack([tr.q, tr.q[-1:]]), tr.dt,
                                                lim.vmax, lim.amax) == []
            # time-synchronised: every moving axis is still moving until the end
            moving = np.abs(q1 - q0) > 1e-6
            assert np.all(np.abs(tr.q[-2, moving] - q1[moving]) > 0)


def test_target_validation() -> None:
    c = MotionSettings("kr16")
    p = TrajectoryPlanner("kr16")
    zero = np.zeros(6)
    # strict turn limits: J2 max is 20 -> exactly 20 is refused
    assert "turn limits" in p.plan_ptp(zero, [0, 20, 0, 0, 0, 0], c).reason
    assert p.plan_ptp(zero, [0, 19.999, 0, 0, 0, 0], c).ok
    assert not p.plan_ptp(zero, [-185, 0, 0, 0, 0, 0], c).ok
    # max change inclusive
    c.set_max_change([10] * 6)
    assert p.plan_ptp(zero, [10, 0, 0, 0, 0, 0], c).ok
    assert "max change" in p.plan_ptp(zero, [10.5, 0, 0, 0, 0, 0], c).reason
    assert check_target(zero, [0, 0, 0, 0, 0, -10], c) == ""
    # limits stored unchecked: max < min refuses everything
    c.reset_max_change()
    c.set_turn_max([-10] * 6)
    assert p.plan_ptp(zero, [-20] * 6, c).ok
    c.set_turn_min([0] * 6)  # max < min: nothing is strictly inside
    assert not p.plan_ptp(zero, [-5] * 6, c).ok
    c.reset_turn()
    # a joint with zero speed cannot move; others can
    c.set_single_speed(3, 0)
    assert "cannot move" in p.plan_ptp(zero, [0, 0, 5, 0, 0, 0], c).reason
    assert p.plan_ptp(zero, [5, 0, 0, 0, 0, 0], c).ok
    # no motion
    res = p.plan_ptp(zero, zero, c)
    assert res.ok and res.trajectory is not None and res.trajectory.n == 1


def test_from_outside_changed_turn_limits_back_inside() -> None:
    """Limits narrowed while the robot is outside: a move back inside is allowed."""
    c = MotionSettings("kr16")
    p = TrajectoryPlanner("kr16")
    c.set_single_turn_max(1, 10)
    res = p.plan_ptp([30, 0, 0, 0, 0, 0], [5, 0, 0, 0, 0, 0], c)
    assert res.ok


def test_lower_limits_take_longer() -> None:
    c = MotionSettings("kr16")
    p = TrajectoryPlanner("kr16")
    t_default = p.ptp_duration(np.zeros(6), [30, 0, 0, 0, 0, 0], c)
    c.set_speed([0.0936] * 6)  # half speed
    t_half = p.ptp_duration(np.zeros(6), [30, 0, 0, 0, 0, 0], c)
    assert t_half > 1.7 * t_default


def test_allowed_status_and_pattern() -> None:
    c = MotionSettings("kr16")
    p = TrajectoryPlanner("kr16")
    zero = np.zeros(6)  # noflip up lefty
    down = [0, -10, -20, 0, 10, 0]  # kr16: up <=> q3 > -2.99 deg -> down
    assert c.robot.status(tuple(down)) == ("noflip", "down", "lefty")
    assert p.plan_ptp(zero, down, c).ok
    c.set_allowed(["noflip", "up", "lefty"])
    assert "allowed status" in p.plan_ptp(zero, down, c).reason
    c.set_allowed(["noToggleElbow"])
    assert not p.plan_ptp(zero, down, c).ok
    assert p.plan_ptp(zero, [0, -10, 20, 0, 10, 0], c).ok
    c.reset_allowed()
    assert not p.plan_ptp(zero, down, c, pattern=["flip", "toggleElbow", "toggleArm"]).ok
    assert p.plan_ptp(zero, down, c, pattern=["noflip", "down", "noToggleArm"]).ok
