"""Fault injection against a real system: kill, stop or restart a service or the router mid-session.

The faults: SIGKILL, SIGSTOP/SIGCONT and SIGTERM (restart) of each service and
SIGSTOP/SIGCONT of the Zenoh router, during one client session.

For every fault: the probe command that needs the faulty service answers an ``ERROR: …``
line (``<service> unavailable`` or ``<service>: no reply to <command> within …``) or still the right
answer (a killed process whose token is not gone yet is retried / a fresh one already up),
never hangs (generous read timeout); the gateway keeps answering commands that do not need
the service; and once the launcher (``restart=True``) restarted the service, or after
SIGCONT, the *same* session gets correct answers again, with the same gateway process.

Used by ``tests/reliability/test_faults.py`` and ``python -m bench.reliability``.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable
from typing import Any

from harness.fuzz import FuzzClient
from harness.system import System, running

# service -> (probe command, is the answer a correct one?)
PROBES: dict[str, tuple[str, Callable[[list[bytes]], bool]]] = {
    "kinematics": ("ForwardCalc 10 0 0 0 0 0", lambda lines: len(lines) == 2 and lines[1].startswith(b"noflip")),
    # a Set reaches the planner (reads are answered from the gateway's mirror); 1 is the default
    "planner": ("SetRTSpeedControl 1", lambda lines: lines == [b"true"]),
    "driver": ("PingRobot 1 0", lambda lines: len(lines) == 1 and len(lines[0].split()) == 5),
    "gripper": ("HasGripper", lambda lines: lines[-1:] == [b"true"]),
    "recorder": ("GetVersion", lambda lines: lines == [b"0.1.01"]),  # needs no service: must not notice
}
HANG_S = 15.0  # a reply later than this counts as a hang (the bus timeout is 200 ms)
RECOVER_S = 40.0


def _ask(client: FuzzClient, command: str) -> tuple[list[bytes], float]:
    start = time.monotonic()
    client.sock.sendall(command.encode() + b"\nCM_PING\n")
    return client.until_pong(), time.monotonic() - start


def _acceptable_during_fault(service: str, lines: list[bytes]) -> bool:
    ok = PROBES[service][1]
    if ok(lines):
        return True
    return bool(lines) and lines[0].startswith(b"ERROR: ") and (
        b"unavailable" in lines[0] or b"no reply" in lines[0])


def _wait_recovered(system: System, client: FuzzClient, service: str, old_pid: int | None,
                    problems: list[tuple[object, ...]]) -> bool:
    command, ok = PROBES[service]
    deadline = time.monotonic() + RECOVER_S
    while time.monotonic() < deadline:
        lines, _ = _ask(client, command)
        pid = system.pids().get(service)
        if ok(lines) and (old_pid is None or (pid and pid != old_pid)):
            return True
        time.sleep(0.2)
    problems.append((service, "did not recover", lines, system.output[-30:]))  # the services' last words
    return False


def inject(system: System, client: FuzzClient, service: str, fault: str, problems: list[tuple[object, ...]]) -> bool:
    """One fault; True when it was survived and recovered from."""
    pids = system.pids()
    pid = pids[service]
    gateway = pids["gateway"]
    command = PROBES.get(service, PROBES["planner"])[0]
    probe_service = service if service in PROBES else "planner"
    good = True
    if fault == "kill":
        os.kill(pid, signal.SIGKILL)
    elif fault == "term":
        os.kill(pid, signal.SIGTERM)
    elif fault == "stop":
        os.kill(pid, signal.SIGSTOP)
    try:
        for _ in range(3):
            lines, took = _ask(client, command)
            if took > HANG_S or not _acceptable_during_fault(probe_service, lines):
                problems.append((service, fault, "bad reply during the fault", lines, round(took, 1)))
                good = False
        lines, _ = _ask(client, "GetVersion")  # the gateway itself is not blocked
        if lines != [b"0.1.01"]:
            problems.append((service, fault, "gateway blocked", lines))
            good = False
    except (TimeoutError, ConnectionError) as exc:
        problems.append((service, fault, f"session broken: {exc!r}"))
        return False
    finally:
        if fault == "stop":
            os.kill(pid, signal.SIGCONT)
    old = None if fault == "stop" else pid
    if service == "router":
        old = None
    good = _wait_recovered(system, client, probe_service, old, problems) and good
    if system.pids().get("gateway") != gateway:
        problems.append((service, fault, "gateway restarted"))
        good = False
    return good


SERVICES = ("kinematics", "planner", "driver", "gripper", "recorder")
FAULTS = ("kill", "stop", "term")


def run_fault_campaign(robot: str = "ad850", rounds: int = 1) -> dict[str, Any]:
    """Every fault on every service (and SIGSTOP of the router) in one session of one system."""
    problems: list[tuple[object, ...]] = []
    injected = recovered = 0
    with running(robot, dummy=True, restart=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        gateway = system.pids()["gateway"]
        client = FuzzClient(system.port, timeout=HANG_S)
        plan = [(s, f) for _ in range(rounds) for s in SERVICES for f in FAULTS] + [("router", "stop")]
        for service, fault in plan:
            injected += 1
            if inject(system, client, service, fault, problems):
                recovered += 1
        for service, (command, ok) in PROBES.items():  # everything works again, same session
            lines, _ = _ask(client, command)
            if not ok(lines):
                problems.append(("final", service, lines))
        gateway_restarts = int(system.pids().get("gateway") != gateway)
        client.close()
    return {"injected": injected, "recovered": recovered, "problems": problems,
            "gateway_restarts": gateway_restarts, "records_lost": "n/a"}
