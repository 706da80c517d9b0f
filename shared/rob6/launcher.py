"""``rob6 run``: the whole system on one machine (router, services, gateway).

Each service is its own OS process. The launcher reports a service (or the Zenoh
router) that dies and restarts it unless told not to, stops everything on
Ctrl-C/SIGTERM within about two seconds, and stops everything after a client's
``Shutdown``.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field

import click

from .bus import Bus
from .config import BusSettings

SERVICES = ("driver", "kinematics", "planner", "gripper", "recorder", "gateway")
STOP_GRACE_S = 1.5


@dataclass
class Child:
    name: str
    argv: list[str]
    process: subprocess.Popen | None = None
    restarts: int = 0
    next_start: float = 0.0
    exits: list[int] = field(default_factory=list)


class Launcher:
    def __init__(self, *, robot: str, robot_id: str, port: int, router_port: int, log_dir: str,
                 dummy: bool, allow_shutdown: bool, restart: bool, services: tuple[str, ...],
                 log_level: str, echo=click.echo):
        self.robot, self.port, self.router_port = robot, port, router_port
        self.restart = restart
        self.echo = echo
        self.endpoint = f"tcp/127.0.0.1:{router_port}"
        self.env = dict(os.environ, ROB6_ROBOT=robot, ROB6_ROBOT_ID=robot_id, ROB6_PORT=str(port),
                        ROB6_LOG_DIR=log_dir, ROB6_DUMMY="1" if dummy else "0",
                        ROB6_ZENOH_CONNECT=self.endpoint, ROB6_LOG_LEVEL=log_level,
                        ROB6_ALLOW_SHUTDOWN="1" if allow_shutdown else "0")
        self.env.pop("ROB6_ZENOH_LISTEN", None)
        self.settings = BusSettings(robot=robot, robot_id=robot_id, connect=(self.endpoint,))
        self.router = Child("router", [sys.executable, "-m", "rob6.cli", "router",
                                       "--listen", self.endpoint])
        self.children = [Child(name, [sys.executable, "-m", f"rob6_{name}"]) for name in services]
        self.stopping = threading.Event()
        self.bus: Bus | None = None

    # ------------------------------------------------------------------ processes
    def _spawn(self, child: Child) -> None:
        child.process = subprocess.Popen(child.argv, env=self.env, stdin=subprocess.DEVNULL)

    def start(self, ready_timeout: float = 30.0) -> bool:
        self._spawn(self.router)
        if not _wait_port(self.router_port, 10.0, self.router):
            self.echo(f"rob6: the Zenoh router did not start on port {self.router_port}", err=True)
            return False
        self.bus = Bus(self.settings, "launcher")
        self.bus.subscribe("control/shutdown", lambda *_: self.stopping.set())
        for child in self.children:
            self._spawn(child)
        services = [c.name for c in self.children]
        # the gateway announces itself once it listens, so its token means the port is open
        missing = self.bus.wait_for(services, ready_timeout)
        if missing:
            self.echo(f"rob6: not ready after {ready_timeout:.0f} s, missing: {', '.join(missing)}", err=True)
            return False
        return True

    def supervise(self) -> int:
        """Watch the children until stopped; returns the exit code for ``rob6 run``."""
        while not self.stopping.wait(0.1):
            # the router too: Zenoh sessions reconnect to it by themselves once it is back
            for child in (self.router, *self.children):
                self._check(child)
            if self.router.process is None and not self.restart:
                self.echo("rob6: without the Zenoh router nothing can talk; stopping", err=True)
                return 1
        return 0

    def _check(self, child: Child) -> None:
        process = child.process
        now = time.monotonic()
        if process is None:
            if now >= child.next_start:
                self.echo(f"rob6: restarting {child.name}", err=True)
                self._spawn(child)
            return
        code = process.poll()
        if code is None:
            return
        child.exits.append(code)
        child.process = None
        self.echo(f"rob6: {child.name} exited with code {code}", err=True)
        if not self.restart:
            child.next_start = float("inf")  # reported; stays down
            return
        child.restarts += 1
        child.next_start = now + min(10.0, 0.5 * 2 ** min(child.restarts - 1, 5))

    def stop(self) -> None:
        self.stopping.set()
        running = [c.process for c in (*self.children, self.router) if c.process and c.process.poll() is None]
        for process in running:
            process.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE_S
        for process in running:
            try:
                process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        if self.bus is not None:
            self.bus.close()


def _wait_port(port: int, timeout: float, child: Child | None = None) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if child is not None and child.process.poll() is not None:
            return False
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False


def run(**options) -> int:
    launcher = Launcher(**options)
    signal.signal(signal.SIGTERM, lambda *_: launcher.stopping.set())
    signal.signal(signal.SIGINT, lambda *_: launcher.stopping.set())
    try:
        if not launcher.start():
            return 1
        click.echo(f"rob6 ready: robot {launcher.robot} on 127.0.0.1:{launcher.port} "
                   f"(Zenoh router {launcher.endpoint}); Ctrl-C stops everything", err=True)
        return launcher.supervise()
    finally:
        launcher.stop()
