"""DirectAdeptCmd: the V+ SIGNAL instruction switches the Adept's digital outputs by default
(RobPraktikum's suction cup: ``DirectAdeptCmd signal 5, -6`` answered ``true``, one line);
a malformed one switches nothing; every other V+ instruction stays refused, off by default
and, when allowed, with the word that no link carries it (deploy/adept/README.md).

The system tests run ``rob6 run --robot ad850`` with the simulated arm and read the outputs
back from the driver's state over Zenoh, as the live view and the recorder see them.
"""

from __future__ import annotations

from pathlib import Path
from typing import cast

from harness.client import Client
from harness.fuzz import _DeadBus  # every bus request would fail loudly
from harness.system import System, driver_state, running
from rob6.bus import Bus
from rob6.robots import get_robot
from rob6_gateway.commands import Gateway, Options
from rob6_gateway.state import Session
from rob6_recorder.reader import read_records

REFUSED_RAW = ("ERROR: DirectAdeptCmd: raw V+ commands cannot reach the controller (neither the simulation "
               "nor the simple_message link has a V+ command channel; only SIGNAL is carried); nothing was sent\n"
               "false\n")


def ask(robot: str, line: str, **options: bool) -> str | None:
    gateway = Gateway(cast(Bus, _DeadBus()), get_robot(robot), Options(**options))
    return gateway.execute(Session(number=1, peer="test"), line)


def driver_outputs(system: System) -> list[int]:
    return list(driver_state(system).outputs)


def test_raw_v_plus_allowed_says_no_link_carries_it() -> None:
    assert ask("ad850", "DirectAdeptCmd SPEED 50", allow_direct_adept_cmd=True) == REFUSED_RAW


def test_raw_v_plus_off_by_default_and_false_on_other_robots() -> None:
    reply = ask("ad850", "DirectAdeptCmd SPEED 50")
    assert reply is not None and reply.startswith("ERROR: DirectAdeptCmd is disabled on this server")
    assert ask("ad850", "DirectAdeptCmd") == reply.replace("SPEED 50", "")  # bare: the same refusal
    assert ask("kr16", "DirectAdeptCmd SPEED 50", allow_direct_adept_cmd=True) == "false\n"
    assert ask("kr16", "DirectAdeptCmd signal 5") == "false\n"  # the original: false, not read


def test_a_malformed_signal_line_is_refused_before_any_bus_request() -> None:
    """_DeadBus fails every request loudly: these never reach the driver."""
    for line, why in (("signal", "SIGNAL needs at least one signal number"),
                      ("signal 5,,6", "SIGNAL 5,,6: an empty place between commas"),
                      ("signal 5,", "SIGNAL 5,: an empty place between commas"),
                      ("SIGNAL 5, x", "SIGNAL 5, x: 'x' is not a signal number"),
                      ("signal 2.5", "SIGNAL 2.5: '2.5' is not a signal number"),
                      ("signal 0", "signal 0 is not a V+ output (1-512) or software signal (2001-2512)"),
                      ("signal 5, 513", "signal 513 is not a V+ output (1-512) or software signal (2001-2512)"),
                      ("signal -1001", "signal -1001 is an input; only outputs (1-512) and software signals "
                                       "(2001-2512) can be switched"),
                      ("signal " + " ".join(["1"] * 33), "SIGNAL with 33 signals; at most 32 in one instruction")):
        assert ask("ad850", "DirectAdeptCmd " + line) == f"ERROR: DirectAdeptCmd: {why}; nothing was switched\nfalse\n"


def test_signal_switches_the_simulated_arms_outputs_by_default() -> None:
    with running("ad850", dummy=True) as system, Client(system.port) as client:
        assert driver_outputs(system) == []
        assert client.ask("DirectAdeptCmd signal 5, -6") == "true\n"
        assert driver_outputs(system) == [5, -6]
        # V+ syntax: keyword in any case, commas and/or blanks, a sign on either side
        assert client.ask("DirectAdeptCmd SIGNAL -5 6,+7 ,2001") == "true\n"
        assert driver_outputs(system) == [-5, 6, 7, 2001]
        # malformed: refused whole, nothing switched (not even the valid numbers before)
        assert client.ask("DirectAdeptCmd signal 8, 1001", lines=2).endswith("; nothing was switched\nfalse\n")
        assert client.ask("DirectAdeptCmd Signal 8 x", lines=2).startswith("ERROR: DirectAdeptCmd: SIGNAL 8 x: ")
        assert driver_outputs(system) == [-5, 6, 7, 2001]
        # any other V+ instruction is still refused
        assert client.ask("DirectAdeptCmd jmove 0,0,0,0,0", lines=2).startswith(
            "ERROR: DirectAdeptCmd is disabled on this server")
        assert client.read_quiet(0.3) == ""  # nothing more came than was read
        assert driver_outputs(system) == [-5, 6, 7, 2001]
        assert client.ask("Quit") == "bye!\n"
        # a new session finds them as they were (they are the arm's, not the session's)
        with Client(system.port) as again:
            assert again.ask("DirectAdeptCmd signal 3") == "true\n"
        assert driver_outputs(system) == [3, -5, 6, 7, 2001]


def test_robpraktikum_reading_one_line_per_command_stays_in_step(tmp_path: Path) -> None:
    """The Java client reads one line per command: switching the cup between motions never
    leaves it a reply behind. The recording has each change of the outputs."""
    script = [("DirectAdeptCmd signal 5, -6", "true"), ("GetRobot", "ad850"),
              ("MovePTPJoints 10 -60 80 20 40 30", "true"),
              ("DirectAdeptCmd signal -5, 6", "true"), ("IsAdept", "true"),
              ("GetPositionJoints", "10.000000 -60.000000 80.000000 20.000000 40.000000 30.000000"),
              ("DirectAdeptCmd signal 5, -6", "true"), ("CM_PING", "PONG")]
    with running("ad850", dummy=True, log_dir=str(tmp_path)) as system, Client(system.port) as client:
        for line, expected in script:
            assert client.ask(line) == expected + "\n", line
        assert client.read_quiet(0.3) == ""
        assert driver_outputs(system) == [5, -6]
    recorded = [r.data.get("outputs", []) for path in sorted(tmp_path.glob("*_system_*.mcap"))
                for r in read_records(path, ["/driver/joint_state"])]
    changes = [o for i, o in enumerate(recorded) if i == 0 or o != recorded[i - 1]]
    assert changes == [[], [5, -6], [-5, 6], [5, -6]]
