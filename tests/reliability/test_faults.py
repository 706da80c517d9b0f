"""Fault injection with real processes (see ``faults.py``): each service SIGKILLed, SIGSTOPped
(then SIGCONT) and SIGTERMed during one client session; the router SIGSTOPped. The session
gets error replies naming the service (never a hang), and works again once the launcher
restarted the service, with the same gateway process and connection."""
import os
import signal
import time
from collections.abc import Iterator

import pytest

from harness.faults import FAULTS, PROBES, SERVICES, _ask, inject
from harness.fuzz import FuzzClient
from harness.system import System, running


@pytest.fixture(scope="module")
def session() -> Iterator[tuple[System, FuzzClient, int]]:
    with running("ad850", dummy=True, restart=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        client = FuzzClient(system.port)
        yield system, client, system.pids()["gateway"]
        client.close()


@pytest.mark.parametrize("fault", FAULTS)
@pytest.mark.parametrize("service", SERVICES)
def test_fault_is_survived_and_recovered(session: tuple[System, FuzzClient, int], service: str, fault: str) -> None:
    system, client, gateway = session
    problems: list[tuple[object, ...]] = []
    assert inject(system, client, service, fault, problems), problems
    assert system.pids()["gateway"] == gateway


def test_router_stopped_and_continued(session: tuple[System, FuzzClient, int]) -> None:
    system, client, gateway = session
    problems: list[tuple[object, ...]] = []
    assert inject(system, client, "router", "stop", problems), problems


def test_stopped_service_is_named_in_the_error(session: tuple[System, FuzzClient, int]) -> None:
    system, client, _ = session
    pid = system.pids()["planner"]
    os.kill(pid, signal.SIGSTOP)
    try:
        lines, took = _ask(client, "SetRTSpeedControl 1")  # a Set: reads come from the gateway's mirror
    finally:
        os.kill(pid, signal.SIGCONT)
    assert lines[0].startswith(b"ERROR: planner: no reply to SetRTSpeedControl within"), lines  # not a bare "ERROR: Timeout"
    assert took < 10


def test_everything_works_again_in_the_same_session(session: tuple[System, FuzzClient, int]) -> None:
    system, client, gateway = session
    deadline = time.monotonic() + 30
    for service, (command, ok) in PROBES.items():
        while not ok(lines := _ask(client, command)[0]) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert ok(lines), (service, lines)
    assert system.pids()["gateway"] == gateway


def test_killed_router_is_restarted_and_the_session_goes_on() -> None:
    """The launcher restarts a killed router and every Zenoh session reconnects to it: the
    same client session works again, with the same gateway."""
    with running("kr16", dummy=True, restart=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        client = FuzzClient(system.port)
        gateway = system.pids()["gateway"]
        router = system.pids()["router"]
        os.kill(router, signal.SIGKILL)
        deadline = time.monotonic() + 30
        while True:  # every reply is an answer or an error line, never a hang
            lines, _ = _ask(client, "ForwardCalc 10 -20 30 40 50 60")
            if not lines[0].startswith(b"ERROR") or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        assert not lines[0].startswith(b"ERROR"), lines  # kinematics answers (again)
        deadline = time.monotonic() + 15
        while system.pids().get("router") in (None, router) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert system.pids().get("router") not in (None, router)  # a new router
        os.kill(system.pids()["kinematics"], signal.SIGKILL)  # a service restarted after the router
        deadline = time.monotonic() + 30
        while _ask(client, "ForwardCalc 10 -20 30 40 50 60")[0][0].startswith(b"ERROR"):
            assert time.monotonic() < deadline, "kinematics not reachable through the new router"
            time.sleep(0.2)
        assert system.pids()["gateway"] == gateway
        assert any("router exited with code -9" in line for line in system.output)
        client.close()
