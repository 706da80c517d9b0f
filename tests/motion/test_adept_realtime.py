"""The whole system (``rob6 run --robot ad850 --link simple_message``) driving the Adept
controller simulator (adept-sm-sim, a separate process playing adept_ros.v2 over real
TCP) in real time: PTP, LIN and Alter sessions within every limit, in both byte orders; a
long PTP at monitor speeds 3, 10 and 100 % arriving without a lost link or a false
timeout; a stop (a client that vanishes, an old client's DisableAlter) bringing the arm
to rest within the stated bound at each of them; and the faults: E-stop and drives off
mid-motion, the motion or state connection dropped, slow and missing acknowledgements.
Each fault ends the motion with a clear ``ERROR: driver: ...`` and ``false``, refuses
motion meanwhile, and rob6 continues from where the robot really is. Assertions are
about positions, limits, texts, recovery and the arm's own clock (the stand-in's), never
about how fast this (shared) machine is; bench/links.py measures the timing."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from harness.client import Client
from harness.system import System, link_status, running
from rob6.robots import get_robot
from tests.controllers.adept_controller import AdeptController
from tests.motion.link_session import reply, wait_until
from tests.motion.realtime_rig import StreamedRig, driver_refusal, fmt, free_tcp_ports

pytestmark = pytest.mark.slow

ROBOT = get_robot("ad850")
START = [0.0, -60.0, 40.0, 0.0, 30.0, 0.0]
#: float32 radians on the wire, rob6 rounds what it reads to 1e-4 deg
POSITION_TOL = 2e-4


def adept_system(motion: int, state: int, order: str = "big", **kwargs: Any) -> AbstractContextManager[System]:
    return running("ad850", dummy=False, extra_env={
        "ROB6_LINK": "simple_message", "ROB6_SM_HOST": "127.0.0.1", "ROB6_SM_MOTION_PORT": str(motion),
        "ROB6_SM_STATE_PORT": str(state), "ROB6_SM_BYTE_ORDER": order}, **kwargs)


def controller(motion: int, state: int, *args: str, order: str = "big") -> AdeptController:
    return AdeptController("--motion-port", str(motion), "--state-port", str(state), *args, byte_order=order)


RIG = StreamedRig(ROBOT, START, POSITION_TOL, moving_key="in_motion")
robot_at, connected, arrived, interrupted, back_home = (RIG.robot_at, RIG.connected, RIG.arrived, RIG.interrupted,
                                                        RIG.back_home)


def session(client: Client, ctl: AdeptController) -> None:
    """PTP, LIN and Alter (EnableAdeptAlter, MoveRTJoints every 16 ms)."""
    RIG.session(client, ctl, via=[30.0, -50.0, 50.0, 10.0, 20.0, -20.0], lin_y_mm=100.0, alter="EnableAdeptAlter")


@pytest.mark.parametrize("order, monitor", [("big", "100"), ("little", "10")])
def test_ptp_lin_alter_over_simple_message_within_limits(tmp_path: Path, order: str, monitor: str) -> None:
    motion, state = free_tcp_ports(2)
    with adept_system(motion, state, order, log_dir=str(tmp_path)) as system, system.client() as client:
        waiting = f"ERROR: driver: robot not connected (waiting for simple_message at 127.0.0.1:{motion}/{state})\n"
        assert reply(client, "MovePTPJoints 10 -60 40 0 30 0") == waiting + "false\n"
        assert reply(client, "EnableAdeptAlter") == waiting + "false\n"
        assert reply(client, "MovePTPJoints 999 0 0 0 0 0") == "false\n"  # refused before the driver
        with controller(motion, state, "--monitor-speed", monitor, order=order) as ctl:
            # the opening may be a MOVE to where the arm stands, as float32 radians carry it
            assert np.allclose(connected(client, ctl, system), np.zeros(6), atol=POSITION_TOL)
            session(client, ctl)
            status = ctl.status()
            assert status["task_errors"] == 0
            assert status["points_acknowledged"] > 100
            link = link_status(system)
            assert (link.state, link.runs, link.garbage) == ("connected", 1, 0)
            assert link.packets == status["points_acknowledged"] - 1  # the opening is no point
            assert client.ask("Quit") == "bye!\n"
    RIG.assert_recorded(tmp_path, "simple_message")  # complete: the launcher stops the recorder last


@pytest.fixture(scope="module")
def adept() -> Iterator[tuple[System, int, int]]:
    """One rob6 system on simple_message for the fault tests; each test brings its own controller."""
    motion, state = free_tcp_ports(2)
    with adept_system(motion, state) as system:
        yield system, motion, state


Rig = tuple[System, AdeptController, Client]


@pytest.fixture
def rig(adept: tuple[System, int, int]) -> Iterator[Rig]:
    """A fault test's start: a controller of its own, rob6 connected to it, and a client."""
    system, motion, state = adept
    with controller(motion, state) as ctl, system.client() as client:
        connected(client, ctl, system)
        yield system, ctl, client


def test_estop_mid_motion_then_released_and_drives_on(rig: Rig) -> None:
    system, ctl, client = rig
    interrupted(client, ctl, ctl.estop, "robot reports an E-stop")
    # a MOVE waiting for the arm when the E-stop hit fails: the program's motion task ends
    errors_at_fault = ctl.status()["task_errors"]
    assert errors_at_fault <= 1
    assert reply(client, "MovePTPJoints " + fmt(START)) == "ERROR: driver: robot reports an E-stop\nfalse\n"
    assert reply(client, "EnableAdeptAlter") == "ERROR: driver: robot reports an E-stop\nfalse\n"
    ctl.release()  # the drives stay off
    wait_until(lambda: reply(client, "MovePTPJoints " + fmt(START))
               == "ERROR: driver: robot reports drives off\nfalse\n", what="drives off")
    ctl.drives(True)
    back_home(client, ctl, system)
    assert ctl.status()["task_errors"] == errors_at_fault  # nothing sent while it could not move


def test_drives_off_mid_motion(rig: Rig) -> None:
    system, ctl, client = rig
    interrupted(client, ctl, lambda: ctl.drives(False), "robot reports drives off")
    ctl.drives(True)
    back_home(client, ctl, system)


def test_motion_connection_dropped_mid_motion_and_restored(adept: tuple[System, int, int], rig: Rig) -> None:
    system, ctl, client = rig
    motion = adept[1]
    interrupted(client, ctl, lambda: ctl.drop_connection("motion"),
                f"simple_message link lost: the controller at 127.0.0.1:{motion} closed the motion connection")
    wait_until(lambda: ctl.status()["clients"]["motion"], what="rob6 to reconnect")
    back_home(client, ctl, system)  # after the points already queued ran out: no jump back
    assert link_status(system).runs >= 2


def test_state_connection_dropped_mid_motion_and_restored(adept: tuple[System, int, int], rig: Rig) -> None:
    system, ctl, client = rig
    state = adept[2]
    interrupted(client, ctl, lambda: ctl.drop_connection("state"),
                f"simple_message link lost: the controller at 127.0.0.1:{state} closed the state connection")
    back_home(client, ctl, system)


def test_slow_then_missing_acknowledgements(adept: tuple[System, int, int], rig: Rig) -> None:
    system, ctl, client = rig
    RIG.slow_then_missing_acknowledgements(
        client, ctl, system, [20.0, -50.0, 50.0, 0.0, 30.0, 10.0],
        f"simple_message link lost: no acknowledgement from the controller at 127.0.0.1:{adept[1]} for 2000 ms")


def test_simple_message_on_a_robot_other_than_the_adept_is_refused_in_one_line() -> None:
    assert driver_refusal("--robot", "kr16", "--link", "simple_message") == (
        78, "rob6-driver: --link simple_message drives the Adept Viper s850 (ad850), not kr16; use --link sim\n")
    assert driver_refusal("--robot", "kaw_fs", "--link", "adept") == (
        78, "rob6-driver: --link adept drives the Adept Viper s850 (ad850), not kaw_fs; use --link sim\n")
