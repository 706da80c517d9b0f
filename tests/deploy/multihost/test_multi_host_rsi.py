"""Several hosts with the robot on its real-time link (issue 14): deploy/multihost/docker-compose.yml
with ``--profile rsi``. The driver on the robot PC drives a stand-in KR C4 (kr16rt: an RSI
packet every 4 ms, answered within the cycle or the controller counts it late and, after
too many, stops RSI) that is a machine of its own on the robot network, which only the robot
PC shares. The remote hosts are on the lab network, as in test_multi_host.py.

The controller is the judge: a motion that depended on a remote host would make the driver
answer late or stop, and the KR C4 would trip or end elsewhere. Its own module, so the
topology of test_multi_host.py is down before this one comes up (one at a time on 2 cores).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator

import pytest

from harness import images
from harness.client import Client
from harness.compose import run
from harness.images import TAG
from harness.topology import (
    Topology,
    alter_session,
    ask_true,
    cannot_run,
)

pytestmark = pytest.mark.docker

if (why := cannot_run()) is not None:
    pytest.skip(why, allow_module_level=True)

REPORT: dict[str, object] = {}
START = "MovePTPJoints 0 -80 100 0 30 0"
TARGET = [30.0, -70.0, 90.0, 10.0, 40.0, 20.0]


@pytest.fixture(scope="module")
def topology(rob6_images: images.Outcome) -> Iterator[Topology]:
    REPORT["images"] = f"rob6/*:{TAG} ready in {rob6_images.seconds:.0f} s"
    topo = Topology(f"rob6mhrsi{os.getpid()}", rsi=True)
    try:
        REPORT["up until healthy"] = f"{topo.up():.0f} s"
        # the KR C4 sends from the moment it is up; until the driver answers, RSI times out
        # and the stand-in operator (--auto-ack) restarts it, as on a real controller
        deadline = time.monotonic() + 90
        while not ((status := topo.kuka())["state"] == "running" and status["replies_ok"] >= 250):
            assert time.monotonic() < deadline, f"the driver never answered the KR C4: {status}"
            time.sleep(0.5)
        yield topo
    finally:
        logs = topo.compose("logs", "--no-color", "--tail", "300", "gateway", "planner", "driver", check=False).stdout
        warnings = [line for line in logs.splitlines() if " WARNING " in line or " ERROR " in line]
        topo.down()
        print("\n--- rob6 multi-host report, robot on RSI ---\n" + json.dumps(REPORT, indent=2))
        print("robot PC warnings and errors (last 40):\n" + "\n".join(warnings[-40:]))


@pytest.fixture
def client(topology: Topology) -> Iterator[Client]:
    c = topology.client()
    yield c
    c.close()


def _networks(topology: Topology, service: str) -> set[str]:
    names = topology.inspect(topology.container(service), "{{json .NetworkSettings.Networks}}")
    return {name.removeprefix(f"{topology.project}_") for name in json.loads(names)}


def test_the_controller_is_on_the_robot_network_only(topology: Topology) -> None:
    assert _networks(topology, "kuka-rsi-sim") == {"robot"}
    assert _networks(topology, "robot-pc") == {"lab", "robot"}
    for host in ("compute1", "compute2", "storage"):
        assert _networks(topology, host) == {"lab"}, host
    # from a lab host the controller's name does not even resolve; from the robot PC it does
    probe = "import socket, sys; socket.gethostbyname(sys.argv[1])"
    assert run(["docker", "exec", topology.container("compute1"), "python3", "-c", probe, "kuka-rsi-sim"],
               check=False).returncode != 0
    assert run(["docker", "exec", topology.container("robot-pc"), "python3", "-c", probe, "kuka-rsi-sim"],
               check=False).returncode == 0


def test_rsi_motion_unchanged_when_every_remote_host_is_partitioned(topology: Topology, client: Client) -> None:
    """A PTP and an Alter session over RSI, first without faults, then with compute1,
    compute2 and storage cut off from the robot PC: each time the KR C4 runs through without
    a trip and its axes end where the client moved them (the late packets it counted are
    reported)."""
    sessions: dict[str, dict[str, object]] = {}

    def session(name: str) -> None:
        ask_true(client, START)
        before = topology.kuka()
        ask_true(client, "MovePTPJoints " + " ".join(f"{x:g}" for x in TARGET))
        refused = alter_session(client)  # ends at TARGET with A1 + 2 deg
        after = topology.kuka()
        assert after["state"] == "running" and after["trips"] == before["trips"], (name, after)
        final = [TARGET[0] + 2.0, *TARGET[1:]]
        assert all(abs(a - b) < 2e-4 for a, b in zip(after["aipos"], final, strict=True)), (name, after["aipos"])
        sessions[name] = {"late packets": after["late_total"] - before["late_total"],
                          "Alter targets refused": refused, "controller cycle ms": after["cycle_ms"]}

    session("no fault")
    with topology.partitioned("compute1", "compute2", "storage"):
        session("every remote host partitioned")
    # late packets are reported, not compared: on this shared 2-core machine they are noise
    # either way (43 without faults and 5 with every remote host cut off in one run, 12 and 48
    # in the next); the controller's own verdict, no trip and the axes where asked, is asserted
    REPORT["PTP + 2 s Alter at 250 Hz over RSI (kr16rt)"] = sessions
