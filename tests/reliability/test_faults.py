"""Fault injection with real processes (see ``faults.py``): each service SIGKILLed, SIGSTOPped
(then SIGCONT) and SIGTERMed during one client session; the router SIGSTOPped. The session
gets error replies naming the service (never a hang), and works again once the launcher
restarted the service, with the same gateway process and connection."""

import os
import signal
import time

import pytest

from bench.reliability import FuzzClient
from faults import FAULTS, PROBES, SERVICES, _ask, inject
from rob6.testing import running


@pytest.fixture(scope="module")
def session():
    with running("ad850", dummy=True, restart=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        client = FuzzClient(system.port)
        yield system, client, system.pids()["gateway"]
        client.close()


@pytest.mark.parametrize("fault", FAULTS)
@pytest.mark.parametrize("service", SERVICES)
def test_fault_is_survived_and_recovered(session, service, fault):
    system, client, gateway = session
    problems = []
    assert inject(system, client, service, fault, problems), problems
    assert system.pids()["gateway"] == gateway


def test_router_stopped_and_continued(session):
    system, client, gateway = session
    problems = []
    assert inject(system, client, "router", "stop", problems), problems


def test_stopped_service_is_named_in_the_error(session):
    system, client, _ = session
    pid = system.pids()["planner"]
    os.kill(pid, signal.SIGSTOP)
    try:
        lines, took = _ask(client, "GetJointsMaxSpeed")
    finally:
        os.kill(pid, signal.SIGCONT)
    assert lines[0].startswith(b"ERROR: planner "), lines  # not a bare "ERROR: Timeout"
    assert took < 10


def test_everything_works_again_in_the_same_session(session):
    system, client, gateway = session
    deadline = time.monotonic() + 30
    for service, (command, ok) in PROBES.items():
        while not ok(lines := _ask(client, command)[0]) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert ok(lines), (service, lines)
    assert system.pids()["gateway"] == gateway


def test_killed_router_ends_the_session_cleanly_instead_of_hanging():
    """The launcher does not restart the router: it stops the whole system. The client must
    see the connection closed (or an error reply), never a hang."""
    with running("kr16", dummy=True, restart=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        client = FuzzClient(system.port)
        os.kill(system.pids()["router"], signal.SIGKILL)
        try:  # peers also link directly: the first commands may still be answered
            for _ in range(200):
                lines, _ = _ask(client, "GetJointsMaxSpeed")
                assert len(lines) == 1, lines
                time.sleep(0.05)
        except ConnectionError:
            pass  # the launcher stopped everything: the gateway closed the connection
        assert system.process.wait(15) == 1  # "the Zenoh router exited ...; stopping"
        client.close()
