"""Real-time motion through the whole system (gateway, planner, kinematics, driver, recorder):
the recorded joint states of a PTP, a LIN and an Alter session stay within every limit and
reach their targets; a 30 deg PTP of A1 takes the time the limits imply."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from harness.system import running
from rob6.robots import RobotModel, get_robot
from rob6.units import UNIT_CYCLE_S
from rob6_driver.service import REST_STATE_PERIOD_S
from rob6_recorder.reader import read_records

TOL = 1e-6


def joint_states(directory: Path) -> tuple[np.ndarray, np.ndarray]:
    """(t, q) of every recorded driver cycle, from the system recording."""
    rows = []
    for path in directory.glob("*_system_*.mcap"):
        rows += [(r.data["cycle"], r.data["t"], r.data["q"]) for r in read_records(path, ["/driver/joint_state"])]
    rows.sort()
    return np.array([r[1] for r in rows]), np.array([r[2] for r in rows])


def assert_within_limits(robot: RobotModel, t: np.ndarray, q: np.ndarray, speed: Sequence[float] | None = None,
                         accel: Sequence[float] | None = None) -> int:
    """The recorded states within the joint, speed and acceleration limits; returns the
    number of records in which the robot had moved since the one before.

    At rest the driver publishes only every few cycles (``REST_STATE_PERIOD_S``), so records
    are whole cycles apart and a gap is at most that long. A change across a gap is taken as
    one cycle's step (the robot may start in the gap's last cycle): that can only
    overestimate speed and acceleration, so the check stays sound."""
    vmax = np.array(speed or robot.default_speed) / UNIT_CYCLE_S
    amax = np.array(accel or robot.default_accel) / UNIT_CYCLE_S ** 2
    assert np.all(q > np.array(robot.turn_min)) and np.all(q < np.array(robot.turn_max))
    cycles = np.diff(t) / robot.cycle_s
    assert np.allclose(cycles, np.rint(cycles), atol=1e-6) and np.all(np.rint(cycles) >= 1), \
        "records not whole driver cycles apart"
    assert np.all(np.diff(t) <= REST_STATE_PERIOD_S + robot.cycle_s + 1e-9), "a driver cycle is missing from the recording"
    v = np.diff(q, axis=0) / robot.cycle_s
    a = np.diff(v, axis=0) / robot.cycle_s
    assert np.all(np.abs(v) <= vmax * (1 + TOL) + TOL), f"speed {np.abs(v).max(axis=0)} > {vmax}"
    assert np.all(np.abs(a) <= amax * (1 + TOL) + 1e-3), f"acceleration {np.abs(a).max(axis=0)} > {amax}"
    return int(np.any(v != 0, axis=1).sum())


def test_ptp_lin_and_alter_sessions_stay_within_limits(tmp_path: Path) -> None:
    robot = get_robot("kr16")
    start = [0.0, -80.0, 100.0, 0.0, 30.0, 0.0]
    with running("kr16", dummy=False, log_dir=str(tmp_path)) as system:
        with system.client() as client:
            assert client.ask("MovePTPJoints " + " ".join(map(str, start)), timeout=30) == "true\n"
            began = time.monotonic()
            assert client.ask("MovePTPJoints 30 -80 100 0 30 0", timeout=30) == "true\n"  # 30 deg of A1
            ptp_wall = time.monotonic() - began
            assert client.ask("MovePTPJoints " + " ".join(map(str, start)), timeout=30) == "true\n"
            assert client.ask("GetPositionJoints") == "0.000000 -80.000000 100.000000 0.000000 30.000000 0.000000\n"
            # LIN: 100 mm along x in the current configuration
            pose = [float(x) for x in client.ask("GetPositionHomRowWise").split()]
            pose[3] += 100.0
            assert client.ask("EnableLin") == "true\n"
            assert client.ask("MoveLINHomRowWise " + " ".join(f"{x:f}" for x in pose), timeout=30) == "true\n"
            reached = [float(x) for x in client.ask("GetPositionHomRowWise").split()]
            assert np.allclose(reached, pose, atol=1e-3)
            assert client.ask("DisableLin") == "true\n"
            # Alter: stream targets at 250 Hz, 2 s, a small sine on A1
            assert client.ask("EnableAlter") == "true\n"
            here = [float(x) for x in client.ask("GetPositionJoints").split()]
            for k in range(500):
                target = list(here)
                target[0] += 3.0 * np.sin(2 * np.pi * 0.5 * k / 250)
                client.send("MoveRTJoints " + " ".join(f"{x:f}" for x in target) + "\n")
                assert client.read_lines(1) == "true\n"
                time.sleep(0.004)
            final = list(here)
            final[0] += 2.0
            assert client.ask("MoveRTJoints " + " ".join(f"{x:f}" for x in final)) == "true\n"
            time.sleep(1.5)
            assert np.allclose([float(x) for x in client.ask("GetPositionJoints").split()], final, atol=1e-3)
            assert client.ask("DisableAlter") == "true\n"
        time.sleep(1.0)
    t, q = joint_states(tmp_path)
    assert assert_within_limits(robot, t, q) > 300  # two 30 deg PTPs alone move ~320 cycles
    # 30 deg of A1 at 0.1872 deg/cycle, 0.005 deg/cycle^2, jerk a/0.048 s: d/v + v/a + a/j
    v, a = 0.1872 / UNIT_CYCLE_S, 0.005 / UNIT_CYCLE_S ** 2
    expected = 30 / v + v / a + 0.048
    moving = np.nonzero(np.abs(np.diff(q[:, 0])) > 1e-9)[0]  # A1 moves only in the 30 deg PTP
    first_move = t[moving[0] + 1] - robot.cycle_s  # the cycle before the first step (records at rest are sparse)
    arrival = t[np.nonzero(np.abs(q[:, 0] - 30.0) < 1e-9)[0][0]]
    assert abs((arrival - first_move) - expected) <= 2 * robot.cycle_s
    assert ptp_wall >= expected - 2 * robot.cycle_s  # answered only after the robot arrived


def test_alter_mode_stops_when_the_client_goes_away() -> None:
    with running("kr16rt", dummy=False) as system:
        with system.client() as client:
            assert client.ask("MovePTPJoints 0 -10 10 0 30 0", timeout=30) == "true\n"
            assert client.ask("EnableAlter") == "true\n"
            assert client.ask("MoveRTJoints 40 -10 10 0 30 0") == "true\n"  # ~3 s away
            time.sleep(0.5)
        # the client left mid-motion: the robot ramps to a stop instead of going on
        time.sleep(2.0)
        with system.client() as client:
            first = [float(x) for x in client.ask("GetPositionJoints").split()]
            time.sleep(0.3)
            second = [float(x) for x in client.ask("GetPositionJoints").split()]
            assert first == second, "still moving"
            assert 0.5 < first[0] < 30.0, f"A1 at {first[0]}: it went on to the target"
            assert client.ask("MoveRTJoints 10 -10 10 0 30 0") == "false\n"  # Alter mode ended with it


def test_alter_mode_stops_when_targets_stop_coming() -> None:
    with running("kr16rt", dummy=False) as system, system.client() as client:
        assert client.ask("MovePTPJoints 0 -10 10 0 30 0", timeout=30) == "true\n"
        assert client.ask("EnableAlter") == "true\n"
        assert client.ask("MoveRTJoints 40 -10 10 0 30 0") == "true\n"
        time.sleep(2.5)  # no new target for 0.5 s: the watchdog stops the robot
        first = [float(x) for x in client.ask("GetPositionJoints").split()]
        time.sleep(0.3)
        assert [float(x) for x in client.ask("GetPositionJoints").split()] == first
        assert 0.5 < first[0] < 30.0


def test_robot_stops_when_the_planner_goes_away_mid_motion() -> None:
    import os
    import signal
    with running("kr16", dummy=False) as system, system.client() as client:
        client.send("MovePTPJoints 60 0 0 0 30 0\n")  # ~5 s of motion
        time.sleep(1.0)
        os.kill(system.pids()["planner"], signal.SIGKILL)
        reply = client.read_lines(2, timeout=10)
        assert reply.startswith("ERROR: planner") and reply.endswith("\nfalse\n"), reply
        time.sleep(2.5)
        first = [float(x) for x in client.ask("GetPositionJoints").split()]
        time.sleep(0.3)
        assert [float(x) for x in client.ask("GetPositionJoints").split()] == first  # at rest
        assert 5.0 < first[0] < 50.0, f"A1 at {first[0]}: it did not stop short of 60"
