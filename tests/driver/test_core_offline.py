"""The motion core's side of a link: offline ends motions with the plant's error and refuses
commands; online resumes at the robot's actual position, at rest, without a jump."""

from __future__ import annotations

import numpy as np
import pytest

from rob6_driver.motion import Motion, MotionCore, Offline
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import TrajectoryPlanner

HOME = [0.0, -90.0, 90.0, 0.0, 0.0, 0.0]


def ptp(core: MotionCore, target: list[float]) -> Motion:
    plan = TrajectoryPlanner(core.robot).plan_ptp(core.state().q.tolist(), target, MotionSettings(core.robot))
    assert plan.ok, plan.reason
    t = plan.trajectory
    assert t is not None
    return core.execute(t.q, t.dt, t.qd, t.qdd)


def test_a_core_waiting_for_its_robot_refuses_motion_with_the_reason() -> None:
    core = MotionCore("kr16rt", offline="robot not connected (waiting for RSI on 0.0.0.0:49152)")
    motion = core.execute([[0.0] * 6, [0.0] * 6], core.dt)
    assert motion.done.is_set() and motion.ok is False
    assert motion.error == motion.reason == "robot not connected (waiting for RSI on 0.0.0.0:49152)"
    with pytest.raises(Offline, match="waiting for RSI"):
        core.enable_alter()
    assert core.stop().wait(0.1)  # stopping what does not move is fine


def test_link_lost_mid_motion_ends_it_and_the_robot_resumes_where_it_really_is() -> None:
    core = MotionCore("kr16rt", q0=HOME)
    motion = ptp(core, [30.0, -90.0, 90.0, 0.0, 0.0, 0.0])
    core.run(200)
    assert not motion.done.is_set()
    core.offline("RSI link lost: no packet for 100 ms")
    assert motion.done.is_set() and motion.ok is False and motion.error == "RSI link lost: no packet for 100 ms"
    refused = core.execute([core.state().q.tolist()] * 2, core.dt)
    assert refused.error == "RSI link lost: no packet for 100 ms"
    actual = core.state().q + [0.01, 0, 0, 0, 0, 0]  # the robot settled a little further
    core.online(actual)
    state = core.step()
    assert np.array_equal(state.q, actual) and not state.moving and state.mode == "idle"
    assert not np.any(state.qd)
    # a new motion starts from there, within the limits from rest
    again = ptp(core, HOME)
    states = core.run_until_idle()
    assert again.ok and np.allclose(states[-1].q, HOME)
    assert np.abs(states[0].q - actual).max() < 1e-3


def test_alter_mode_survives_a_lost_link_holding_the_actual_position() -> None:
    core = MotionCore("kr16rt", q0=HOME)
    assert core.enable_alter() == (True, "")
    assert core.set_target([5.0, -90.0, 90.0, 0.0, 0.0, 0.0]) == (True, "")
    core.run(50)
    core.offline("RSI link lost")
    with pytest.raises(Offline, match="RSI link lost"):
        core.set_target([6.0, -90.0, 90.0, 0.0, 0.0, 0.0])
    actual = core.state().q
    core.online(actual)
    assert core.alter_enabled
    states = core.run(20)  # no stale target: it holds
    assert all(np.array_equal(s.q, actual) for s in states)
    assert core.set_target([1.0, -90.0, 90.0, 0.0, 0.0, 0.0]) == (True, "")
    core.run_until_idle()
    assert np.allclose(core.state().q, [1.0, -90.0, 90.0, 0.0, 0.0, 0.0])


def test_online_under_a_running_motion_ends_it_with_the_restart_reason() -> None:
    core = MotionCore("kr16rt", q0=HOME)
    motion = ptp(core, [10.0, -90.0, 90.0, 0.0, 0.0, 0.0])
    core.run(10)
    core.online([3.0, -80.0, 90.0, 0.0, 0.0, 0.0], reason="the controller restarted RSI")
    assert motion.ok is False and motion.error == "the controller restarted RSI"
    assert core.step().q.tolist() == [3.0, -80.0, 90.0, 0.0, 0.0, 0.0]
