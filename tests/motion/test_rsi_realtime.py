"""The whole system (``rob6 run --link rsi``) driving the KR C4 controller simulator
(kuka-rsi-sim) in real time over real UDP: PTP, LIN and Alter sessions within every limit
without a trip, the recording replayed against the simulation without a
difference, and the link's faults: packets lost, dropped, RSI restarted on a new start
pose, the controller switched off and on again."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from harness.client import Client
from harness.ports import free_port
from harness.system import System, link_status, running
from rob6.robots import get_robot
from rob6_recorder.reader import read_records
from tests.controllers.rsi_controller import SYSTEM_TIMEOUT, RsiController
from tests.motion.link_session import joints, reply, wait_until
from tests.motion.realtime_rig import driver_refusal, recorded_states
from tests.motion.test_realtime_system import assert_within_limits

pytestmark = pytest.mark.slow

ROBOT = get_robot("kr16rt")
HOME = [0.0, -90.0, 90.0, 0.0, 0.0, 0.0]
#: the controller's rated axis speeds (its machine data), deg/s: a correction step beyond
#: speed x cycle trips "Command velocity"
RATED = np.array([156.0, 156.0, 156.0, 330.0, 330.0, 615.0])
#: AIPos travels with 4 decimals, AK with 6
POSITION_TOL = 2e-4


def rsi_system(port: int, **kwargs: Any) -> AbstractContextManager[System]:
    return running("kr16rt", dummy=False, extra_env={"ROB6_LINK": "rsi", "ROB6_RSI_LISTEN": f"127.0.0.1:{port}"},
                   **kwargs)


def controller(port: int, *args: str) -> RsiController:
    """The stand-in KR C4 running the shipped files, sending to the driver on ``port``."""
    return RsiController(*args, rob6=("127.0.0.1", port), robot="kr16rt", timeout=SYSTEM_TIMEOUT)


def connected(client: Client, kuka: RsiController, system: System) -> np.ndarray:
    """Wait until rob6 follows the controller: the driver's link is up again and rob6's
    position is the controller's AIPos (a robot holding still shows that already while
    the link is still lost)."""
    def follows() -> np.ndarray | None:
        q = joints(client)
        return q if np.allclose(q, kuka.status()["aipos"], atol=POSITION_TOL) else None
    wait_until(lambda: link_status(system).state == "connected", timeout=10.0, what="the RSI link to be up")
    return wait_until(follows, timeout=10.0, what="rob6 to follow the controller")


def assert_no_jump(status: dict[str, Any]) -> None:
    """No correction step of the run went beyond what the axes can move in one cycle."""
    assert not status["trips"], status["trips"]
    assert np.all(np.array(status["max_ak_step"]) <= RATED * ROBOT.cycle_s), status["max_ak_step"]


def connected_states(directory: Path) -> tuple[np.ndarray, np.ndarray]:
    """(t, q) of every recorded cycle while the robot was connected."""
    return recorded_states(directory, connected_only=True)


def session(client: Client) -> None:
    """PTP, LIN and Alter (MoveRTJoints streamed at 250 Hz), as in test_realtime_system."""
    start = "0 -80 100 0 30 0"
    assert reply(client, "MovePTPJoints " + start) == "true\n"
    assert reply(client, "MovePTPJoints 30 -80 100 0 30 0") == "true\n"
    assert reply(client, "MovePTPJoints " + start) == "true\n"
    assert client.ask("GetPositionJoints") == "0.000000 -80.000000 100.000000 0.000000 30.000000 0.000000\n"
    pose = [float(x) for x in client.ask("GetPositionHomRowWise").split()]
    pose[3] += 100.0
    assert client.ask("EnableLin") == "true\n"
    assert reply(client, "MoveLINHomRowWise " + " ".join(f"{x:f}" for x in pose)) == "true\n"
    assert np.allclose([float(x) for x in client.ask("GetPositionHomRowWise").split()], pose, atol=1e-3)
    assert client.ask("DisableLin") == "true\n"
    assert client.ask("EnableAlter") == "true\n"
    here = joints(client)
    began = time.monotonic()
    for k in range(500):
        target = here.copy()
        target[0] += 3.0 * np.sin(2 * np.pi * 0.5 * k / 250)
        assert reply(client, "MoveRTJoints " + " ".join(f"{x:f}" for x in target)) == "true\n"
        delay = began + (k + 1) * 0.004 - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    final = here.copy()
    final[0] += 2.0
    assert reply(client, "MoveRTJoints " + " ".join(f"{x:f}" for x in final)) == "true\n"
    time.sleep(1.5)
    assert np.allclose(joints(client), final, atol=1e-3)
    assert client.ask("DisableAlter") == "true\n"


def test_ptp_lin_alter_over_rsi_within_limits_and_replayed_on_the_simulation(tmp_path: Path) -> None:
    port = free_port(socket.SOCK_DGRAM)
    # the controller starts where the simulation does, so that the replay below is exact
    zero = "--start-pose", "0,0,0,0,0,0"
    with rsi_system(port, log_dir=str(tmp_path)) as system:
        with system.client() as client:  # session 1: no robot yet, then the robot comes
            assert reply(client, "MovePTPJoints 10 -90 90 0 0 0") == (
                f"ERROR: driver: robot not connected (waiting for RSI on 127.0.0.1:{port})\nfalse\n")
            assert reply(client, "EnableAlter") == (
                f"ERROR: driver: robot not connected (waiting for RSI on 127.0.0.1:{port})\nfalse\n")
            assert reply(client, "MoveRTJoints 10 -90 90 0 0 0") == "false\n"  # Alter mode is off
            assert reply(client, "MovePTPJoints 999 0 0 0 0 0") == "false\n"  # refused before the driver
            kuka = controller(port, *zero).start()
            assert np.array_equal(connected(client, kuka, system), np.zeros(6))
        try:
            with system.client() as client:  # session 2: the one replayed below
                session(client)
                status = kuka.status()
                assert np.allclose(joints(client), status["aipos"], atol=POSITION_TOL)
                assert client.ask("Quit") == "bye!\n"
            assert status["state"] == "running" and status["runs"] == 1
            # late packets depend on how busy this machine is (bench/ measures them); what
            # must hold is that the run never tripped and rob6 counts what the controller counts
            assert_no_jump(status)
            link = link_status(system)
            assert (link.state, link.runs) == ("connected", 1)
            assert status["late_total"] <= link.late <= kuka.status()["late_total"]
            time.sleep(1.5)  # the session file is finished shortly after the client left
        finally:
            kuka.stop()
    t, q = connected_states(tmp_path)
    assert assert_within_limits(ROBOT, t, q) > 1000
    recorded = [r for path in tmp_path.glob("*_system_*.mcap") for r in read_records(path, ["/driver/link"])]
    assert [r.data["event"] for r in recorded][:2] == ["waiting", "run_start"]
    assert recorded[1].data["start_pose"] == [0.0] * 6
    # the recorded session against the simulation: the same replies
    replayed = sorted(tmp_path.glob("*_session2.mcap"))
    assert replayed, sorted(p.name for p in tmp_path.iterdir())
    with running("kr16rt", dummy=False) as simulation:
        result = subprocess.run([sys.executable, "-m", "rob6_recorder.cli", "replay", str(replayed[0]), "--to",
                                 f"127.0.0.1:{simulation.port}", "--timeout", "30"],
                                capture_output=True, check=False, text=True, timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.fixture(scope="module")
def rsi() -> Iterator[tuple[System, int]]:
    """One rob6 system on RSI for the fault tests; each test brings its own controller."""
    port = free_port(socket.SOCK_DGRAM)
    with rsi_system(port) as system:
        yield system, port


def long_move(client: Client, kuka: RsiController) -> None:
    """Start a PTP of ~3 s from HOME (A1 0 -> 40) without waiting for its reply."""
    assert reply(client, "MovePTPJoints 0 -90 90 0 0 0") == "true\n"
    client.send("MovePTPJoints 40 -90 90 0 0 0\n")
    wait_until(lambda: kuka.status()["aipos"][0] > 5.0, timeout=10.0, what="the robot to move")


def test_packets_lost_mid_motion_end_it_and_rob6_resumes_from_aipos(rsi: tuple[System, int]) -> None:
    system, port = rsi
    with controller(port) as kuka, system.client() as client:
        connected(client, kuka, system)
        long_move(client, kuka)
        kuka.fault(lose_s=0.3)  # 75 cycles without a packet either way: the controller holds
        lost = client.read_lines(2, timeout=30)
        assert lost.startswith("ERROR: driver: RSI link lost: no packet from the controller at 127.0.0.1:")
        assert lost.endswith(" for 100 ms\nfalse\n")
        here = connected(client, kuka, system)  # back in the same run, where the robot stands
        assert 5.0 < here[0] < 40.0
        status = kuka.status()
        assert status["runs"] == 1 and status["late_total"] >= 25
        assert reply(client, "MovePTPJoints 0 -90 90 0 0 0") == "true\n"
        assert np.allclose(joints(client), kuka.status()["aipos"], atol=POSITION_TOL)
        assert_no_jump(kuka.status())


def test_every_50th_packet_dropped_the_motion_completes(rsi: tuple[System, int]) -> None:
    system, port = rsi
    with controller(port) as kuka, system.client() as client:
        connected(client, kuka, system)
        before = link_status(system).late
        kuka.fault(drop_every=50)
        assert reply(client, "MovePTPJoints 30 -80 80 10 20 30") == "true\n"
        assert reply(client, "MovePTPJoints 0 -90 90 0 0 0") == "true\n"
        kuka.clear()
        status = kuka.status()
        dropped = status["fault_stats"]["dropped"]
        assert dropped >= 20
        assert status["late_total"] >= dropped  # every dropped packet counts as late (a busy machine adds some)
        link = link_status(system)
        assert link.late - before >= dropped and link.state == "connected"
        assert_no_jump(status)
        assert np.allclose(joints(client), status["aipos"], atol=POSITION_TOL)


def test_rsi_restarted_on_a_new_start_pose_rebases_without_a_jump(rsi: tuple[System, int]) -> None:
    system, port = rsi
    with controller(port) as kuka, system.client() as client:
        connected(client, kuka, system)
        long_move(client, kuka)
        new_start = [-20.0, -70.0, 80.0, 10.0, 20.0, 0.0]
        kuka.restart(start=new_start)  # RSI off, a PTP to the new pose, RSI on again
        answer = client.read_lines(1, timeout=30)
        assert answer == "ERROR: driver: the controller restarted RSI during the motion\n", answer
        assert client.read_lines(1) == "false\n"
        assert np.allclose(connected(client, kuka, system), new_start, atol=POSITION_TOL)
        assert kuka.status()["ak"] == [0.0] * 6  # re-based: zero correction at the new start
        assert reply(client, "MovePTPJoints -10 -70 80 10 20 0") == "true\n"
        status = kuka.status()
        assert status["runs"] == 2 and np.allclose(status["aspos"], new_start, atol=POSITION_TOL)
        assert np.allclose(status["aipos"], [-10.0, -70.0, 80.0, 10.0, 20.0, 0.0], atol=POSITION_TOL)
        assert_no_jump(status)


def test_controller_vanishes_and_returns(rsi: tuple[System, int]) -> None:
    system, port = rsi
    with controller(port) as kuka, system.client() as client:
        connected(client, kuka, system)
        long_move(client, kuka)
        kuka.vanish()  # switched off until restarted
        lost = client.read_lines(2, timeout=30)
        assert lost.startswith("ERROR: driver: RSI link lost: no packet from the controller at ")
        assert lost.endswith("false\n")
        refused = reply(client, "MovePTPJoints 0 -90 90 0 0 0")
        assert refused.startswith("ERROR: driver: RSI link lost: ") and refused.endswith("\nfalse\n")
        stood = kuka.status()["aipos"]
        kuka.restart()  # on again: a new run from where the robot stands
        assert np.allclose(connected(client, kuka, system), stood, atol=POSITION_TOL)
        assert reply(client, "MovePTPJoints 0 -90 90 0 0 0") == "true\n"
        status = kuka.status()
        assert np.allclose(status["aipos"], HOME, atol=POSITION_TOL) and status["runs"] == 2
        assert_no_jump(status)


def test_rsi_on_a_robot_without_rsi_is_refused_in_one_line() -> None:
    assert driver_refusal("--robot", "ad850", "--link", "rsi") == (
        78, "rob6-driver: --link rsi drives KUKA robots (kr3, kr16, kr3rt, kr16rt), not ad850; use --link sim\n")
