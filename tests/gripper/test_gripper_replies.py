"""How many lines each gripper command answers, through a real system (gateway, gripper
service, Zenoh): the protocol description's counts on success (HasGripper 1, GripperMove 2,
GripperGoHome 3, GripperMoveToPosition 3) and the same counts on every failure, ending in
``ERROR: <reason>`` and ``false`` -- so a client that reads a fixed number of lines per
command (rob-chess: three for GripperGoHome) never hangs and never falls a reply behind.

Every reply is read as "the lines that came until the server fell quiet", so an extra or
a missing line shows as a wrong reply, not as a timeout hidden by a line count.
"""

from __future__ import annotations

import os
import signal
import time

from harness.client import Client
from harness.system import System, running
from rob6_gripper.fake_device import FakeSmpDevice

#: the protocol description's line count of each command (section 3.4), true/false included
LINES = {"HasGripper": 1, "GripperMove": 2, "GripperGoHome": 3, "GripperMoveToPosition": 3}


def reply(client: Client, line: str, quiet: float = 0.4) -> list[str]:
    """Every line the server sent for ``line``, waiting until it was quiet for ``quiet`` s
    after the first byte (a gripper motion takes up to ~1 s before the first byte)."""
    first = client.ask(line, lines=1, timeout=20)
    assert first, f"no reply to {line!r}"
    rest = client.read_quiet(quiet)
    return (first + rest).splitlines()


def assert_failure(lines: list[str], command: str, reason: str, info: str) -> None:
    """As many lines as the command's success: ``info`` lines, ``ERROR: <reason...>``, ``false``."""
    assert len(lines) == LINES[command], lines
    assert lines[-1] == "false" and lines[-2].startswith(f"ERROR: {reason}"), lines
    assert lines[:-2] == [info] * (LINES[command] - 2), lines


def test_success_and_failure_line_counts_with_the_simulated_gripper() -> None:
    # an object 30 mm wide between the jaws: closing onto it works, moving to 10 mm is blocked
    with (running("ad850", dummy=True, extra_env={"ROB6_GRIPPER_OBJECT": "0.03"}) as system,
          Client(system.port) as client):
        assert reply(client, "HasGripper") == ["true"]
        assert reply(client, "GripperGoHome") == [
            "Start moving to home position", "Gripper at 0.0400 m", "true"]
        assert reply(client, "GripperMoveToPosition 0.05") == [
            "Start moving to position 0.0500 m", "Gripper at 0.0500 m", "true"]
        assert reply(client, "GripperMove -1") == ["Start moving with amperage -1.000", "true"]
        assert reply(client, "GripperMove 2.5") == ["Start moving with amperage 2.500", "true"]
        # failures: the device's reason, where the jaws are, the same number of lines
        assert_failure(reply(client, "GripperMoveToPosition 0.01"), "GripperMoveToPosition",
                       "GripperMoveToPosition: ", "Gripper at 0.0300 m")
        assert_failure(reply(client, "GripperMoveToPosition 0.5"), "GripperMoveToPosition",
                       "GripperMoveToPosition: position 0.5000 m is outside the stroke",
                       "Gripper at 0.0300 m")
        assert_failure(reply(client, "GripperMoveToPosition x"), "GripperMoveToPosition",
                       "incorrect value", "Gripper not moved")
        assert_failure(reply(client, "GripperMoveToPosition"), "GripperMoveToPosition",
                       "incorrect value", "Gripper not moved")
        assert_failure(reply(client, "GripperMove"), "GripperMove", "incorrect value", "")
        assert_failure(reply(client, "GripperMove nan"), "GripperMove", "incorrect value", "")
        assert reply(client, "GetRobot") == ["ad850"]  # the session goes on, in step


def test_a_silent_serial_gripper_fails_with_the_same_line_counts() -> None:
    """The real backend (Schunk SMP over a serial port; here the fake module on a pty):
    a module that stops answering fails every motion, the position then unknown."""
    with FakeSmpDevice(module_id=12, time_scale=5.0) as dev:
        env = {"ROB6_GRIPPER_PORT": dev.port}
        with running("ad850", dummy=True, extra_env=env) as system, Client(system.port) as client:
            assert reply(client, "HasGripper") == ["true"]
            assert reply(client, "GripperGoHome")[-1] == "true"
            dev.silent = True
            assert reply(client, "HasGripper") == ["false"]  # an answer, not a failure
            for line in ("GripperGoHome", "GripperMoveToPosition 0.02", "GripperMove -1"):
                command = line.split()[0]
                assert_failure(reply(client, line), command, f"{command}: ", "Gripper position unknown")
            dev.silent = False
            assert reply(client, "GripperMoveToPosition 0.02") == [
                "Start moving to position 0.0200 m", "Gripper at 0.0200 m", "true"]


def _gateway_saw_go(system: System, service: str, timeout: float = 10.0) -> None:
    """Until the gateway logs that ``service``'s instance went away (its liveliness token
    left with its session): from then on its commands answer ``unavailable``."""
    deadline = time.monotonic() + timeout
    while not any(f"{service} instance" in line and "went away" in line for line in list(system.output)):
        assert time.monotonic() < deadline, f"the gateway did not see {service} go within {timeout} s"
        time.sleep(0.05)


def test_no_gripper_service_fails_with_the_same_line_counts() -> None:
    with running("ad850", dummy=True) as system, Client(system.port) as client:
        assert reply(client, "HasGripper") == ["true"]
        os.kill(system.pids()["gripper"], signal.SIGKILL)
        _gateway_saw_go(system, "gripper")
        assert reply(client, "HasGripper") == ["ERROR: gripper unavailable"]
        for line in ("GripperGoHome", "GripperMoveToPosition 0.02", "GripperMove -1"):
            command = line.split()[0]
            assert_failure(reply(client, line), command, "gripper unavailable", "Gripper position unknown")
        assert reply(client, "GetRobot") == ["ad850"]


def test_a_client_reading_a_fixed_count_never_falls_behind() -> None:
    """rob-chess style: ``command(name, n)`` reads exactly n lines and judges the last;
    successes and failures interleaved, then a GetRobot must be answered ad850."""
    script = [("GripperGoHome", True), ("GripperMoveToPosition 0.01", False),
              ("GripperMoveToPosition 0.06", True), ("GripperMove -1", True),
              ("GripperMoveToPosition 9", False), ("GripperMoveToPosition x", False),
              ("GripperMove x", False), ("HasGripper", True), ("GripperGoHome", True)]
    with (running("ad850", dummy=True, extra_env={"ROB6_GRIPPER_OBJECT": "0.03"}) as system,
          Client(system.port) as client):
        for line, ok in script:
            got = client.ask(line, lines=LINES[line.split()[0]], timeout=20).splitlines()
            assert got[-1] == ("true" if ok else "false"), (line, got)
            assert all(g not in ("true", "false") for g in got[:-1]), (line, got)
        assert client.ask("GetRobot") == "ad850\n"
        assert client.read_quiet(0.3) == ""


def test_other_robots_answer_false_in_one_line_as_the_original() -> None:
    with running("kr16", dummy=True) as system, Client(system.port) as client:
        for line in ("HasGripper", "GripperGoHome", "GripperMove -1", "GripperMoveToPosition 0.02",
                     "GripperMoveToPosition x"):
            assert reply(client, line, quiet=0.3) == ["false"], line
