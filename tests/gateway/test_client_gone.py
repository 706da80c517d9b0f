"""A client gone mid-move (issue 24): on ad850 in real time at SetAdeptSpeed 5, a client
that disconnects during a long MovePTPJoints no longer holds the server for the rest of
the move: the next client is accepted at once, the arm stops with its ramp (within the
limits) and the recording has the session's close event saying why. Real processes,
real Zenoh, the recorder writing MCAP."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from harness.client import Client
from harness.system import running
from rob6.robots import get_robot
from rob6_recorder.reader import read_records
from tests.motion.test_realtime_system import assert_within_limits, joint_states

TARGET = "MovePTPJoints 60 0 0 0 0 0"  # A1 60 deg at 5 % speed: ~50 s


def _accepted(port: int, within: float) -> tuple[Client, float]:
    """A client that got the greeting (not ``server busy``), and how long that took."""
    began = time.monotonic()
    while True:
        client = Client(port, handshake=False)
        if client.greeting.startswith("welcome"):
            return client, time.monotonic() - began
        client.close()
        assert time.monotonic() - began < within, f"still refused: {client.greeting!r}"
        time.sleep(0.02)


def _close_events(directory: Path) -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = []
    for path in directory.glob("*.mcap"):
        events += [r.data for r in read_records(path) if r.topic.endswith("/event") and r.data.get("event") == "close"]
    return events


def _recorded_at_zero_and_closed(directory: Path, timeout: float = 20.0) -> None:
    """Until the recorder has written the arm at rest at zero and the first session's close
    event (the traces reach it in batches, a little after the replies)."""
    deadline = time.monotonic() + timeout
    while True:
        _, q = joint_states(directory)
        if len(q) and np.isclose(q[-1], 0.0, atol=1e-6).all() and \
                any(e.get("session") == 1 for e in _close_events(directory)):
            return
        assert time.monotonic() < deadline, f"the recording lacks the final state or the close event after {timeout} s"
        time.sleep(0.2)


def test_client_gone_mid_move_frees_the_server_and_stops_the_arm(tmp_path: Path) -> None:
    robot = get_robot("ad850")
    with running("ad850", dummy=False, log_dir=str(tmp_path)) as system:
        with system.client(timeout=30) as client:
            assert client.ask("SetAdeptSpeed 5") == "true\n"
            client.send(TARGET + "\n")
            time.sleep(1.5)  # moving
        # the move has ~45 s to go: the server used to refuse everyone until it ended
        again, waited = _accepted(system.port, within=10.0)
        with again:
            assert again.ask("Hello Robot") == "accepted\n"
            # its first command waits for the stop: the arm is at rest, short of the target
            first = [float(x) for x in again.ask("GetPositionJoints", timeout=30).split()]
            time.sleep(0.5)
            assert [float(x) for x in again.ask("GetPositionJoints").split()] == first, "still moving"
            assert 0.1 < first[0] < 30.0, f"A1 at {first[0]}: it did not stop"
            assert again.ask("SetAdeptSpeed 100") == "true\n"
            assert again.ask("MovePTPJoints 0 0 0 0 0 0", timeout=30) == "true\n"  # the next move works
        _recorded_at_zero_and_closed(tmp_path)
    print(f"accepted {waited:.2f} s after the client left")
    t, q = joint_states(tmp_path)
    assert assert_within_limits(robot, t, q) > 0  # the stop ramp too: within speed and acceleration
    closes = [e for e in _close_events(tmp_path) if e.get("session") == 1]
    assert closes and closes[0]["reason"] == "the client left during MovePTPJoints: the robot stops", closes
    assert np.isclose(q[-1], 0.0, atol=1e-6).all()
