"""The system harness of the tests and the benchmarks: start a real rob6 system (``rob6 run``)
from Python and talk to it like a client (``running``, ``System``, ``Client``), a Zenoh
router in-process (``zenoh_router``), free ports, and where the ground truth lives.

Development only: the product (``shared/rob6``, ``services/*``) never imports it.
"""

from __future__ import annotations

import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import zenoh

from rob6.bus import Bus, zenoh_config
from rob6.config import BusSettings
from rob6.messages import Empty, JointState, LinkQuery, LinkStatus, Struct
from rob6.robots import DEFAULT_ROBOT

__all__ = ["CONFORMANCE", "REPO", "SHARED", "TEST_PORTS", "Client", "System", "driver_state", "free_port",
           "running", "zenoh_router"]

REPO = Path(__file__).resolve().parents[1]
#: the original server's transcripts, kept with the tests (tests/transcripts/ORIGIN.md)
CONFORMANCE = REPO / "tests" / "transcripts"
#: where they are refreshed from: the ground truth beside the project, when present
SHARED = Path(os.environ.get("ROB6_SHARED", REPO.parent / "shared")).resolve()


#: Ports handed out for tests: below Linux's ephemeral range (32768-60999), where the
#: kernel picks the local port of every outgoing connection; a port the kernel gave us
#: from that range can be taken by someone's connection before our server binds it
TEST_PORTS = range(20000, 32768)


R = TypeVar("R")


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A port nothing listens on (TCP, or UDP with ``socket.SOCK_DGRAM``), on any address."""
    for _ in range(200):
        port = random.choice(TEST_PORTS)
        with socket.socket(socket.AF_INET, kind) as sock:
            try:
                sock.bind(("0.0.0.0", port))
            except OSError:
                continue
            return port
    raise RuntimeError("no free port for a test")


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
        self._ready = threading.Event()
        self.process: subprocess.Popen[str] = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, start_new_session=True)
        threading.Thread(target=self._collect, daemon=True).start()

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

    def stop(self, timeout: float = 5.0) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        return self.process.returncode


@contextmanager
def running(robot: str = DEFAULT_ROBOT, **kwargs: Any) -> Iterator[System]:
    system = System(robot, **kwargs)
    try:
        system.wait_ready()
        yield system
    finally:
        system.stop()


class Client:
    """A raw TCP client of the gateway."""

    def __init__(self, port: int, *, host: str = "127.0.0.1", handshake: bool = True, timeout: float = 10.0) -> None:
        self.sock = socket.create_connection((host, port), timeout=timeout)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.timeout = timeout
        self.buffer = b""
        self.greeting = self.read_lines(1)
        if handshake:
            assert self.greeting == "welcome to rob6server 0.1.01 !\n", self.greeting
            assert self.ask("Hello Robot") == "accepted\n"

    def send(self, data: bytes | str) -> None:
        self.sock.sendall(data.encode("latin-1") if isinstance(data, str) else data)

    def read_lines(self, count: int, timeout: float | None = None) -> str:
        """Exactly ``count`` lines (or what came before EOF/timeout)."""
        self.sock.settimeout(timeout or self.timeout)
        while self.buffer.count(b"\n") < count and self._receive():
            pass
        lines = self.buffer.split(b"\n")
        taken = b"".join(line + b"\n" for line in lines[:count]) if len(lines) > count else self.buffer
        self.buffer = self.buffer[len(taken):]
        return taken.decode("latin-1")

    def _receive(self) -> bool:
        """One chunk into the buffer; False at the socket's timeout or at EOF."""
        try:
            chunk = self.sock.recv(65536)
        except TimeoutError:
            return False
        if not chunk:
            return False
        self.buffer += chunk
        return True

    def read_quiet(self, quiet: float = 0.15) -> str:
        """Whatever arrives until nothing more comes for ``quiet`` seconds."""
        self.sock.settimeout(quiet)
        while self._receive():
            pass
        data, self.buffer = self.buffer, b""
        return data.decode("latin-1")

    def ask(self, command: str, lines: int = 1, timeout: float | None = None) -> str:
        self.send(command + "\n")
        return self.read_lines(lines, timeout)

    def closed(self, timeout: float = 2.0) -> bool:
        """True when the server closed the connection (EOF) within ``timeout``."""
        self.sock.settimeout(timeout)
        try:
            return self.sock.recv(1) == b""
        except TimeoutError:
            return False
        except ConnectionError:
            return True

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
