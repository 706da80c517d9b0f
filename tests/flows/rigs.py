"""The (robot, link) rigs the client flows run on: a real-time ``rob6 run`` recording to a
directory of its own, with the stand-in controller its link drives (kuka-rsi-sim over RSI,
adept-sm-sim over simple_message), connected and followed before the first flow."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.ports import free_port
from harness.system import System, driver_state, link_status, running
from tests.controllers.adept_controller import AdeptController
from tests.controllers.rsi_controller import SYSTEM_TIMEOUT, RsiController
from tests.motion.link_session import wait_until
from tests.motion.test_rsi_realtime import rsi_system

#: where each robot's flows start (a pose the clients home to; inside every limit)
STARTS = {"kr16rt": [0.0, -80.0, 100.0, 0.0, 30.0, 0.0], "ad850": [0.0, -60.0, 40.0, 0.0, 30.0, 0.0]}
#: how far a position read back may be from the commanded one: the simulation is exact;
#: RSI carries AIPos with 4 decimals, simple_message float32 radians rounded to 1e-4 deg
POSITION_TOL = {"sim": 1e-6, "rsi": 2e-4, "simple_message": 2e-4}

ALL = [("kr16rt", "sim"), ("kr16rt", "rsi"), ("ad850", "sim"), ("ad850", "simple_message")]
ADEPT = [rig for rig in ALL if rig[0] == "ad850"]


def rig_id(rig: tuple[str, str]) -> str:
    return "-".join(rig)


@dataclass
class Rig:
    robot: str
    link: str
    system: System
    log_dir: Path
    adept: AdeptController | None = None  # the controller on the simple_message link

    @property
    def start(self) -> list[float]:
        return STARTS[self.robot]

    def outputs(self) -> set[int]:
        """The Adept's digital outputs as switched so far: the controller's own, where there
        is one, and always the driver's state, which must agree with it."""
        switched = set(driver_state(self.system).outputs)
        if self.adept is not None:
            assert set(self.adept.status()["outputs"]) == switched
        return switched

    @property
    def tol(self) -> float:
        return POSITION_TOL[self.link]


@contextmanager
def rig(robot: str, link: str, log_dir: Path) -> Iterator[Rig]:
    """The system on ``link``, its controller up and followed (rob6's position is the robot's)."""
    adept = None
    with ExitStack() as stack:
        if link == "sim":
            system = stack.enter_context(running(robot, dummy=False, log_dir=str(log_dir)))
        elif link == "rsi":
            port = free_port(socket.SOCK_DGRAM)
            system = stack.enter_context(rsi_system(port, log_dir=str(log_dir)))
            kuka = stack.enter_context(RsiController(rob6=("127.0.0.1", port), robot=robot, timeout=SYSTEM_TIMEOUT))
            wait_until(lambda: link_status(system).state == "connected", what="the RSI link to be up")
            wait_until(lambda: np.allclose(driver_state(system).q, kuka.status()["aipos"], atol=2e-4),
                       what="rob6 to follow the KR C4")
        elif link == "simple_message":
            adept = stack.enter_context(AdeptController())
            assert adept.motion is not None and adept.state is not None and adept.io is not None
            system = stack.enter_context(running(robot, dummy=False, log_dir=str(log_dir), extra_env={
                "ROB6_LINK": "simple_message", "ROB6_SM_HOST": "127.0.0.1",
                "ROB6_SM_MOTION_PORT": str(adept.motion[1]), "ROB6_SM_STATE_PORT": str(adept.state[1]),
                "ROB6_SM_IO_PORT": str(adept.io[1])}))
            wait_until(lambda: link_status(system).state == "connected", what="the simple_message link to be up")
            wait_until(lambda: np.allclose(driver_state(system).q, adept.status()["position_rob6_deg"], atol=2e-4),
                       what="rob6 to follow the Adept")
        else:
            raise ValueError(f"no rig for link {link}")
        yield Rig(robot, link, system, log_dir, adept)
