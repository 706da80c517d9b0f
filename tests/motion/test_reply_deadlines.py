"""Replies that wait for the arm are bounded by what they wait for, not by the 200 ms
quick-call deadline (rob6.deadlines; issue 24): DisableAlter in the middle of an Alter
stream answers ``true`` once the arm is at rest, from a raw client and from the client
library, and the next point-to-point move works, starting from where the arm came to
rest (the reply carries that state: the gateway's published copy lags). Real processes,
real Zenoh, kr16rt and the kr16 dummy."""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Iterator

import pytest

from harness.client import Client
from harness.system import System, running
from rob6_client import Robot

START = [0.0, -10.0, 10.0, 0.0, 30.0, 0.0]
READ_S = 30.0  # a reply later than this is a hang, whatever the machine's load


@pytest.fixture(scope="module")
def kr16rt() -> Iterator[System]:
    with running("kr16rt", dummy=False) as system:
        yield system


def _joints(values: Iterable[float]) -> str:
    return " ".join(f"{v:f}" for v in values)


def _position(client: Client) -> list[float]:
    return [float(x) for x in client.ask("GetPositionJoints").split()]


def _sine(k: int) -> list[float]:
    """Step ``k`` of one second at 250 Hz: A1 follows a 2 deg sine, one period. At its end
    A1 moves at its fastest, so the stop ramp takes longer than the quick-call deadline."""
    target = list(START)
    target[0] += 2.0 * math.sin(2 * math.pi * k / 250)
    return target


def test_disable_alter_mid_stream_answers_true_at_rest_and_the_next_ptp_works(kr16rt: System) -> None:
    with kr16rt.client(timeout=READ_S) as client:
        assert client.ask("MovePTPJoints " + _joints(START)) == "true\n"
        assert client.ask("EnableAlter") == "true\n"
        for k in range(1, 251):
            assert client.ask("MoveRTJoints " + _joints(_sine(k))) == "true\n", k
            time.sleep(0.004)  # a send-and-wait client streaming at up to 250 Hz
        assert client.ask("DisableAlter") == "true\n"
        first = _position(client)
        time.sleep(0.3)
        assert _position(client) == first, "DisableAlter answered before the arm was at rest"
        assert client.ask("MoveRTJoints " + _joints(first)) == "false\n"  # Alter is off
        assert client.ask("MovePTPJoints " + _joints(START)) == "true\n"
        assert _position(client) == START


def test_client_library_alter_block_ends_with_the_arm_at_rest(kr16rt: System) -> None:
    with Robot("127.0.0.1", kr16rt.port, timeout=READ_S) as robot:
        assert robot.move_ptp_joints(START)
        with robot.alter():  # DisableAlter on exit: raised Rob6Error before the fix
            for k in range(1, 251):  # 0.01 deg steps
                assert robot.move_rt_joints([START[0] + 0.01 * k, *START[1:]]) is True, k
        assert robot.move_ptp_joints(START)
        with robot.alter():  # the same, leaving while A1 moves at its fastest
            for k in range(1, 251):
                assert robot.move_rt_joints(_sine(k)) is True, k
                time.sleep(0.004)  # a send-and-wait client streaming at up to 250 Hz
        assert robot.move_ptp_joints(START)
        assert list(robot.get_position_joints()) == START


def test_the_move_after_an_alter_stream_starts_where_the_stream_left_the_arm() -> None:
    """A dummy arm follows each target at once; as fast as the client sends, DisableAlter,
    and at once the position is the last target and a PTP runs from there. Before
    DisableAlter carried the state at rest, the gateway sent the planner its last
    published state as the start, and the driver refused the PTP (``false``)."""
    with running("kr16", dummy=True) as system, system.client(timeout=READ_S) as client:
        for stream in range(5):
            assert client.ask("MovePTPJoints " + _joints(START)) == "true\n"
            assert client.ask("EnableAlter") == "true\n"
            last = START
            for k in range(1, 101):
                last = [START[0] + 0.01 * k, *START[1:]]
                assert client.ask("MoveRTJoints " + _joints(last)) == "true\n", (stream, k)
            assert client.ask("DisableAlter") == "true\n"
            assert _position(client) == last, stream
            assert client.ask("MovePTPJoints " + _joints(START)) == "true\n", stream
