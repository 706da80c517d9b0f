"""rob6_client against a running rob6 system: a whole lab session, blocking and asyncio."""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Iterator, Sequence
from typing import Any

import msgspec
import pytest

from harness.system import System, running
from rob6.cell import default_cell
from rob6.messages import Cell, Zone
from rob6.robots import get_robot
from rob6_client import COMMANDS, AsyncRobot, Rob6ConnectionError, Rob6Error, Rob6Timeout, Robot

Q = (10.0, -60.0, 80.0, 20.0, 40.0, 30.0)  # kr16, noflip up lefty
KR16_SPEED = (0.1872, 0.1872, 0.1872, 0.396, 0.396, 0.738)


@pytest.fixture(scope="module")
def kr16() -> Iterator[System]:
    # Shutdown refused, as on a shared lab server: a rob6-only ERROR without `false`
    with running("kr16", dummy=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        yield system


def is_default_cell(cell: dict[str, Any], robot: str) -> bool:
    """GetCell's dict without ROB6_CELL: the default cell, with every field, defaults included
    (a client needs no knowledge of them), and the pairs not measured, each with why."""
    served = msgspec.convert(cell, Cell)  # with the pairs the driver does not measure, and why
    return (msgspec.structs.replace(served, unchecked=[]) == default_cell(get_robot(robot))
            and bool(served.unchecked) and all(": " in line for line in served.unchecked)
            and set(cell) == set(Cell.__struct_fields__) and cell["source"] == f"default {robot}"
            and all(set(zone) == set(Zone.__struct_fields__) for zone in cell["zones"]))


def close_to(a: Sequence[float] | None, b: Sequence[float], tol: float = 1e-3) -> bool:
    return a is not None and len(a) == len(b) and all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def stream(robot: Robot, start: Sequence[float], count: int, rate_hz: float = 250.0) -> None:
    """MoveRTJoints targets paced at ``rate_hz``, A1 advancing 0.02 deg each."""
    began = time.monotonic()
    for k in range(1, count + 1):
        assert robot.move_rt_joints([start[0] + 0.02 * k, *start[1:]]) is True
        time.sleep(max(0.0, began + k / rate_hz - time.monotonic()))


def test_lab_session(kr16: System) -> None:
    with Robot("127.0.0.1", kr16.port) as robot:
        assert robot.greeting == "welcome to rob6server 0.1.01 !"
        assert (robot.get_robot(), robot.get_version(), robot.cm_ping()) == ("kr16", "0.1.01", "PONG")
        assert robot.is_kuka() and robot.is_kr16() and not robot.is_adept()
        assert abs(robot.get_timestamp() - time.time()) < 5

        # FK / IK round trip
        fk = robot.forward_calc(Q)
        assert fk is not None
        pose, status = fk
        assert status == ("noflip", "up", "lefty")
        assert close_to(robot.backward_calc(pose, status), Q)
        assert close_to(robot.get_joints_row_wise(pose.rows, "noflip up lefty"), Q)
        assert robot.is_possible(pose, status) is True
        far = list(pose)
        far[3] = 5000.0
        assert robot.backward_calc(far, status) is None and robot.is_possible(far, status) is False
        assert robot.forward_calc([0, 20, 0, 0, 0, 0]) is None  # J2 exactly at its limit: strict

        # limits: get, set, refuse, reset
        assert robot.get_joints_max_speed() == KR16_SPEED
        assert robot.set_joints_max_speed([0.1] * 6) is True
        assert robot.set_single_joint_max_speed(1, 0.15) is True
        assert robot.get_joints_max_speed() == (0.15, 0.1, 0.1, 0.1, 0.1, 0.1)
        assert robot.set_single_joint_max_speed(1, 2.0) is False  # above 10x the default
        assert robot.set_single_joint_max_speed(7, 0.1) is False
        assert robot.reset_joints_max_speed() is True and robot.get_joints_max_speed() == KR16_SPEED
        assert robot.set_single_joint_max_turn_max(1, 5.0) is True
        assert robot.get_joints_max_turn_max()[0] == 5.0
        assert robot.move_ptp_joints(Q) is False  # A1 = 10 beyond the new limit
        assert robot.reset_joints_max_turn() is True and robot.get_joints_max_turn_max()[0] == 185.0
        assert robot.get_min_change_weights() == (4.0, 1.0, 1.0, 1.0, 1.0, 1.0)
        assert robot.set_rt_speed_control(2) is False and robot.get_rt_speed_control() == 1

        # point-to-point moves and the position read back
        assert robot.move_ptp_joints(Q) is True
        assert robot.get_position_joints() == Q
        assert close_to(robot.get_position_hom_row_wise(), pose, 1e-5)
        assert robot.get_status() == status
        assert robot.set_joints_max_change([10] * 6) is True
        assert robot.move_ptp_joints([20.5, *Q[1:]]) is False  # 10.5 deg > max change
        assert robot.reset_joints_max_change() is True
        robot.set_allowed_status("righty")  # no answer on success (raises Rob6Error if refused)
        assert robot.get_allowed_status() == ("toggleHand", "toggleElbow", "righty")
        assert robot.move_ptp_joints([0, -60, 80, 20, 40, 30]) is False  # a lefty pose
        assert robot.reset_allowed_status() is True
        fk = robot.forward_calc([0, -60, 80, 20, 40, 30])
        assert fk is not None
        target, _ = fk
        assert robot.move_ptp_hom_row_wise(target) is True
        assert close_to(robot.get_position_hom_row_wise(), target)

        # route test: a virtual position, real moves refused meanwhile
        real = robot.get_position_joints()
        assert robot.enable_routetest() is True and robot.enable_routetest() is False
        assert robot.routetest_joints(Q) is True and robot.get_position_joints() == Q
        assert robot.move_ptp_joints(Q) is False
        assert robot.disable_routetest() is True and robot.get_position_joints() == real

        # Alter mode: a few targets at 250 Hz; leaving the block ends the mode
        assert robot.move_ptp_joints(Q) is True
        with robot.alter():
            stream(robot, Q, 25)
            assert robot.move_ptp_joints(Q) is False  # no PTP while Alter is on
        assert robot.move_rt_joints(Q) is False
        with pytest.raises(ZeroDivisionError), robot.alter():
            assert robot.do_alter_joint([0.1, 0, 0, 0, 0, 0]) is True
            raise ZeroDivisionError
        assert robot.move_rt_joints(Q) is False  # disabled on the way out
        time.sleep(0.3)
        assert robot.move_ptp_joints(Q) is True

        # rob6's own: the cell every motion is checked against (the default one), as a dict
        cell = robot.get_cell()
        assert is_default_cell(cell, "kr16") and cell["zones"][0]["name"] == "floor", cell
        assert robot.get_status() == ("noflip", "up", "lefty")  # unchanged beside it
        with pytest.raises(Rob6Error) as refused:  # the reason, not a bare False
            robot.move_ptp_joints([0, 10, 110, 0, 60, 0])  # the flange below the floor
        assert refused.value.message.startswith("path enters keep-out 'floor' at "), refused.value.message
        assert robot.get_position_joints() == Q  # nothing moved

        # ERROR replies are exceptions and the session goes on
        with pytest.raises(Rob6Error) as caught:
            robot.shutdown()
        assert caught.value.message.startswith("Shutdown is disabled")
        with pytest.raises(Rob6Error, match="incorrect joints"):  # what a hand-rolled client could send
            robot._call(COMMANDS["MovePTPJoints"], "MovePTPJoints 1 2 3", None)
        assert robot.get_robot() == "kr16"
        with pytest.raises(Rob6ConnectionError, match="server busy"):
            Robot("127.0.0.1", kr16.port)  # one client at a time
    assert not robot.connected


def test_timeout_closes_the_session_and_a_new_one_starts(kr16: System) -> None:
    robot = Robot("127.0.0.1", kr16.port)
    with pytest.raises(Rob6Timeout):
        robot.ping_robot(40, 25, timeout=0.2)  # ~1 s of pings
    assert not robot.connected
    deadline = time.monotonic() + 10
    while True:  # the gateway finishes the pings before it takes the next client
        try:
            with Robot("127.0.0.1", kr16.port) as robot:
                ping = robot.ping_robot(3, 1)
                assert ping is not None and ping.mean_rtt < 0.5
                return
        except Rob6ConnectionError:
            assert time.monotonic() < deadline
            time.sleep(0.1)


def test_asyncio_twin(kr16: System) -> None:
    async def session() -> None:
        async with AsyncRobot("127.0.0.1", kr16.port) as robot:
            assert await robot.get_robot() == "kr16"
            fk = await robot.forward_calc(Q)
            assert fk is not None
            pose, status = fk
            assert close_to(await robot.backward_calc(pose, status), Q)
            assert await robot.move_ptp_joints(Q) is True
            assert await robot.get_position_joints() == Q
            async with robot.alter():
                for k in range(1, 11):
                    assert await robot.move_rt_joints([Q[0] + 0.02 * k, *Q[1:]]) is True
                    await asyncio.sleep(0.004)
            assert await robot.move_rt_joints(Q) is False
            with pytest.raises(Rob6Error, match="Shutdown is disabled"):
                await robot.shutdown()
            # calls from several tasks are serialised: each gets its own reply
            results = await asyncio.gather(*(robot.forward_calc([k, 0, 0, 0, 0, 0]) for k in range(5)),
                                           robot.get_robot())
            assert all(isinstance(fk, tuple) and abs(fk[0].r12 + math.sin(math.radians(k))) < 1e-5
                       for k, fk in enumerate(results[:5]))
            assert results[5] == "kr16"
            assert is_default_cell(await robot.get_cell(), "kr16")
            with pytest.raises(Rob6Timeout):
                await robot.ping_robot(40, 25, timeout=0.2)
            assert not robot.connected
    asyncio.run(session())


def test_ad850_gripper_and_adept_commands() -> None:
    with running("ad850", dummy=True) as system, Robot("127.0.0.1", system.port) as robot:
        assert robot.is_adept() and robot.has_gripper() is True
        assert robot.gripper_go_home() is True
        assert robot.gripper_move(-1) is True  # after its "Start moving with amperage" line
        assert robot.gripper_move_to_position(0.02) is True
        assert robot.cm_ping() == "PONG"  # in step after the multi-line replies
        with pytest.raises(Rob6Error, match="DirectAdeptCmd is disabled"):
            robot.direct_adept_cmd("jmove 0,0,0,0,0")
        assert robot.set_adept_speed(50) is True and robot.set_adept_accel(80, 60) is True
        with robot.alter(adept=True):
            assert robot.move_rt_joints([1, 0, 0, 0, 0, 0]) is True
        assert robot.move_rt_joints([1, 0, 0, 0, 0, 0]) is False
