"""``rob6 run``: the whole system on one machine (router, services, gateway).

Each service is its own OS process. Before starting anything the launcher checks that
its ports are free, so a second ``rob6 run`` (an everyday slip) ends at once with one
line naming the cause and the fix. ``ready`` is printed only when every service is
alive and the gateway listens. A child that fails to start ends the whole start (no
restart loop for what a restart cannot fix); a child that crashes at run time is
reported and restarted (unless ``--no-restart``), except one that exits with
``EXIT_REFUSED`` (another owner of the robot, a bad setting). Ctrl-C, SIGTERM or a
client's ``Shutdown`` stop everything in order: the gateway first (no new commands),
then the services, the recorder last (so the end of every session is in its file),
then the router.
"""

from __future__ import annotations

import errno
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import click

from .bus import Bus
from .config import DEFAULT_LIVE_PORT, BusSettings
from .ownership import EXIT_REFUSED
from .service import StartupError

#: stop order, and how long each group may take before it is killed: long enough for a
#: clean stop on a busy machine (the gateway waits for the arm to come to rest, the
#: recorder finishes its files), so a kill means something is wrong and is reported
STOP_ORDER = ((("gateway",), 15.0), (("ros",), 5.0), (("planner",), 5.0),
              (("driver", "gripper", "kinematics"), 5.0), (("recorder",), 10.0), (("router",), 5.0))


@dataclass
class Child:
    name: str
    argv: list[str]
    process: subprocess.Popen[bytes] | None = None  # None until spawned
    restarts: int = 0
    next_start: float = 0.0
    exits: list[int] = field(default_factory=list)


class Launcher:
    def __init__(self, *, robot: str, robot_id: str, port: int, router_port: int, log_dir: str,
                 dummy: bool, allow_shutdown: bool, restart: bool, services: tuple[str, ...],
                 log_level: str, echo: Callable[..., object] = click.echo):
        self.robot, self.port, self.router_port = robot, port, router_port
        self.restart = restart
        self.echo = echo
        self.endpoint = f"tcp/127.0.0.1:{router_port}"
        self.env = dict(os.environ, ROB6_ROBOT=robot, ROB6_ROBOT_ID=robot_id, ROB6_PORT=str(port),
                        ROB6_LOG_DIR=log_dir, ROB6_DUMMY="1" if dummy else "0",
                        ROB6_ZENOH_CONNECT=self.endpoint, ROB6_LOG_LEVEL=log_level,
                        ROB6_ALLOW_SHUTDOWN="1" if allow_shutdown else "0",
                        ROB6_SERVICES=",".join(services), ROB6_LAUNCHER_PID=str(os.getpid()))
        self.env.pop("ROB6_ZENOH_LISTEN", None)
        self.settings = BusSettings(robot=robot, robot_id=robot_id, connect=(self.endpoint,))
        self.router = Child("router", [sys.executable, "-m", "rob6.cli", "router",
                                       "--listen", self.endpoint])
        self.children = [Child(name, [sys.executable, "-m", f"rob6_{name}"]) for name in services]
        self.stopping = threading.Event()
        self.bus: Bus | None = None
        self.live_url: str | None = None  # the live view's address, once preflight checked its port

    # ------------------------------------------------------------------ processes
    def _spawn(self, child: Child) -> None:
        # a group of its own: a terminal's Ctrl-C reaches the launcher alone, which stops the
        # children in STOP_ORDER (always from this thread: see rob6.service.follow_launcher)
        child.process = subprocess.Popen(child.argv, env=self.env, stdin=subprocess.DEVNULL, process_group=0)

    def preflight(self) -> None:
        """Everything a start can be refused for, checked before anything starts."""
        names = {c.name for c in self.children}
        if "gateway" in names:
            bind = self.env.get("ROB6_BIND", "0.0.0.0")
            _check_free(socket.SOCK_STREAM, bind, self.port,
                        f"the client port {bind}:{self.port} is in use: is rob6 (or rob6server) already "
                        f"running? Stop it, or choose another port with ROB6_PORT")
        if "recorder" in names:
            self._live_preflight()
        _check_free(socket.SOCK_STREAM, "127.0.0.1", self.router_port,
                    f"the Zenoh router port 127.0.0.1:{self.router_port} is in use: is rob6 already running? "
                    f"Stop it, or choose another port with ROB6_ROUTER_PORT")
        if "driver" in names and self.env.get("ROB6_LINK", "sim") == "rsi":
            listen = self.env.get("ROB6_RSI_LISTEN", "0.0.0.0:49152")
            host, _, port = listen.rpartition(":")
            if not host or not port.isdigit():
                raise StartupError(f"ROB6_RSI_LISTEN={listen!r}: expected HOST:PORT, e.g. 0.0.0.0:49152")
            _check_free(socket.SOCK_DGRAM, host.strip("[]"), int(port),
                        f"the RSI port udp/{listen} is in use: is another rob6 driving the robot? "
                        f"Stop it, or set ROB6_RSI_LISTEN")

    def _live_preflight(self) -> None:
        """The recorder serves the live view: its address, or off when its port is taken (a
        view is not worth refusing to drive the robot for)."""
        text = self.env.get("ROB6_LIVE_PORT", str(DEFAULT_LIVE_PORT)).strip() or "0"
        if not text.isdigit():
            raise StartupError(f"ROB6_LIVE_PORT={text!r}: expected a port number (0 = no live view)")
        port = int(text)
        if port == 0:
            return
        bind = self.env.get("ROB6_BIND", "0.0.0.0")
        try:
            _check_free(socket.SOCK_STREAM, bind, port, "")
        except StartupError:
            self.echo(f"rob6: live view off: port {bind}:{port} is in use (another rob6?); "
                      f"choose one with ROB6_LIVE_PORT", err=True)
            self.env["ROB6_LIVE_PORT"] = "0"
            return
        self.env["ROB6_LIVE_PORT"] = str(port)
        scheme = "wss" if self.env.get("ROB6_LIVE_TLS_CERT") else "ws"
        host = "127.0.0.1" if bind in ("0.0.0.0", "::", "") else bind
        self.live_url = f"{scheme}://{host}:{port}"

    def start(self, ready_timeout: float = 60.0) -> None:
        """Start the router and every service; returns once all are alive, else raises StartupError."""
        self.preflight()
        self._spawn(self.router)
        if not _wait_port(self.router_port, 10.0, self.router):
            raise StartupError(f"the Zenoh router did not start on port {self.router_port} (see above)")
        self.bus = Bus(self.settings, "launcher")
        self.bus.subscribe("control/shutdown", lambda *_: self.stopping.set())
        for child in self.children:
            self._spawn(child)
        # the gateway announces itself once it listens (after the services it needs), so
        # its token means a client gets real answers
        deadline = time.monotonic() + ready_timeout
        waiting = [c.name for c in self.children]
        while waiting:
            for child in (self.router, *self.children):
                code = child.process.poll() if child.process else None
                if code is not None:
                    raise StartupError(f"{child.name} failed to start (exit code {code}, see above)")
            if self.stopping.is_set():
                raise StartupError("stopped before the system was ready")
            if time.monotonic() > deadline:
                raise StartupError(f"not ready after {ready_timeout:.0f} s, still waiting for {', '.join(waiting)}")
            waiting = [name for name in waiting if not self.bus.instances(name)]
            time.sleep(0.02)

    def supervise(self) -> int:
        """Watch the children until stopped; returns the exit code for ``rob6 run``."""
        while not self.stopping.wait(0.1):
            # the router too: Zenoh sessions reconnect to it by themselves once it is back
            for child in (self.router, *self.children):
                if not self._check(child):
                    return 1
            if self.router.process is None and not self.restart:
                self.echo("rob6: without the Zenoh router nothing can talk; stopping", err=True)
                return 1
        return 0

    def _check(self, child: Child) -> bool:
        """False when the system cannot go on (a child refused to run)."""
        process = child.process
        now = time.monotonic()
        if process is None:
            if now >= child.next_start:
                self.echo(f"rob6: restarting {child.name}", err=True)
                self._spawn(child)
            return True
        code = process.poll()
        if code is None:
            return True
        child.exits.append(code)
        child.process = None
        if code == EXIT_REFUSED:
            self.echo(f"rob6: {child.name} refused to run (see above); a restart cannot fix that: stopping",
                      err=True)
            return False
        self.echo(f"rob6: {child.name} exited with code {code}", err=True)
        if not self.restart:
            child.next_start = float("inf")  # reported; stays down
            return True
        child.restarts += 1
        child.next_start = now + min(10.0, 0.5 * 2 ** min(child.restarts - 1, 5))
        return True

    def stop(self) -> bool:
        """Stop every child in STOP_ORDER; True when each exited 0 by itself (what was not is
        said in one line)."""
        self.stopping.set()
        if self.bus is not None:
            self.bus.close()
        clean = True
        by_name = {c.name: c for c in (*self.children, self.router)}
        for names, grace in STOP_ORDER:
            # those still running: one that ended before was reported when it did
            group = [c for n in names if (c := by_name.get(n)) is not None and c.process is not None
                     and c.process.poll() is None]
            killed = _terminate(group, grace)
            for child in group:
                assert child.process is not None
                if child in killed:
                    self.echo(f"rob6: {child.name} did not stop within {grace:.0f} s; killed", err=True)
                elif child.process.returncode != 0:
                    self.echo(f"rob6: {child.name} stopped with exit code {child.process.returncode}", err=True)
                clean = clean and child.process.returncode == 0 and child not in killed
        return clean


def _terminate(children: list[Child], grace: float) -> list[Child]:
    """SIGTERM to each, then up to ``grace`` seconds in all; returns those that had to be killed."""
    for child in children:
        assert child.process is not None
        child.process.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + grace
    killed = []
    for child in children:
        assert child.process is not None
        try:
            child.process.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            child.process.kill()
            child.process.wait()
            killed.append(child)
    return killed


def _check_free(kind: int, host: str, port: int, message: str) -> None:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, kind) as sock:
        if kind == socket.SOCK_STREAM:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the servers bind
        try:
            sock.bind((host, port))
        except OSError as exc:
            if exc.errno in (errno.EADDRINUSE, errno.EACCES):
                raise StartupError(message) from None
            raise StartupError(f"cannot use {host}:{port}: {exc.strerror}") from None


def _wait_port(port: int, timeout: float, child: Child | None = None) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if child is not None and child.process is not None and child.process.poll() is not None:
            return False
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False


def run(**options: Any) -> int:
    launcher = Launcher(**options)
    for signum in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):  # SIGHUP: the terminal closed
        signal.signal(signum, lambda *_: launcher.stopping.set())
    code = 1
    try:
        launcher.start()
        if launcher.live_url:  # before the ready line: whoever waits for it sees both
            click.echo(f"live view: {launcher.live_url} (open in Foxglove: Open connection > "
                       f"Foxglove WebSocket)", err=True)
        click.echo(f"rob6 ready: robot {launcher.robot} on 127.0.0.1:{launcher.port} "
                   f"(Zenoh router {launcher.endpoint}); Ctrl-C stops everything", err=True)
        code = launcher.supervise()
    except StartupError as exc:
        click.echo(f"rob6: {exc}", err=True)
    finally:
        clean = launcher.stop()
    return code or (0 if clean else 1)
