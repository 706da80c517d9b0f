"""One robot, one owner: a second driver, planner, gripper or gateway for a robot id is
refused with one line while the first system goes on undisturbed; of two started at the
same moment exactly one wins; a stray publisher on the robot's state key is ignored."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time

import msgspec
import pytest
import zenoh

from harness.client import Client
from harness.ports import free_port
from harness.system import System, running
from rob6.bus import Bus
from rob6.config import BusSettings
from rob6.messages import JointState
from rob6.ownership import EXIT_REFUSED

pytestmark = pytest.mark.slow

OWNERS = ("driver", "planner", "gripper", "gateway")


def _start(system: System, service: str, **env: str) -> subprocess.Popen[str]:
    """One more instance of ``service`` for the robot id of ``system``, on its router."""
    env = dict(os.environ, ROB6_ROBOT=system.robot, ROB6_ROBOT_ID=system.robot_id, ROB6_DUMMY="1",
               ROB6_ZENOH_CONNECT=f"tcp/127.0.0.1:{system.router_port}", ROB6_PORT=str(free_port()),
               **env)
    env.pop("ROB6_SERVICES", None)
    return subprocess.Popen([sys.executable, "-m", f"rob6_{service}"], env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _moves_undisturbed(client: Client, stop: threading.Event, seen: list[bool | tuple[str, str]]) -> None:
    """A client of the first system moving the robot, reading back every position."""
    k = 0
    while not stop.is_set():
        target = [(-1) ** k * 10.0, -60.0, 80.0, 0.0, 40.0, 0.0]
        command = "MovePTPJoints " + " ".join(f"{x:f}" for x in target)
        reply = client.ask(command)
        seen.append(True if reply == "true\n" else (command, reply))
        for _ in range(3):
            reply = client.ask("GetPositionJoints")
            seen.append(True if [float(x) for x in reply.split()] == target else ("GetPositionJoints", reply))
        k += 1


def test_second_owner_of_each_kind_is_refused_with_one_line() -> None:
    with running("kr16", dummy=True) as system, system.client() as client:
        stop = threading.Event()
        seen: list[bool | tuple[str, str]] = []
        mover = threading.Thread(target=_moves_undisturbed, args=(client, stop, seen))
        mover.start()
        try:
            for service in OWNERS:
                started = time.monotonic()
                out, err = _start(system, service).communicate(timeout=30)
                assert re.fullmatch(f"rob6: a {service} for {system.robot_id} is already running on "
                                    r"[\w-]+; stop it or use another ROB6_ROBOT_ID\n", err), err
                assert "Traceback" not in err
                assert time.monotonic() - started < 10
        finally:
            stop.set()
            mover.join(30)
        wrong = [x for x in seen if x is not True]
        assert seen and not wrong, f"{len(wrong)} of {len(seen)} moves or positions were wrong: {wrong[:8]}"
        # the first system is whole: one instance of each owner, and it still moves
        bus = Bus(BusSettings(robot_id=system.robot_id, connect=(f"tcp/127.0.0.1:{system.router_port}",)),
                  "probe")
        try:
            assert not bus.wait_for(list(OWNERS), 5.0)
            time.sleep(0.5)
            assert {s: len(bus.instances(s)) for s in OWNERS} == dict.fromkeys(OWNERS, 1)
        finally:
            bus.close()
        assert client.ask("MovePTPJoints 1 -60 80 0 40 0") == "true\n"


def test_a_second_rob6_run_is_refused_at_once() -> None:
    with running("kr16", dummy=True) as system:
        started = time.monotonic()
        second = subprocess.run([sys.executable, "-m", "rob6.cli", "run", "--robot-id", system.robot_id,
                                 "--port", str(system.port), "--router-port", str(system.router_port)],
                                capture_output=True, check=False, text=True, timeout=30)
        assert second.returncode != 0
        assert time.monotonic() - started < 5
        assert second.stderr.strip().splitlines() == [
            f"rob6: the client port 0.0.0.0:{system.port} is in use: is rob6 (or rob6server) already running? "
            f"Stop it, or choose another port with ROB6_PORT"]
        with system.client() as client:
            assert client.ask("MovePTPJoints 5 -60 80 0 40 0") == "true\n"
            assert client.ask("GetPositionJoints") == "5.000000 -60.000000 80.000000 0.000000 40.000000 0.000000\n"


@pytest.mark.parametrize("service", ["driver", "gateway"])
def test_two_started_at_the_same_moment_exactly_one_wins(service: str) -> None:
    # only a router and kinematics: both newcomers race for an empty role
    with running("kr16", dummy=True, services=("kinematics",)) as system:
        for _ in range(3):
            first, second = _start(system, service), _start(system, service)
            try:
                deadline = time.monotonic() + 20
                while time.monotonic() < deadline and first.poll() is None and second.poll() is None:
                    time.sleep(0.05)
                time.sleep(1.0)  # the winner stays; a second loser would have exited by now
                codes = sorted(str(p.poll()) for p in (first, second))
                assert codes == [str(EXIT_REFUSED), "None"], codes
                loser = first if first.poll() is not None else second
                assert loser.stderr is not None  # a pipe
                err = loser.stderr.read()
                assert err.startswith(f"rob6: a {service} for {system.robot_id} is "), err
                assert len(err.strip().splitlines()) == 1, err
            finally:
                for process in (first, second):
                    process.terminate()
                    process.wait(10)


def test_a_foreign_state_on_the_robot_key_is_ignored_and_logged() -> None:
    with running("kr16", dummy=True) as system, system.client() as client:
        assert client.ask("MovePTPJoints 20 -60 80 0 40 0") == "true\n"
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{system.router_port}"]')
        intruder = zenoh.open(config)
        try:
            fake = msgspec.json.encode(JointState(t=1.0, cycle=10**9, q=[99.0] * 6, qd=[0.0] * 6,
                                                  instance="intruder-1"))
            key = f"rob6/{system.robot_id}/driver/state"
            answers = set()
            for _ in range(100):
                intruder.put(key, fake, attachment=b"intruder-1")
                answers.add(client.ask("GetPositionJoints"))
                time.sleep(0.01)
        finally:
            intruder.close()
        assert answers == {"20.000000 -60.000000 80.000000 0.000000 40.000000 0.000000\n"}
        assert client.ask("MovePTPJoints 21 -60 80 0 40 0") == "true\n"
    logged = [line for line in system.output if "ignoring" in line and "intruder-1" in line]
    assert any(" gateway " in line for line in logged), system.output[-20:]  # the one that follows the state
