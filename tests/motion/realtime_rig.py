"""Test helper: the setup the real-time link tests share (the whole system on a link, a
controller simulator as its plant): free ports, the driver's link status, the recorded
joint states, and, for the links that stream points (Adept, Kawasaki), following the
robot, moving it away and back, and a PTP/LIN/Alter session."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from harness.ports import free_port
from harness.system import System, link_status
from rob6.robots import RobotModel
from rob6_recorder.reader import read_records
from tests.controllers.sim_process import PointsControllerProcess, SimProcess, Status
from tests.motion.link_session import joints, reply, wait_until
from tests.motion.test_realtime_system import assert_within_limits

Joints = npt.NDArray[np.float64]


def free_tcp_ports(n: int) -> list[int]:
    """``n`` distinct TCP ports nothing listens on, below the ephemeral range (``TEST_PORTS``):
    a port of that range can be taken meanwhile as a connection's own port, even by rob6's
    link connecting to it while nothing listens there (a TCP self-connect)."""
    ports: list[int] = []
    while len(ports) < n:
        if (port := free_port()) not in ports:
            ports.append(port)
    return ports


def recorded_states(directory: Path, connected_only: bool = False) -> tuple[Joints, Joints]:
    """(t, q) of every cycle the recorder wrote to ``directory`` (``connected_only``: while
    the robot was connected; waiting or lost, the driver repeats its last state a few
    times a second)."""
    rows: dict[int, tuple[float, list[float]]] = {}
    for path in directory.glob("*_system_*.mcap"):
        for r in read_records(path, ["/driver/joint_state"]):
            if not connected_only or r.data.get("link", "connected") == "connected":
                rows[r.data["cycle"]] = (r.data["t"], r.data["q"])
    cycles = sorted(rows)
    return np.array([rows[c][0] for c in cycles]), np.array([rows[c][1] for c in cycles])


def fmt(q: Sequence[float] | Joints) -> str:
    return " ".join(f"{x:f}" for x in q)


def driver_refusal(*args: str) -> tuple[int, str]:
    """(exit status, stderr) of ``python -m rob6_driver`` with ``args``: a setting it refuses."""
    result = subprocess.run([sys.executable, "-m", "rob6_driver", *args],
                            capture_output=True, check=False, text=True, timeout=60)
    return result.returncode, result.stderr


@dataclass(frozen=True)
class StreamedRig:
    """A robot whose link streams points to a controller simulator: where it starts, how
    exactly its position comes back over the wire, and the status key that says it moves."""

    robot: RobotModel
    start: list[float]
    tol: float
    moving_key: str

    def robot_at(self, ctl: SimProcess) -> Joints:
        return np.array(ctl.status()["position_rob6_deg"])

    def connected(self, client: Any, ctl: SimProcess, system: System) -> Joints:
        """Wait until rob6 can move the robot again and follows it: a motion to where the robot
        stands is accepted (it sends nothing), and rob6's position is the robot's."""
        def ready() -> Joints | None:
            here = self.robot_at(ctl)
            if reply(client, "MovePTPJoints " + fmt(here)) != "true\n":
                return None
            q = joints(client)
            return q if np.allclose(q, self.robot_at(ctl), atol=self.tol) else None
        q: Joints = wait_until(ready, what="rob6 to follow the controller")
        assert link_status(system).state == "connected"
        return q

    def arrived(self, ctl: SimProcess, target: Sequence[float] | Joints) -> Status:
        """The controller at rest on target (rob6's degrees)."""
        return ctl.wait_for(lambda st: not st[self.moving_key] and np.allclose(st["position_rob6_deg"], target,
                                                                               atol=self.tol),
                            timeout=20, what=f"the robot at {target}")

    def long_move(self, client: Any, ctl: SimProcess) -> None:
        """Start a PTP of a few seconds (J1 0 -> 60) without waiting for its reply."""
        assert reply(client, "MovePTPJoints " + fmt(self.start)) == "true\n"
        target = list(self.start)
        target[0] = 60.0
        client.send("MovePTPJoints " + fmt(target) + "\n")
        wait_until(lambda: float(self.robot_at(ctl)[0]) > 5.0, what="the robot to move")

    def interrupted(self, client: Any, ctl: SimProcess, fault: Callable[[], bool | None], error: str) -> None:
        """``long_move``, then ``fault`` on the controller (False: it could not be done) ends the
        move with ``ERROR: driver: {error}`` and ``false``."""
        self.long_move(client, ctl)
        assert fault() is not False
        assert client.read_lines(2, timeout=30) == f"ERROR: driver: {error}\nfalse\n"

    def back_home(self, client: Any, ctl: SimProcess, system: System) -> None:
        """After a fault in ``long_move``: rob6 continues from where the robot stopped, home."""
        here = self.connected(client, ctl, system)
        assert 5.0 < here[0] < 60.0  # where the fault caught it: rob6 continues from there
        assert reply(client, "MovePTPJoints " + fmt(self.start)) == "true\n"
        assert np.allclose(self.robot_at(ctl), self.start, atol=self.tol)

    def slow_then_missing_acknowledgements(self, client: Any, ctl: PointsControllerProcess, system: System,
                                           target: list[float], lost: str) -> None:
        """Acknowledgements three points late: what rob6 makes meanwhile goes as one point and
        the PTP to ``target`` arrives; beyond rob6's 2 s: the next PTP ends with ``ERROR:
        driver: {lost}`` and ``false``; once they come in time again, rob6 moves again."""
        assert reply(client, "MovePTPJoints " + fmt(self.start)) == "true\n"
        merged = link_status(system).late
        ctl.slow_ack(150)
        assert reply(client, "MovePTPJoints " + fmt(target)) == "true\n"
        assert np.allclose(self.robot_at(ctl), target, atol=self.tol)
        assert link_status(system).late > merged
        ctl.slow_ack(3000)
        client.send("MovePTPJoints " + fmt(self.start) + "\n")
        assert client.read_lines(2, timeout=30) == f"ERROR: driver: {lost}\nfalse\n"
        ctl.slow_ack(0)
        self.connected(client, ctl, system)
        assert reply(client, "MovePTPJoints " + fmt(self.start)) == "true\n"
        assert np.allclose(self.robot_at(ctl), self.start, atol=self.tol)

    def session(self, client: Any, ctl: SimProcess, *, via: list[float], lin_y_mm: float, alter: str) -> None:
        """PTP start -> via -> start, LIN ``lin_y_mm`` along y, and Alter (``alter``, then
        MoveRTJoints every cycle): each motion true only with the robot there."""
        for ptp_target in (self.start, via, self.start):
            assert reply(client, "MovePTPJoints " + fmt(ptp_target)) == "true\n"
            assert np.allclose(self.robot_at(ctl), ptp_target, atol=self.tol)  # true: the robot is there
        assert client.ask("GetPositionJoints") == fmt(self.start) + "\n"
        pose = [float(x) for x in client.ask("GetPositionHomRowWise").split()]
        pose[7] += lin_y_mm  # along y, a straight line
        assert client.ask("EnableLin") == "true\n"
        assert reply(client, "MoveLINHomRowWise " + fmt(pose)) == "true\n"
        assert np.allclose([float(x) for x in client.ask("GetPositionHomRowWise").split()], pose, atol=1e-3)
        assert np.allclose(self.robot_at(ctl), joints(client), atol=self.tol)
        assert client.ask("DisableLin") == "true\n"
        assert client.ask(alter) == "true\n"
        here = joints(client)
        cycle_s = self.robot.cycle_s
        began = time.monotonic()
        for k in range(250):
            target = here.copy()
            target[0] += 3.0 * np.sin(2 * np.pi * 0.5 * k * cycle_s)
            assert reply(client, "MoveRTJoints " + fmt(target)) == "true\n"
            # pace the targets at the controller cycle like an Alter client does; a late one only
            # makes the motion slower, never changes what is asserted
            delay = began + (k + 1) * cycle_s - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        final = here.copy()
        final[0] += 2.0
        assert reply(client, "MoveRTJoints " + fmt(final)) == "true\n"
        self.arrived(ctl, final)
        assert np.allclose(joints(client), final, atol=1e-6)
        assert client.ask("DisableAlter") == "true\n"

    def assert_recorded(self, directory: Path, link: str) -> None:
        """What the recorder wrote to ``directory`` of a system that ran ``session`` on ``link``:
        rob6's setpoints, every cycle of a motion (at rest fewer), the controller connected or
        not, within every limit; the link's events from waiting to connected."""
        t, q = recorded_states(directory)
        assert assert_within_limits(self.robot, t, q) > 250  # the Alter part alone: 250 targets, one per cycle
        events = [r.data for path in directory.glob("*_system_*.mcap") for r in read_records(path, ["/driver/link"])]
        assert [e["event"] for e in events][:2] == ["waiting", "connected"]
        assert all(e["link"] == link for e in events)
