"""The motion core's time scaling (``MotionCore.set_feed``), fast-forward: a trajectory run
at a changing pace stays on the path the limit monitor checked (for a LIN move: on the
line) and within every limit, and takes as much longer as it was held back; Alter plans
slower; a stop brakes from the speed the setpoints actually have."""

from __future__ import annotations

import numpy as np
import pytest

from rob6.robots import get_robot
from rob6_driver.motion import MotionCore
from rob6_planner.config import MotionSettings
from rob6_planner.lin_planner import plan_lin
from rob6_planner.trajectory import TrajectoryPlanner
from tests.motion.motion_kin import fk, make_ik

ROBOT = get_robot("ad850")
#: the link's pattern of paces: full, slowed hard, halted, back up (as acknowledgements come and go)
FEEDS = (1.0, 0.3, 0.0, 0.05, 0.8, 0.2, 1.0)


def on_path(samples: np.ndarray, q: np.ndarray) -> bool:
    """``q`` lies on the sampled path: on the straight piece between two successive samples."""
    a, b = samples[:-1], samples[1:]
    d = b - a
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.nan_to_num(((q - a) * d).sum(axis=1) / (d * d).sum(axis=1)), 0.0, 1.0)
    return bool((np.abs(a + t[:, None] * d - q).max(axis=1) < 1e-9).any())


def run_with_feeds(core: MotionCore, cycles_each: int = 25) -> list[np.ndarray]:
    states = []
    k = 0
    while core.mode == "trajectory":
        core.set_feed(FEEDS[(k // cycles_each) % len(FEEDS)])
        states.append(core.step().q)
        k += 1
    return states


def test_a_slowed_ptp_stays_on_its_path_within_the_limits_and_takes_longer_by_what_it_was_held_back() -> None:
    core = MotionCore(ROBOT)
    plan = TrajectoryPlanner(ROBOT).plan_ptp([0.0] * 6, [60.0, -30.0, 40.0, 20.0, -30.0, 90.0], MotionSettings(ROBOT))
    t = plan.trajectory
    assert t is not None
    motion = core.execute(t.q, t.dt, t.qd, t.qdd)
    states = run_with_feeds(core)
    assert motion.ok and core.violation_count == 0
    assert all(on_path(t.q, q) for q in states)
    assert np.array_equal(states[-1], t.q[-1])
    assert len(states) * core.dt == pytest.approx((len(t.q) - 1) * core.dt + core.held_back_s, abs=core.dt)
    assert core.held_back_s > 3.0  # it was slowed, halted and slowed again on the way


def test_a_slowed_lin_stays_on_its_line() -> None:
    q0 = np.array([0.0, -60.0, 40.0, 0.0, 30.0, 0.0])
    settings, planner = MotionSettings(ROBOT), TrajectoryPlanner(ROBOT)
    start = fk(ROBOT, q0)[0]
    end = start.copy()
    end[:, 3] += [0.0, 100.0, 0.0]
    res = plan_lin(planner, q0, start, end, settings, make_ik(ROBOT, q0))
    assert res.ok and res.trajectory is not None, res.reason
    t = res.trajectory
    core = MotionCore(ROBOT, q0=q0)
    motion = core.execute(t.q, t.dt, t.qd, t.qdd)
    states = np.array(run_with_feeds(core, cycles_each=10))
    assert motion.ok and core.violation_count == 0 and core.held_back_s > 1.0
    assert all(on_path(t.q, q) for q in states)
    # between two samples 16 ms apart the joints' straight piece strays from the line by far less than a micrometre
    p = fk(ROBOT, states)[:, :, 3]
    u = (end[:, 3] - start[:, 3]) / np.linalg.norm(end[:, 3] - start[:, 3])
    d = p - start[:, 3]
    assert np.linalg.norm(d - np.outer(d @ u, u), axis=1).max() < 1e-3  # mm


def test_alter_plans_slower_at_a_lower_feed_and_still_arrives() -> None:
    durations = {}
    for feed in (1.0, 0.25):
        core = MotionCore(ROBOT)
        assert core.enable_alter() == (True, "")
        core.set_feed(feed)
        assert core.set_target([20.0, 0.0, 0.0, 0.0, 0.0, 0.0]) == (True, "")
        states = [core.step()]
        while states[-1].moving:
            core.heartbeat()  # the client is there, as an Alter client's stream says
            states.append(core.step())
        assert core.violation_count == 0 and np.allclose(states[-1].q, [20.0, 0, 0, 0, 0, 0], atol=1e-9)
        assert max(abs(s.qd[0]) for s in states) <= feed * core.limits().vmax[0] * (1 + 1e-6)
        durations[feed] = len(states) * core.dt
    assert durations[0.25] > 2 * durations[1.0]  # 20 deg: at full speed a triangle (1.5 s), slowed 3.2 s at 6.25 deg/s


def test_a_stop_brakes_from_the_slowed_speed() -> None:
    travel = {}
    for feed in (1.0, 0.2):
        core = MotionCore(ROBOT)
        plan = TrajectoryPlanner(ROBOT).plan_ptp([0.0] * 6, [90.0, 0, 0, 0, 0, 0], MotionSettings(ROBOT))
        t = plan.trajectory
        assert t is not None
        core.execute(t.q, t.dt, t.qd, t.qdd)
        core.set_feed(feed)
        for _ in range(150):  # cruising at that pace
            core.step()
        at = core.state().q[0]
        stop = core.stop("stop requested")
        core.run_until_idle()
        assert stop.done.is_set() and core.violation_count == 0
        travel[feed] = core.state().q[0] - at
    assert 0 < travel[0.2] < 0.1 * travel[1.0]  # the braking distance goes with the square of the speed
