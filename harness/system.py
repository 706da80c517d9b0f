"""Start a real rob6 system (``rob6 run``: router, services, gateway) in processes on free ports.

``running``/``System`` start and stop it; ``System.client`` talks to its gateway with
``harness.client.Client``, ``System.bus`` and ``driver_state``/``link_status`` ask its
services over its Zenoh router; ``zenoh_router`` is a bare router in this process.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import zenoh

from harness.client import Client
from harness.ports import free_port
from rob6.bus import Bus, zenoh_config
from rob6.config import BusSettings
from rob6.messages import Empty, JointState, LinkQuery, LinkStatus, Struct
from rob6.robots import DEFAULT_ROBOT

__all__ = ["System", "ask_driver", "driver_state", "link_status", "running", "zenoh_router"]

R = TypeVar("R")

#: the systems started since the current test began (tests/conftest.py clears it and, when the
#: test fails, shows their output: the services' warnings say what a failure's error cannot)
STARTED: list[System] = []


class System:
    """A running ``rob6 run`` (router, services, gateway) on free ports."""

    def __init__(self, robot: str = DEFAULT_ROBOT, *, dummy: bool = True, services: tuple[str, ...] = (),
                 restart: bool = False, log_dir: str | None = None, extra_env: dict[str, str] | None = None) -> None:
        self.robot = robot
        self.port = free_port()
        self.router_port = free_port()
        self.robot_id = "test"
        argv = [sys.executable, "-m", "rob6.cli", "run", "--robot", robot, "--robot-id", self.robot_id,
                "--port", str(self.port), "--router-port", str(self.router_port),
                "--dummy" if dummy else "--real-time", "--restart" if restart else "--no-restart"]
        for service in services:
            argv += ["--service", service]
        # no live view unless a test asks for one: systems of a test run must not race for 8765
        env = {**os.environ, "ROB6_LIVE_PORT": "0", **(extra_env or {})}
        if log_dir:
            env["ROB6_LOG_DIR"] = log_dir
        self.output: list[str] = []
        STARTED.append(self)
        self._ready = threading.Event()
        self.process: subprocess.Popen[str] = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self._collector = threading.Thread(target=self._collect, daemon=True)
        self._collector.start()

    def _collect(self) -> None:
        assert self.process.stdout is not None  # stdout=PIPE
        for line in self.process.stdout:
            self.output.append(line.rstrip("\n"))
            if line.startswith("rob6 ready"):
                self._ready.set()

    def wait_ready(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while not self._ready.wait(0.1):
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("rob6 did not start:\n" + "\n".join(self.output[-40:]))

    def pids(self) -> dict[str, int]:
        """Service name -> pid of the processes the launcher started."""
        out = subprocess.run(["ps", "-o", "pid=,args=", "--ppid", str(self.process.pid)],
                             capture_output=True, check=False, text=True).stdout
        pids = {}
        for line in out.splitlines():
            pid, _, args = line.strip().partition(" ")
            for token in args.split():
                if token.startswith("rob6_"):
                    pids[token[5:]] = int(pid)
                elif token == "router":
                    pids["router"] = int(pid)
        return pids

    def client(self, **kwargs: Any) -> Client:
        return Client(self.port, **kwargs)

    def bus(self, service: str = "test") -> Bus:
        """A bus session on this system's router, for this robot (the caller closes it)."""
        return Bus(BusSettings(robot=self.robot, robot_id=self.robot_id,
                               connect=(f"tcp/127.0.0.1:{self.router_port}",)), service)

    def stop(self, timeout: float = 30.0) -> int:
        """Ctrl-C (SIGINT to ``rob6 run``), and its exit code once everything it started has
        ended and all of its output is in ``output``; killed if it hangs for ``timeout``."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()  # its children follow it (rob6.service.follow_launcher)
                self.process.wait()
        self._collector.join(timeout)  # the pipe ends when the last of its children did
        return self.process.returncode


@contextmanager
def running(robot: str = DEFAULT_ROBOT, **kwargs: Any) -> Iterator[System]:
    system = System(robot, **kwargs)
    try:
        system.wait_ready()
        yield system
    finally:
        system.stop()


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


def ask_driver(system: System, op: str, body: Struct, reply: type[R]) -> R:
    """The driver's ``reply`` to ``op``, asked over the system's Zenoh router like any service would."""
    bus = system.bus()
    try:
        bus.wait_for(["driver"], 10)
        answer: R = bus.request("driver", op, body)
        return answer
    finally:
        bus.close()


def driver_state(system: System) -> JointState:
    """The driver's state."""
    return ask_driver(system, "state", Empty(), JointState)


def link_status(system: System) -> LinkStatus:
    """The state of the driver's link to the robot."""
    return ask_driver(system, "link", LinkQuery(), LinkStatus)
