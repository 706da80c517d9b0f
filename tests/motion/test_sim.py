"""Simulated robot: trajectory execution, monitor, stops, Alter mode, watchdog, dummy mode.

Everything runs in fast-forward (``sim.step()``), never on the wall clock.
"""

import math
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from rob6_driver.limits import Limits
from rob6_driver.motion import CoreState, Motion, MotionCore
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import SampledTrajectory, TrajectoryPlanner

TOL_REL = 1e-6
TOL_V = 1e-9
TOL_A = 1e-6


def limit_problems(qs: npt.ArrayLike, dt: float, lim: Limits, q_before: npt.ArrayLike | None = None,
                   v_before: npt.ArrayLike | None = None, qd: npt.ArrayLike | None = None,
                   qdd: npt.ArrayLike | None = None) -> list[tuple[str, np.ndarray]]:
    """All speed/acceleration/turn problems of a state sequence (finite differences + exact)."""
    qs = np.asarray(qs, float)
    if q_before is not None:
        qs = np.vstack([q_before, qs])
    problems: list[tuple[str, np.ndarray]] = []
    v = np.diff(qs, axis=0) / dt
    v0 = np.zeros((1, 6)) if v_before is None else np.asarray(v_before)[None]
    a = np.diff(np.vstack([v0, v]), axis=0) / dt
    if (np.abs(v) > lim.vmax * (1 + TOL_REL) + TOL_V).any():
        problems.append(("speed", np.abs(v).max(axis=0)))
    if (np.abs(a) > lim.amax * (1 + TOL_REL) + TOL_A).any():
        problems.append(("accel", np.abs(a).max(axis=0)))
    inside = (qs[1:] > lim.turn_min) & (qs[1:] < lim.turn_max)
    if not inside.all():
        problems.append(("turn", qs[1:][~inside.all(axis=1)][:1]))
    for name, arr, bound in (("qd", qd, lim.vmax), ("qdd", qdd, lim.amax)):
        if arr is not None and (np.abs(arr) > bound * (1 + TOL_REL) + TOL_A).any():
            problems.append((name, np.abs(arr).max(axis=0)))
    return problems


def run_states(sim: MotionCore, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[CoreState]]:
    states = sim.run(n)
    return (np.array([s.q for s in states]), np.array([s.qd for s in states]),
            np.array([s.qdd for s in states]), states)


def plan(robot: str, q0: npt.ArrayLike, q1: npt.ArrayLike,
         config: MotionSettings | None = None) -> SampledTrajectory:
    config = config or MotionSettings(robot)
    res = TrajectoryPlanner(robot).plan_ptp(q0, q1, config)
    assert res.ok, res.reason
    assert res.trajectory is not None
    return res.trajectory


# ---------------------------------------------------------------- trajectories
def test_execute_completes_awaitably() -> None:
    sim = MotionCore("kr16")
    tr = plan("kr16", np.zeros(6), [20, -30, 40, 10, 30, -50])
    seen = []

    def on_done(m: Motion) -> None:
        assert m.final is not None  # a finished motion has its final state
        seen.append((m.ok, m.final.cycle))

    motion = sim.execute(tr.q, tr.dt, tr.qd, tr.qdd)
    motion.add_done_callback(on_done)
    assert not motion.done.is_set() and sim.state().mode == "trajectory"
    q, qd, qdd, states = run_states(sim, tr.n - 1)
    assert motion.wait(0) and motion.ok and seen == [(True, tr.n - 1)]
    assert np.allclose(sim.state().q, tr.q[-1], atol=0)
    assert sim.state().mode == "idle"
    assert limit_problems(q, sim.dt, sim.limits(), np.zeros(6), qd=qd, qdd=qdd) == []
    late = []
    motion.add_done_callback(lambda m: late.append(m.ok))  # already done: runs at once
    assert late == [True]


def test_execute_refusals() -> None:
    sim = MotionCore("kr16")
    tr = plan("kr16", np.zeros(6), [10, 0, 0, 0, 0, 0])
    assert "start" in sim.execute(tr.q[5:]).reason
    assert "cycle" in sim.execute(tr.q, dt=0.004).reason
    jumpy = tr.q.copy()
    jumpy[50:, 0] += 1.0  # a 1 deg jump: far beyond speed and acceleration
    m = sim.execute(jumpy)
    assert m.done.is_set() and not m.ok and "joint 1" in m.reason
    outside = np.linspace([0] * 6, [0, 25, 0, 0, 0, 0], 3000)  # J2 max is 20
    assert "turn limits" in sim.execute(outside).reason
    m = sim.execute(tr.q, tr.dt)
    assert "busy" in sim.execute(tr.q).reason
    sim.run_until_idle()
    assert m.ok and sim.violation_count == 0


def test_monitor_stops_a_bad_sample_in_a_controlled_way() -> None:
    sim = MotionCore("kr16")
    tr = plan("kr16", np.zeros(6), [30, 0, 0, 0, 0, 0])
    bad = tr.q.copy()
    bad[100:, 0] += 2.0  # corrupted stream: skipped by the up-front check
    m = sim.execute(bad, tr.dt, tr.qd, tr.qdd, check=False)
    q, qd, qdd, states = run_states(sim, 400)
    assert m.done.is_set() and not m.ok and "violation" in m.reason
    assert sim.violation_count >= 1 and sim.violations[0].kind in ("speed", "acceleration")
    assert sim.violations[0].source == "trajectory"
    assert limit_problems(q, sim.dt, sim.limits(), np.zeros(6), qd=qd, qdd=qdd) == []
    assert states[-1].mode == "idle" and not states[-1].moving
    assert sim.violations[0].cycle == 100  # caught at the first bad sample
    assert bad[99, 0] < q[-1, 0] < 25  # braked from there (braking distance ~3.6 deg)
    # it braked: stops well before the trajectory's end
    stopped_at = next(i for i, s in enumerate(states) if not s.moving)
    assert stopped_at < tr.n


def test_stop_mid_trajectory_ramps_within_limits() -> None:
    for with_derivatives in (True, False):
        sim = MotionCore("kr16rt")
        tr = plan("kr16rt", np.zeros(6), [60, -40, 50, 90, 60, 120])
        m = sim.execute(tr.q, tr.dt, *((tr.qd, tr.qdd) if with_derivatives else ()))
        q1, qd1, qdd1, _ = run_states(sim, 170)  # in the acceleration phase
        s = sim.stop("client gone")
        q2, qd2, qdd2, states = run_states(sim, 600)
        q = np.vstack([q1, q2])
        assert s.done.is_set() and m.done.is_set() and not m.ok and m.reason == "client gone"
        problems = limit_problems(q, sim.dt, sim.limits(), np.zeros(6),
                                  qd=np.vstack([qd1, qd2]), qdd=np.vstack([qdd1, qdd2]))
        assert problems == []
        assert not states[-1].moving and states[-1].mode == "idle"
        assert np.abs(q[-1] - tr.q[-1]).max() > 1.0  # did not just finish the move
        if with_derivatives:
            assert sim.violation_count == 0


def test_dummy_mode_jumps_to_the_end() -> None:
    sim = MotionCore("kr16", dummy=True)
    tr = plan("kr16", np.zeros(6), [10, -60, 80, 20, 40, 30])
    m = sim.execute(tr.q, tr.dt)
    assert m.done.is_set() and m.ok
    assert np.array_equal(sim.state().q, tr.q[-1])
    assert not sim.execute(np.array([tr.q[-1], [10, 25, 80, 20, 40, 30]])).ok  # turn limit
    sim.enable_alter()
    assert sim.set_target([0, 0, 0, 0, 10, 0])[0]
    assert np.array_equal(sim.state().q, [0, 0, 0, 0, 10, 0])


# ---------------------------------------------------------------- Alter mode
@pytest.mark.parametrize("robot", ["kr16rt", "kr16"])
def test_alter_streaming_250hz(robot: str) -> None:
    sim = MotionCore(robot, alter_timeout_s=0.1)
    q_start = np.array([0, -60, 80, 0, 40, 0.0])
    sim.execute(plan(robot, np.zeros(6), q_start).q)
    sim.run_until_idle()
    assert sim.enable_alter(synchronized=False)[0]
    dt_stream = 1 / 250
    amp = np.array([10, 5, 5, 10, 10, 10.0])
    freq = 0.25  # Hz: peak speed/acceleration within the default limits
    t_stream = 0.0
    qs, qds, qdds, errs = [], [], [], []
    for _ in range(int(8.0 / sim.dt)):
        # the client sends at 250 Hz; the driver cycles at its own rate
        while t_stream <= sim.t + 1e-12:
            target = q_start + amp * np.sin(2 * math.pi * freq * t_stream)
            assert sim.set_target(target)[0]
            t_stream += dt_stream
        s = sim.step()
        qs.append(s.q)
        qds.append(s.qd)
        qdds.append(s.qdd)
        errs.append(np.abs(s.q - target).max())
    assert limit_problems(qs, sim.dt, sim.limits(), q_start, qd=np.array(qds), qdd=np.array(qdds)) == []
    assert sim.violation_count == 0
    # tracks; the lag (~3 deg at the turning points) is that of a follower that plans to
    # stop at every new target with 15.6 deg/s and 34.7 deg/s^2
    assert max(errs[int(3.0 / sim.dt):]) < 4.0
    # client goes quiet: the watchdog stops the robot within limits and stays in Alter
    q, qd, qdd, states = run_states(sim, int(2.0 / sim.dt))
    assert not states[-1].moving and states[-1].mode == "alter"
    assert limit_problems(q, sim.dt, sim.limits(), qs[-1], (qs[-1] - qs[-2]) / sim.dt, qd, qdd) == []
    assert sim.violation_count == 0


def test_watchdog_event_and_resume() -> None:
    events: list[dict[str, Any]] = []
    sim = MotionCore("kr16rt", alter_timeout_s=0.05, on_event=events.append)
    sim.enable_alter()
    sim.set_target([40, 0, 0, 0, 0, 0])
    q, *_ = run_states(sim, 200)  # 0.8 s without news
    assert [e["type"] for e in events] == ["watchdog"]
    assert events[0]["t"] == pytest.approx(0.056, abs=0.005)
    assert not sim.state().moving and 0 < sim.state().q[0] < 5
    sim.set_target([1, 0, 0, 0, 0, 0])  # a new target resumes
    for _ in range(300):
        sim.heartbeat()
        sim.step()
    assert sim.state().q[0] == pytest.approx(1.0, abs=1e-9)


def test_rt_speed_control_synchronised_vs_independent() -> None:
    arrival = {}
    for synchronized in (True, False):
        sim = MotionCore("kr16rt", alter_timeout_s=10)
        sim.enable_alter(synchronized=synchronized)
        sim.set_target([30, 0, 0, 0, 3, 0])
        first = {}
        for k in range(2000):
            s = sim.step()
            for j in (0, 4):
                if j not in first and abs(s.q[j] - [30, 0, 0, 0, 3, 0][j]) < 1e-9 and abs(s.qd[j]) < 1e-9:
                    first[j] = k
        arrival[synchronized] = first
    assert arrival[True][0] == arrival[True][4]  # RTSpeedControl 0: arrive together
    assert arrival[False][4] < arrival[False][0] - 50  # RTSpeedControl 1: each on its own


def test_alter_targets_near_a_turn_limit_never_cross_it() -> None:
    sim = MotionCore("kr16rt", alter_timeout_s=10)
    sim.set_limits(max_speed=[1.872] * 3 + [3.96, 3.96, 7.38], max_accel=[0.02] * 6)
    sim.enable_alter()
    sim.set_target([170, 0, 0, 0, 0, 0])
    q1, *_ = run_states(sim, 120)  # fast towards +170
    assert sim.state().qd[0] > 50
    sim.set_target([184.999, 0, 0, 0, 0, 0])  # max 185, closer than the braking distance
    q2, *_ = run_states(sim, 1000)
    assert q2[:, 0].max() < 185.0
    assert not sim.set_target([185, 0, 0, 0, 0, 0])[0]  # strict limits
    assert not sim.set_target([0, 0, 0, 0, float("nan"), 0])[0]
    assert sim.violation_count == 0


def test_alter_targets_within_max_change_of_where_the_robot_is() -> None:
    """The driver is the home of the Alter target rule (the gateway streams to it directly)."""
    sim = MotionCore("kr16", dummy=True)
    assert sim.set_limits(max_change=[5, 5, 5, 5, 5, 1])[0]
    assert not sim.set_target([1, 0, 0, 0, 0, 0])[0]  # Alter mode off
    sim.enable_alter()
    assert sim.set_target([5, 0, 0, 0, 0, 1])[0]  # exactly max change away is allowed
    ok, reason = sim.set_target([5, 0, 0, 0, 0, 2.5])
    assert not ok and "joint 6" in reason and "max change 1" in reason
    assert np.array_equal(sim.state().q, [5, 0, 0, 0, 0, 1])  # a refused target moves nothing
    assert sim.set_target([-1, 0, 0, 0, 0, 0.5], relative=True)[0]  # DoAlterJoint: an offset
    assert np.array_equal(sim.state().q, [4, 0, 0, 0, 0, 1.5])
    assert not sim.set_target([0, 0, 0, 0, 0, 1.5], relative=True)[0]
    assert not sim.set_limits(max_change=[1, 2, 3])[0]  # six values or nothing changes
    assert sim.limits().max_change.tolist() == [5, 5, 5, 5, 5, 1]


def test_limit_change_during_alter_is_smooth() -> None:
    sim = MotionCore("kr16rt", alter_timeout_s=10)
    sim.enable_alter()
    sim.set_target([100, 0, 0, 0, 0, 0])
    q1, qd1, qdd1, _ = run_states(sim, 500)
    old = sim.limits()
    assert sim.set_limits(max_speed=[0.05] * 6, max_accel=[0.001] * 6)[0]
    q2, qd2, qdd2, st = run_states(sim, 3000)
    new = sim.limits()
    wide = Limits(old.turn_min, old.turn_max, np.maximum(old.vmax, new.vmax),
                     np.maximum(old.amax, new.amax), old.jmax, old.max_change)
    q = np.vstack([q1, q2])
    assert limit_problems(q, sim.dt, wide, np.zeros(6)) == []
    assert np.allclose(sim.enforced_limits().vmax, new.vmax)  # monitor closed again
    # after settling, the new limits hold
    assert np.abs(qd2[-1000:]).max() <= new.vmax.max() * (1 + 1e-6)
    assert sim.violation_count == 0


def test_turn_limit_change_under_a_crossing_motion_stops() -> None:
    sim = MotionCore("kr16")
    tr = plan("kr16", np.zeros(6), [90, 0, 0, 0, 0, 0])
    m = sim.execute(tr.q, tr.dt, tr.qd, tr.qdd)
    q1, *_ = run_states(sim, 200)
    assert sim.set_limits(turn_max=[40, 20, 154, 350, 125, 350])[0]
    q2, qd2, qdd2, states = run_states(sim, 600)
    assert m.done.is_set() and not m.ok
    assert [v.kind for v in sim.violations] == ["limits_changed"]
    q = np.vstack([q1, q2])
    assert limit_problems(q, sim.dt, Limits.defaults(sim.robot), np.zeros(6)) == []
    assert not states[-1].moving
    assert np.array_equal(sim.enforced_limits().turn_max, [40, 20, 154, 350, 125, 350])


def test_stop_in_alter_leaves_alter_mode() -> None:
    sim = MotionCore("kr16", alter_timeout_s=10)
    sim.enable_alter()
    sim.set_target([20, -10, 10, 0, 20, 0])
    sim.run(60)
    s = sim.stop()
    assert not sim.alter_enabled and not s.done.is_set()
    sim.run_until_idle()
    assert s.done.is_set() and sim.state().mode == "idle" and not sim.state().moving
    assert not sim.set_target([0] * 6)[0]
    assert sim.disable_alter().done.is_set()


def test_trajectory_extrema_match_dense_sampling() -> None:
    """The sim's own extrema (used for the turn-limit look-ahead) against at_time sampling."""
    import ruckig

    from rob6_driver.motion import trajectory_extrema

    rng = np.random.default_rng(5)
    otg = ruckig.Ruckig(6, 0.004)
    checked = 0
    for k in range(300):
        inp = ruckig.InputParameter(6)
        inp.current_position = rng.uniform(-50, 50, 6).tolist()
        inp.current_velocity = (rng.uniform(-60, 60, 6) * (rng.random(6) < 0.7)).tolist()
        inp.current_acceleration = (rng.uniform(-60, 60, 6) * (rng.random(6) < 0.5)).tolist()
        inp.max_velocity = rng.uniform(1, 40, 6).tolist()
        inp.max_acceleration = rng.uniform(5, 40, 6).tolist()
        inp.max_jerk = (np.array(inp.max_acceleration) / 0.048).tolist()
        if k % 2:
            inp.control_interface = ruckig.ControlInterface.Velocity
        else:
            inp.target_position = rng.uniform(-50, 50, 6).tolist()
        inp.synchronization = [ruckig.Synchronization.No, ruckig.Synchronization.Time,
                               ruckig.Synchronization.Phase][k % 3]
        traj = ruckig.Trajectory(6)
        try:
            res = otg.calculate(inp, traj)
        except Exception:
            continue
        if res not in (ruckig.Result.Working, ruckig.Result.Finished) or traj.duration > 30:
            continue
        t_from = rng.uniform(0, traj.duration) if k % 4 == 0 else 0.0
        times = np.linspace(t_from, traj.duration + 0.2, 3001)
        P = np.array([traj.at_time(float(t))[0] for t in times])
        lo, hi = trajectory_extrema(traj, t_from)
        step = np.abs(np.diff(P, axis=0)).max()  # sampling can miss a peak by < one step
        assert np.all(lo <= P.min(axis=0) + 1e-9) and np.all(hi >= P.max(axis=0) - 1e-9)
        assert np.all(lo >= P.min(axis=0) - step) and np.all(hi <= P.max(axis=0) + step)
        checked += 1
    assert checked > 200
