"""The whole system (``rob6 run --robot kaw_fs --link kawasaki``) driving the Kawasaki controller
simulator (kawasaki-as-sim, a separate process executing deploy/kawasaki/rob6.as, over real
TCP) in PTP, LIN and Alter within every limit, final positions equal; a long PTP at a monitor speed
of 10 %; and the faults: E-stop (which the program reports as motor power off), motor power
off, teach mode and a controller error mid-motion, each followed by the operator's EXECUTE
of the robot program, the connection dropped, slow and missing acknowledgements. Each ends the motion with a clear ``ERROR: driver: ...`` and
``false``, refuses motion meanwhile, and rob6 continues from where the robot really is.
Assertions are about positions, limits, texts and recovery, never about how fast this
(shared) machine is; bench/kawasaki.py measures the timing."""

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
from tests.controllers.kawasaki_controller import KawasakiController
from tests.motion.link_session import reply, wait_until
from tests.motion.realtime_rig import StreamedRig, driver_refusal, fmt, free_tcp_ports

pytestmark = pytest.mark.slow

ROBOT = get_robot("kaw_fs")
START = [0.0, -30.0, 40.0, 0.0, 30.0, 0.0]
#: the wire carries 1e-3 deg
POSITION_TOL = 1.5e-3
#: how long a point may come late before the arm runs dry: rob6.as starts at three points,
#: but its robot program takes each point as soon as the motion before begins, so a steady
#: stream has one period (48 ms, the link's default) of slack (deploy/kawasaki/PROTOCOL.md,
#: "Rules"); the answer comes after the point is queued, so an answer later than that is late
LEAD_US = 48_000


def kawasaki_system(ports: tuple[int, int], cell: Path | None = None, **kwargs: Any) -> AbstractContextManager[System]:
    """The driver on the program's port and its state port (and the cell file ``cell``)."""
    return running("kaw_fs", dummy=False, extra_env={
        "ROB6_LINK": "kawasaki", "ROB6_KAS_HOST": "127.0.0.1", "ROB6_KAS_PORT": str(ports[0]),
        "ROB6_KAS_STATE_PORT": str(ports[1]), **({"ROB6_CELL": str(cell)} if cell else {})}, **kwargs)


def controller(ports: tuple[int, int], *args: str) -> KawasakiController:
    return KawasakiController("--port", str(ports[0]), "--state-port", str(ports[1]), *args)


RIG = StreamedRig(ROBOT, START, POSITION_TOL, moving_key="moving")
robot_at, connected, arrived, interrupted, back_home = (RIG.robot_at, RIG.connected, RIG.arrived, RIG.interrupted,
                                                        RIG.back_home)


def session(client: Client, ctl: KawasakiController) -> None:
    """PTP, LIN and Alter (EnableAlter, MoveRTJoints every 16 ms)."""
    RIG.session(client, ctl, via=[30.0, -20.0, 50.0, 10.0, 20.0, -20.0], lin_y_mm=60.0, alter="EnableAlter")


def test_ptp_lin_alter_over_the_kawasaki_link_within_limits(tmp_path: Path) -> None:
    first, second = free_tcp_ports(2)
    port = (first, second)
    with kawasaki_system(port, log_dir=str(tmp_path)) as system, system.client() as client:
        waiting = f"ERROR: driver: robot not connected (waiting for the Kawasaki AS program at 127.0.0.1:{first})\n"
        assert reply(client, "MovePTPJoints 10 -30 40 0 30 0") == waiting + "false\n"
        assert reply(client, "EnableAlter") == waiting + "false\n"
        assert reply(client, "MovePTPJoints 999 0 0 0 0 0") == "false\n"  # refused before the driver
        with controller(port) as ctl:
            assert np.array_equal(connected(client, ctl, system), np.zeros(6))
            session(client, ctl)
            status = ctl.status()
            assert set(status["answers"]) == {"0"}  # every line accepted
            assert status["answers"]["0"] > 100
            assert status["max_speed_ratio"] <= 1.0  # no axis above its rated speed, ever
            link = link_status(system)
            # the arm never ran out of points mid-path, unless this loaded machine held rob6 up
            # longer than the program's lead (one 48 ms period): an answer that late, or
            # driver cycles missed (the link counts them with the controller's underruns)
            kunder = ctl.type("kunder")
            assert kunder == 0 or link.latency_us[2] > LEAD_US or link.missed > kunder, (kunder, link)
            assert (link.state, link.runs, link.garbage) == ("connected", 1, 0)
            assert link.packets == status["answers"]["0"]
            assert client.ask("Quit") == "bye!\n"
    RIG.assert_recorded(tmp_path, "kawasaki")  # complete: the launcher stops the recorder last


#: the fault tests' cell: the floor without self-collision. The range test folds JT3 to the
#: controller's limit, where the FS03N's estimated shapes (rob6/cell/arms/REFERENCES.md) have
#: the forearm within the margin of the column: the cell's guard would refuse the path before
#: the link's own range check is reached
FLOOR_ONLY = """\
zones:
  - {name: floor, keep: out, half_space: {point: [0, 0, 0], normal: [0, 0, 1]}, ignore: [link_1]}
arm:
  self_collision: false
"""


@pytest.fixture(scope="module")
def kawasaki(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[System, tuple[int, int]]]:
    """One rob6 system on the kawasaki link for the fault tests; each test brings its own controller."""
    first, second = free_tcp_ports(2)
    port = (first, second)
    cell = tmp_path_factory.mktemp("kawasaki") / "floor-only.yaml"
    cell.write_text(FLOOR_ONLY)
    with kawasaki_system(port, cell) as system:
        yield system, port


Rig = tuple[System, KawasakiController, Client]


@pytest.fixture
def rig(kawasaki: tuple[System, tuple[int, int]]) -> Iterator[Rig]:
    """A fault test's start: a controller of its own, rob6 connected to it, and a client."""
    system, port = kawasaki
    with controller(port) as ctl, system.client() as client:
        connected(client, ctl, system)
        yield system, ctl, client


def refused(ctl: KawasakiController) -> int:
    """Lines the program answered with a code other than 0."""
    return sum(n for code, n in ctl.status()["answers"].items() if code != "0")


def test_estop_mid_motion_then_released_motor_on_and_the_program_started(rig: Rig) -> None:
    system, ctl, client = rig
    off = "ERROR: driver: robot reports motor power off\nfalse\n"  # AS cannot tell an E-stop apart
    interrupted(client, ctl, ctl.estop, "robot reports motor power off")
    assert reply(client, "MovePTPJoints " + fmt(START)) == off
    assert reply(client, "EnableAlter") == off
    ctl.release()  # the motor power stays off
    assert reply(client, "MovePTPJoints " + fmt(START)) == off
    before = refused(ctl)
    assert before <= 1  # at most the point that was on its way when the E-stop hit
    ctl.motor(True)
    ctl.execute()
    back_home(client, ctl, system)
    assert refused(ctl) == before  # nothing sent while it could not move


def test_motor_power_off_mid_motion(rig: Rig) -> None:
    system, ctl, client = rig
    interrupted(client, ctl, lambda: ctl.motor(False), "robot reports motor power off")
    ctl.motor(True)
    ctl.execute()
    back_home(client, ctl, system)


def test_teach_mode_and_a_controller_error_mid_motion(rig: Rig) -> None:
    system, ctl, client = rig
    interrupted(client, ctl, lambda: ctl.teach(True), "robot reports teach mode")
    assert reply(client, "MovePTPJoints " + fmt(START)) == "ERROR: driver: robot reports teach mode\nfalse\n"
    ctl.teach(False)
    ctl.execute()
    back_home(client, ctl, system)
    interrupted(client, ctl, lambda: ctl.error(1502), "robot reports controller error 1502")
    ctl.clear_error()
    ctl.execute()
    back_home(client, ctl, system)


NOT_RUNNING = ("robot program rob6_motion not running (start it: EXECUTE rob6_motion, "
               "or CONTINUE after a HOLD)")


def test_a_robot_program_not_started_or_held_is_a_clear_error(kawasaki: tuple[System, tuple[int, int]]) -> None:
    """rob6_motion never started (the operator typed only PCEXECUTE 1: rob6_pc): the state says
    it does not run (TASK(1)), a motion command answers that at once and no point goes out (the
    program would answer each 4 and nothing would ever drain). Started, rob6 moves; HOLD mid-motion
    is the same error; after RUN rob6 continues from where the arm stands."""
    system, port = kawasaki
    with controller(port, "--start", "PCEXECUTE 1: rob6_pc") as ctl, system.client() as client:
        wait_until(lambda: ctl.status()["client"], what="rob6 to connect")
        assert ctl.status()["tasks"].get("robot") is None
        not_running = f"ERROR: driver: {NOT_RUNNING}\nfalse\n"
        # until the first state the link says it is not connected yet; then why it cannot move
        wait_until(lambda: reply(client, "MovePTPJoints " + fmt(START)) == not_running, what="the first state")
        assert reply(client, "EnableAlter") == not_running
        assert ctl.status()["lines_received"] == 0  # not a point sent, none refused
        ctl.execute("rob6_motion")
        connected(client, ctl, system)
        interrupted(client, ctl, lambda: ctl.hold(True), NOT_RUNNING)
        assert ctl.type("TASK(1)") == 2  # held, not aborted: RUN lets it go on
        assert reply(client, "MovePTPJoints " + fmt(START)) == not_running
        ctl.hold(False)
        back_home(client, ctl, system)
        assert refused(ctl) <= 1  # at most the point on its way when HOLD came


def test_connection_dropped_mid_motion_and_restored(kawasaki: tuple[System, tuple[int, int]], rig: Rig) -> None:
    """The network drops both connections at once: the driver names the one it noticed first."""
    system, ctl, client = rig
    port, state_port = kawasaki[1]
    runs = link_status(system).runs
    RIG.long_move(client, ctl)
    assert ctl.drop_connection()
    assert client.read_lines(2, timeout=30) in (
        f"ERROR: driver: kawasaki link lost: the controller at 127.0.0.1:{port} closed the connection\nfalse\n",
        f"ERROR: driver: kawasaki link lost: the controller at 127.0.0.1:{state_port} closed the state connection"
        "\nfalse\n")
    wait_until(lambda: ctl.status()["client"], what="rob6 to reconnect")
    back_home(client, ctl, system)  # after the segment under way ran out: no jump back
    assert link_status(system).runs > runs


def test_slow_then_missing_acknowledgements(kawasaki: tuple[System, tuple[int, int]], rig: Rig) -> None:
    system, ctl, client = rig
    RIG.slow_then_missing_acknowledgements(
        client, ctl, system, [20.0, -20.0, 50.0, 0.0, 30.0, 10.0],
        f"kawasaki link lost: no acknowledgement from the controller at 127.0.0.1:{kawasaki[1][0]} for 2000 ms")


def test_a_point_outside_the_controllers_range_is_never_sent(rig: Rig) -> None:
    """rob6 allows q3 down to -150, the controller only to -120 (JT3 +120): the link stops the
    motion at the border with a clear error instead of sending the point."""
    system, ctl, client = rig
    assert reply(client, "MovePTPJoints " + fmt(START)) == "true\n"
    beyond = list(START)
    beyond[2] = -130.0
    answer = reply(client, "MovePTPJoints " + fmt(beyond))
    assert answer.startswith("ERROR: driver: refused to send a point outside the robot's range (joint 3 at -12")
    assert answer.endswith(" on the controller, outside its range -150 .. 120)\nfalse\n"), answer
    here = connected(client, ctl, system)
    assert -120.0 <= here[2] < 40.0  # stopped on the way, inside the controller's range
    status = ctl.status()
    assert refused(ctl) == 0 and status["position_ctrl_deg"][2] <= 120.0
    assert reply(client, "MovePTPJoints " + fmt(START)) == "true\n"


def test_a_long_ptp_at_a_monitor_speed_of_ten_percent(rig: Rig) -> None:
    """At 10 % every SPEED ... S segment runs ten times longer: the link must pace itself by
    the controller's queue, never have a point refused and never let the queue run dry
    mid-path; the motion arrives, slower."""
    system, ctl, client = rig
    assert reply(client, "MovePTPJoints " + fmt(START)) == "true\n"
    ctl.monitor_speed(10)
    target = list(START)
    target[0] = 60.0
    assert reply(client, "MovePTPJoints " + fmt(target), timeout=120) == "true\n"
    assert np.allclose(robot_at(ctl), target, atol=POSITION_TOL)
    assert refused(ctl) == 0 and ctl.type("kunder") == 0


def test_the_kawasaki_link_on_another_robot_is_refused_in_one_line() -> None:
    assert driver_refusal("--robot", "ad850", "--link", "kawasaki") == (
        78, "rob6-driver: --link kawasaki drives the Kawasaki FS03N (kaw_fs), not ad850; use --link sim\n")
    assert driver_refusal("--robot", "kaw_fs", "--link", "kawasaki", "--kas-port", "0") == (
        78, "rob6-driver: ROB6_KAS_PORT=0: expected a TCP port 1..65535\n")
