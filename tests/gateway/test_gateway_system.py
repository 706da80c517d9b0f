"""The gateway against real processes: client styles, one client at a time, failures, Shutdown, GetCell."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import msgspec
import pytest

from harness.client import Client
from harness.system import System, running
from rob6.cell import default_cell, load_cell
from rob6.messages import Cell
from rob6.robots import get_robot
from tests.motion.link_session import wait_until

GATEWAY_AND_DRIVER = ("driver", "gateway")


@pytest.fixture(scope="module")
def system() -> Iterator[System]:
    with running("kr16", services=GATEWAY_AND_DRIVER) as system:
        yield system


def test_separate_processes(system: System) -> None:
    pids = system.pids()
    assert {"router", "driver", "gateway"} <= set(pids)
    assert len(set(pids.values())) == len(pids)


@pytest.mark.parametrize("terminator", [b"\n", b"\r\n"])
def test_terminated_commands(system: System, terminator: bytes) -> None:
    with system.client() as client:
        client.send(b"GetRobot" + terminator)
        assert client.read_lines(1) == "kr16\n"


def test_unterminated_commands_one_per_write(system: System) -> None:
    with system.client() as client:
        for command, reply in ((b"GetRobot", "kr16\n"), (b"CM_PING", "PONG\n"), (b"GetVersion", "0.1.01\n")):
            client.send(command)
            assert client.read_lines(1) == reply


def test_client_that_reads_one_recv_per_reply(system: System) -> None:
    """A multi-line reply arrives in one segment, so one recv() gets all of it."""
    with system.client() as client:
        client.send(b"SetVerbosity x\n")
        client.sock.settimeout(2)
        assert client.sock.recv(4096) == b"ERROR: incorrect value\nfalse\n"


def test_several_commands_in_one_write_answered_in_order(system: System) -> None:
    with system.client() as client:
        client.send(b"GetRobot\nCM_PING\r\nGetVersion\nFoo\n")
        assert client.read_lines(4) == "kr16\nPONG\n0.1.01\nERROR: Foo\n"


def test_command_split_across_writes_is_reassembled(system: System) -> None:
    with system.client() as client:
        client.send(b"GetRo")
        client.send(b"bot\n")  # well within the pause: one line
        assert client.read_lines(1) == "kr16\n"


def test_missing_arguments_are_answered_at_once(system: System) -> None:
    with system.client() as client:
        start = time.monotonic()
        assert client.ask("MovePTPJoints", 2) == "ERROR: incorrect joints\nfalse\n"
        assert client.ask("SetVerbosity", 2) == "ERROR: incorrect value\nfalse\n"
        assert client.ask("SetAllowedStatus", 1) == "ERROR: incorrect status\n"
        assert time.monotonic() - start < 1.0
        assert client.ask("GetRobot") == "kr16\n"  # the next command is a command, not arguments


def test_unknown_and_malformed_commands_keep_the_connection(system: System) -> None:
    with system.client() as client:
        assert client.ask("getrobot") == "ERROR: getrobot\n"
        assert client.ask("MovePTPJoints 1 2 3", 2) == "ERROR: incorrect joints\nfalse\n"
        assert client.ask("SetVerbosity nan", 2) == "ERROR: incorrect value\nfalse\n"
        client.send(b"\xff\xfe\x00junk\n")
        assert client.read_lines(1) == "ERROR: \xff\xfe\n"
        client.send(b"X" * (1 << 20) + b"\n")  # 1 MiB line
        assert client.read_lines(1).startswith("ERROR: line too long (1048577 bytes")
        assert client.ask("CM_PING") == "PONG\n"


def test_second_client_is_refused_without_disturbing_the_first(system: System) -> None:
    with system.client() as first:
        with Client(system.port, handshake=False) as second:
            assert second.greeting == "ERROR: server busy, another client is connected\n"
            assert second.closed()
        assert first.ask("CM_PING") == "PONG\n"
        assert first.ask("Quit") == "bye!\n"
    with system.client() as third:  # accepted at once after Quit
        assert third.ask("GetRobot") == "kr16\n"


def test_next_client_accepted_right_after_a_disconnect(system: System) -> None:
    client = system.client()
    client.close()
    deadline = time.monotonic() + 1.0
    while True:
        with Client(system.port, handshake=False) as again:
            if again.greeting.startswith("welcome") or time.monotonic() > deadline:
                assert again.greeting.startswith("welcome")
                break
        time.sleep(0.01)


def test_ping_robot_measures_the_driver(system: System) -> None:
    with system.client() as client:
        numbers = client.ask("PingRobot 5 1").split()
        assert len(numbers) == 5
        assert 0 < float(numbers[0]) < 0.2  # seconds
        assert client.ask("PingRobot 0 0") == "-1\n"  # cannot be measured: the original's answer


def test_get_cell_answers_the_drivers_cell_in_one_line_of_json(system: System) -> None:
    with system.client() as client:
        client.send(b"GetCell\nCM_PING\n")  # one line: the next reply is the next command's
        line, pong = client.read_lines(2).split("\n")[:2]
        assert pong == "PONG"
        cell = json.loads(line)
        served = msgspec.convert(cell, Cell)
        assert msgspec.structs.replace(served, unchecked=[]) == default_cell(get_robot("kr16"))
        assert set(cell) == set(Cell.__struct_fields__)  # every field, those at their default too
        # the pairs the driver does not measure, each with why
        assert "link_3 with link_1: near in the chain: the joint between them keeps them apart" in served.unchecked
        assert client.ask("GetStatus") == "noflip up lefty\n"  # GetStatus is what it was


LAB_CELL = """\
margin_mm: 8
zones:
  - name: Tisch (Gerät)
    keep: out
    box: {min: [600, -300, -50], max: [1200, 300, 120], rpy_deg: [0, 0, 15]}
  - name: Zelle €
    keep: in
    box: {min: [-2000, -2000, -100], max: [2000, 2000, 2500]}
tool:
  - {name: Greifer, capsule: {from: [0, 0, 0], to: [0, 0, -140], radius: 30}}   # out of the flange: -z
arm:
  self_collision: false
"""


def test_get_cell_of_a_lab_cell_and_without_a_driver(tmp_path: Path) -> None:
    """A lab's own cell comes back as the driver read it, names beyond latin-1 included (the
    reply is ASCII JSON); without a driver GetCell answers the one line every value command
    does, and the session goes on."""
    path = tmp_path / "cell.yaml"
    path.write_text(LAB_CELL, encoding="utf-8")
    with running("kr16", services=GATEWAY_AND_DRIVER, extra_env={"ROB6_CELL": str(path)}) as system, \
            system.client() as client:
        line = client.ask("GetCell")
        assert line.isascii() and line.count("\n") == 1
        assert msgspec.structs.replace(msgspec.convert(json.loads(line), Cell), unchecked=[]) == load_cell(path)
        assert [z["name"] for z in json.loads(line)["zones"]] == ["Tisch (Gerät)", "Zelle €"]
        sha256 = hashlib.sha256(path.read_bytes()).hexdigest()  # which cell: the driver logs it at start too
        assert json.loads(line)["sha256"] == sha256
        assert any("driver" in out and f"sha256 {sha256}" in out for out in system.output), system.output
        os.kill(system.pids()["driver"], signal.SIGKILL)
        wait_until(lambda: any("driver instance" in out and "went away" in out for out in system.output),
                   10.0, "the gateway to see the driver gone")
        assert client.ask("GetCell", timeout=3) == "ERROR: driver unavailable\n"  # one line, no false
        assert client.ask("CM_PING") == "PONG\n"


def test_a_killed_service_gives_an_error_reply_not_a_hang() -> None:
    with running("kr16", services=GATEWAY_AND_DRIVER) as system:
        with system.client() as client:
            assert client.ask("PingRobot 1 0").count(" ") == 4
            os.kill(system.pids()["driver"], signal.SIGKILL)
            time.sleep(0.3)
            start = time.monotonic()
            assert client.ask("PingRobot 1 0", timeout=3) == "ERROR: driver unavailable\n"
            assert client.ask("GetPositionJoints", timeout=3).startswith("ERROR: driver unavailable")
            assert time.monotonic() - start < 2.5
            assert client.ask("CM_PING") == "PONG\n"  # still connected
        assert any("driver exited with code" in line for line in system.output)


def test_shutdown_stops_the_whole_system() -> None:
    with running("kr16", services=GATEWAY_AND_DRIVER) as system:
        pids = system.pids()
        with system.client() as client:
            assert client.ask("Shutdown", 2) == "bye!\nshutting down ...\n"
            assert client.closed()
        system.process.wait(5)
        assert system.process.returncode == 0
        for pid in pids.values():
            with pytest.raises(ProcessLookupError):
                os.kill(pid, 0)
        with pytest.raises(ConnectionRefusedError):
            socket.create_connection(("127.0.0.1", system.port), timeout=1)


def test_ctrl_c_stops_everything_within_two_seconds() -> None:
    with running("kr16", services=GATEWAY_AND_DRIVER) as system:
        pids = system.pids()
        start = time.monotonic()
        system.process.send_signal(signal.SIGINT)
        system.process.wait(5)
        assert time.monotonic() - start < 2.0
        for pid in pids.values():
            with pytest.raises(ProcessLookupError):
                os.kill(pid, 0)


def test_configuration_reads_follow_every_set_and_a_restarted_planner() -> None:
    """Configuration reads are answered from the gateway's mirror of the planner's state:
    a read right after a Set shows it, and after a planner restart the reads show the new
    planner's (default) configuration, never the dead one's."""
    with running("kr16", dummy=True, restart=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system, \
            system.client() as client:
        default = client.ask("GetJointsMaxSpeed")
        for k in range(1, 41):
            values = " ".join(f"{0.1 + k * 0.001 + j * 1e-4:f}" for j in range(6))
            assert client.ask(f"SetJointsMaxSpeed {values}") == "true\n"
            assert client.ask("GetJointsMaxSpeed") == values + "\n"
            assert client.ask(f"SetRTSpeedControl {k % 2}") == "true\n"
            assert client.ask("GetRTSpeedControl") == f"{k % 2}\n"
        os.kill(system.pids()["planner"], signal.SIGKILL)
        deadline = time.monotonic() + 30
        while (reply := client.ask("GetJointsMaxSpeed")) != default:
            assert reply == "ERROR: planner unavailable\n" or reply == values + "\n", reply
            assert time.monotonic() < deadline, "the restarted planner's configuration never showed"
            time.sleep(0.05)
        assert client.ask("GetRTSpeedControl") == "1\n"
