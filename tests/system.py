"""Where the ground truth lives, and the system/client harness (rob6.testing)."""

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import zenoh

from rob6.bus import Bus, zenoh_config
from rob6.config import BusSettings
from rob6.messages import Empty, JointState
from rob6.testing import Client, System, free_port, running

__all__ = ["CONFORMANCE", "REPO", "SHARED", "Client", "System", "driver_state", "free_port", "running",
           "zenoh_router"]

REPO = Path(__file__).resolve().parents[1]
#: the original server's transcripts, kept with the tests (tests/transcripts/ORIGIN.md)
CONFORMANCE = REPO / "tests" / "transcripts"
#: where they are refreshed from: the ground truth beside the project, when present
SHARED = Path(os.environ.get("ROB6_SHARED", REPO.parent / "shared")).resolve()


@contextmanager
def zenoh_router(robot_id: str) -> Iterator[BusSettings]:
    """A real Zenoh router in this process on a free port; yields the settings of a session
    of robot ``robot_id`` connected to it."""
    port = free_port()
    router = zenoh.open(zenoh_config(BusSettings(), mode="router", listen=(f"tcp/127.0.0.1:{port}",)))
    try:
        yield BusSettings(robot_id=robot_id, connect=(f"tcp/127.0.0.1:{port}",))
    finally:
        router.close()


def driver_state(system: System) -> JointState:
    """The driver's state, asked over the system's Zenoh router like any service would."""
    bus = Bus(BusSettings(robot=system.robot, robot_id=system.robot_id,
                          connect=(f"tcp/127.0.0.1:{system.router_port}",)), "test")
    try:
        bus.wait_for(["driver"], 10)
        state: JointState = bus.request("driver", "state", Empty())
        return state
    finally:
        bus.close()
