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

import math
from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from harness.client import Client
from harness.system import System, link_status, running
from rob6.robots import get_robot
from rob6_driver.links.simple_message import MAX_SEGMENT_DEG
from tests.controllers.adept_controller import AdeptController
from tests.motion.link_session import joints, reply, wait_until
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


# ---------------------------------------------------------------------- pacing and stops
MONITOR_SPEEDS = ("3", "10", "100")
#: the Viper's rated joint speeds (the controller's, deg/s): a MOVE at 100 %
RATED_DEG_S = np.array([250.0, 250.0, 250.0, 375.0, 375.0, 600.0])
#: the stand-in's 100 % acceleration: full speed in 0.25 s (its --accel-time), of which its
#: path uses 90 %; and its servo's last approach to a point (within 1e-3 deg)
ACCEL_DEG_S2 = 0.9 * RATED_DEG_S / 0.25
SERVO_TAIL_S = 0.1


def segment_bound_s(monitor: str) -> float:
    """The arm's time for the longest segment rob6 may send (MAX_SEGMENT_DEG on every joint,
    whatever limits a client set), at its rated speeds stretched by the monitor speed."""
    return float(np.max(MAX_SEGMENT_DEG / RATED_DEG_S)) / (float(monitor) / 100)


def run_on_bound(monitor: str) -> tuple[float, float]:
    """How far (deg, J1) and how long (s) the arm may run after rob6's last word: the three
    MOVEs the program may hold (running, planned, the one its task is in), from rest to rest
    at the worst, every part of it stretched by the monitor speed (time scaling): the
    distance the same at every monitor speed."""
    distance = 3 * float(MAX_SEGMENT_DEG[0])
    at_100 = 2 * math.sqrt(distance / float(ACCEL_DEG_S2[0])) + SERVO_TAIL_S
    return distance, at_100 / (float(monitor) / 100)


def assert_stopped_within_bound(ctl: AdeptController, client: Client, monitor: str) -> None:
    """The arm at rest where rob6's setpoint rests; after rob6's last point it ran on at most
    three of the longest segments, in degrees at any monitor speed and in their time at this
    one; no segment longer than the link's bound."""
    # at rest where rob6 rests (at 100 % the arm also rests at points between rob6's late ones)
    st = ctl.wait_for(lambda s: not s["in_motion"] and np.allclose(s["position_rob6_deg"], joints(client),
                                                                     atol=POSITION_TOL),
                      timeout=60, what="the arm at rest where rob6's setpoint rests")
    assert np.all(np.array(st["longest_segment_deg"]) <= MAX_SEGMENT_DEG + 1e-3), st["longest_segment_deg"]
    distance, seconds = run_on_bound(monitor)
    assert st["ran_on_deg"] <= distance + 1e-3, (st["ran_on_deg"], distance)
    assert st["ran_on_s"] <= seconds, (st["ran_on_s"], seconds)
    assert st["task_errors"] == 0


@pytest.fixture(params=MONITOR_SPEEDS)
def paced(request: pytest.FixtureRequest, adept: tuple[System, int, int]) -> Iterator[tuple[Rig, str]]:
    """A controller at a monitor speed of its own, rob6 connected to it at full speed (SetAdeptSpeed 100)."""
    system, motion, state = adept
    monitor: str = request.param
    with controller(motion, state, "--monitor-speed", monitor) as ctl, system.client() as client:
        connected(client, ctl, system)
        assert client.ask("SetAdeptSpeed 100") == "true\n"
        assert reply(client, "MovePTPJoints " + fmt(START), timeout=120) == "true\n"
        yield (system, ctl, client), monitor


def test_a_long_ptp_arrives_at_every_monitor_speed(paced: tuple[Rig, str]) -> None:
    """The arm slower or faster than rob6's plan: the link paces the core by the controller's
    acknowledgements, so the move arrives (true) without a lost link or a false timeout (the
    answers may take longer than the deadline while the arm moves), and no segment is longer
    than its bound."""
    (system, ctl, client), monitor = paced
    runs = link_status(system).runs
    target = [60.0, -40.0, 60.0, 20.0, 40.0, 30.0]
    assert reply(client, "MovePTPJoints " + fmt(target), timeout=180) == "true\n"
    st = ctl.status()
    assert np.allclose(st["position_rob6_deg"], target, atol=POSITION_TOL) and not st["in_motion"]
    assert st["longest_segment_s"] <= segment_bound_s(monitor) + 1e-6, (st["longest_segment_s"], monitor)
    assert np.all(np.array(st["longest_segment_deg"]) <= MAX_SEGMENT_DEG + 1e-3), st["longest_segment_deg"]
    assert st["task_errors"] == 0
    link = link_status(system)
    assert (link.state, link.runs) == ("connected", runs)
    assert reply(client, "MovePTPJoints " + fmt(START), timeout=180) == "true\n"


def test_a_vanished_client_brings_the_arm_to_rest_within_the_bound(paced: tuple[Rig, str]) -> None:
    (system, ctl, client), monitor = paced
    target = list(START)
    target[0] = 40.0
    client.send("MovePTPJoints " + fmt(target) + "\n")
    ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 10.0, timeout=60, what="the arm under way")
    client.close()  # the client has gone: its session ends, the driver stops the arm
    with system.client() as after:
        assert_stopped_within_bound(ctl, after, monitor)
        assert 10.0 < ctl.status()["position_rob6_deg"][0] < 40.0
        assert reply(after, "MovePTPJoints " + fmt(START), timeout=120) == "true\n"


def test_an_old_clients_stop_brings_the_arm_to_rest_within_the_bound(paced: tuple[Rig, str]) -> None:
    """DisableAlter mid-motion: answered true once the arm itself is at rest."""
    (system, ctl, client), monitor = paced
    assert client.ask("EnableAdeptAlter") == "true\n"
    target = list(START)
    target[0] = 40.0
    # the target again and again, as an Alter client does (else the watchdog stops the arm)
    wait_until(lambda: reply(client, "MoveRTJoints " + fmt(target)) == "true\n"
               and ctl.status()["position_rob6_deg"][0] > 10.0, timeout=60, what="the arm under way")
    assert reply(client, "DisableAlter", timeout=120) == "true\n"
    assert not ctl.status()["in_motion"]  # true only with the arm at rest
    assert_stopped_within_bound(ctl, client, monitor)
    assert 10.0 < ctl.status()["position_rob6_deg"][0] < 40.0
    assert reply(client, "MovePTPJoints " + fmt(START), timeout=120) == "true\n"


def test_raised_speed_limits_keep_segments_and_the_run_on_in_degrees(adept: tuple[System, int, int]) -> None:
    """SetJointsMaxSpeed and SetJointsMaxAcceleration at the protocol's bounds: rob6's core may
    move many times as far per period, yet no MOVE goes farther than MAX_SEGMENT_DEG, and a client
    that vanishes leaves the arm no farther to run than at the defaults."""
    system, motion, state = adept
    with controller(motion, state) as ctl, system.client() as client:
        connected(client, ctl, system)
        assert client.ask("SetAdeptSpeed 100") == "true\n"
        assert client.ask("SetJointsMaxSpeed " + fmt(list(ROBOT.speed_bound))) == "true\n"
        assert client.ask("SetJointsMaxAcceleration " + fmt([ROBOT.max_accel_bound] * 6)) == "true\n"
        try:
            assert reply(client, "MovePTPJoints " + fmt(START), timeout=60) == "true\n"
            target = list(START)
            target[0] = 80.0
            client.send("MovePTPJoints " + fmt(target) + "\n")
            ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 20.0, timeout=60, what="the arm under way")
        finally:
            client.close()
        with system.client() as after:
            assert_stopped_within_bound(ctl, after, "100")
            assert reply(after, "MovePTPJoints " + fmt(START), timeout=60) == "true\n"


def test_a_long_ptp_at_monitor_speed_1_arrives_with_no_false_link_lost(adept: tuple[System, int, int]) -> None:
    """At 1 % a single MOVE of a segment lasts seconds, and so does the answer to the point
    after it: longer than the 2 s deadline. The state port shows the arm moving all along,
    so the link waits: the PTP arrives on the same connection."""
    system, motion, state = adept
    with controller(motion, state, "--monitor-speed", "1") as ctl, system.client() as client:
        connected(client, ctl, system)
        assert client.ask("SetAdeptSpeed 100") == "true\n"
        runs = link_status(system).runs
        target = [12.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        assert reply(client, "MovePTPJoints " + fmt(target), timeout=180) == "true\n"
        st = ctl.status()
        assert np.allclose(st["position_rob6_deg"], target, atol=POSITION_TOL) and not st["in_motion"]
        assert st["ack_latency_ms"]["max"] > 2000  # answers did come later than the deadline
        assert st["task_errors"] == 0
        link = link_status(system)
        assert (link.state, link.runs) == ("connected", runs)


def test_lowering_the_monitor_speed_mid_stream_is_no_lost_link(adept: tuple[System, int, int]) -> None:
    """The operator turns the monitor speed from 100 % down to 1 % while a PTP streams (V+:
    it takes effect at once): the answers slow down with the arm, the link waits while it
    moves, and the PTP arrives."""
    system, motion, state = adept
    with controller(motion, state) as ctl, system.client() as client:
        connected(client, ctl, system)
        assert client.ask("SetAdeptSpeed 100") == "true\n"
        runs = link_status(system).runs
        target = [20.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        client.send("MovePTPJoints " + fmt(target) + "\n")
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 4.0, timeout=30, what="the arm under way")
        ctl.monitor_speed(1)
        assert client.read_lines(1, timeout=180) == "true\n"
        st = ctl.status()
        assert np.allclose(st["position_rob6_deg"], target, atol=POSITION_TOL) and not st["in_motion"]
        assert st["ack_latency_ms"]["max"] > 2000 and st["task_errors"] == 0
        link = link_status(system)
        assert (link.state, link.runs) == ("connected", runs)


def test_a_reconnect_mid_motion_at_3_percent_never_moves_the_arm_backwards(adept: tuple[System, int, int]) -> None:
    """The motion connection dropped while the arm runs out its MOVEs at 3 %, V+ discarding
    the client's first four bytes (``--connect-read client``: then the opening is a MOVE to
    where it says the arm is). rob6 sends the opening only once the arm is at rest, with its
    latest position: the arm never turns back."""
    system, motion, state = adept
    with controller(motion, state, "--monitor-speed", "3", "--connect-read", "client",
                    "--restart-s", "0.1") as ctl, system.client() as client:
        connected(client, ctl, system)
        assert client.ask("SetAdeptSpeed 100") == "true\n"  # segments of MAX_SEGMENT_DEG: the arm at speed
        client.send("MovePTPJoints " + fmt([30.0, 0.0, 0.0, 0.0, 0.0, 0.0]) + "\n")
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 1.0, timeout=60, what="the arm under way")
        assert ctl.drop_connection("motion")
        assert client.read_lines(2, timeout=60)[-6:] == "false\n"
        furthest = -math.inf
        def settled() -> bool:
            nonlocal furthest
            st = ctl.status()
            j1 = st["position_rob6_deg"][0]
            assert j1 >= furthest - POSITION_TOL, f"J1 went back from {furthest} to {j1}"
            furthest = max(furthest, j1)
            return bool(st["clients"]["motion"] and not st["in_motion"] and st["points_received"] > 0)
        wait_until(settled, timeout=120, what="rob6 reconnected, the arm at rest")
        here = connected(client, ctl, system)
        assert here[0] == pytest.approx(furthest, abs=POSITION_TOL)
        for _ in range(20):  # and it stays there
            settled()
        assert ctl.status()["task_errors"] == 0
