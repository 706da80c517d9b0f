"""Run the multi-host topology (deploy/multihost/docker-compose.yml) and make its network faults.

Used by tests/deploy/multihost and bench/multihost.py.

A host is a network namespace owned by its holder container (robot-pc, compute1, compute2,
storage). Faults are made from this machine with the real tools:

- ``netem(host, delay_ms, jitter_ms, loss)``: iptables NFQUEUE rules in the host's namespace
  for its traffic with the robot PC, and deploy/multihost/nfq_netem.py holding/dropping the
  queued packets (``tc qdisc ... netem`` where the kernel has sch_netem, else NFQUEUE: both
  are run with ``nsenter -t <pid> -n``; root needed);
- ``partition(host)``: ``docker network disconnect`` from the lab network, ``connect`` back
  with the same address (a pulled cable, not a new machine);
- ``docker kill`` / ``pause`` of a container (a router, a host).

Images: ``rob6/<service>:<tag>`` as deploy/build-images.sh builds them (harness/images.py).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import random
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from harness.client import Client, connect
from harness.compose import compose_cmd, project_containers, run, unhealthy
from harness.images import TAG
from harness.ports import free_port

REPO = Path(__file__).resolve().parents[1]
COMPOSE_FILE = REPO / "deploy" / "multihost" / "docker-compose.yml"
REALTIME_FILE = REPO / "deploy" / "multihost" / "realtime.yml"
#: Docker's parent cgroup on a cgroup v1 host (cgroupfs driver): its real-time budget bounds
#: the containers' (deploy/multihost/realtime.yml)
DOCKER_RT_RUNTIME = Path("/sys/fs/cgroup/cpu/docker/cpu.rt_runtime_us")
#: of every second, for each of the driver and the stand-in KR C4: a real-time task past its
#: budget is stopped for the rest of the second (measured with 100 ms: the KR C4 lost the link
#: for 100 ms and counted 60-80 late packets a second), so the budget is not what limits them
RT_RUNTIME_US = 400_000
NETEM = REPO / "deploy" / "multihost" / "nfq_netem.py"
HOSTS = ("robot-pc", "compute1", "compute2", "storage")
SERVICES = ("router-pc", "gateway", "planner", "driver", "gripper", "router-compute", "kinematics-c1",
            "kinematics-c2", "recorder")
REMOTE_KINEMATICS = ("kinematics-c1", "kinematics-c2")
REMOTE_HOSTS = ("compute1", "compute2")  # the compute hosts, whose links the faults slow down
FK_LINE = "ForwardCalc 10 -20 30 40 50 60"
JOINTS = (10.0, -20.0, 30.0, 40.0, 50.0, 60.0)


def cannot_run() -> str | None:
    """Why the multi-host suites cannot run here (None: they can): a Docker engine, compose,
    and the tools to make faults."""
    if not shutil.which("docker") or subprocess.run(["docker", "info"], capture_output=True, check=False, timeout=30).returncode:
        return "no Docker engine here"
    if compose_cmd() is None:
        return "no docker compose here"
    return fault_tools_missing()


def fault_tools_missing() -> str | None:
    """Why faults cannot be made here (None: they can): root, nsenter, iptables, NFQUEUE."""
    if os.geteuid() != 0:
        return "making network faults needs root (nsenter into the containers' namespaces)"
    for tool in ("nsenter", "iptables"):
        if not shutil.which(tool):
            return f"{tool} is not installed on this machine"
    return None


def free_subnet() -> str:
    """A /24 for the lab network that no docker network uses yet."""
    used = set()
    for net in run(["docker", "network", "ls", "-q"]).stdout.split():
        info = json.loads(run(["docker", "network", "inspect", net]).stdout)[0]
        for cfg in (info.get("IPAM") or {}).get("Config") or []:
            used.add(cfg.get("Subnet", ""))
    while True:
        subnet = f"10.{random.randint(100, 250)}.{random.randint(0, 255)}.0/24"
        if subnet not in used:
            return subnet


@dataclass
class Topology:
    """One project of deploy/multihost/docker-compose.yml."""

    project: str
    replicas_c1: int = 2
    local_kinematics: bool = False
    #: the driver on RSI to the stand-in KR C4 on the robot network (kr16rt, --profile rsi)
    rsi: bool = False
    port: int = field(default_factory=free_port)
    subnet: str = field(default_factory=free_subnet)
    #: the services' Docker health checks: often for the tests, which wait for them; rarely
    #: for a benchmark, because each check is a Python process opening a Zenoh session
    #: (~0.3 s of CPU): at 2 s the robot's nine services took over a core of two
    health_interval: str = "2s"

    def __post_init__(self) -> None:
        cmd = compose_cmd()
        if cmd is None:
            raise RuntimeError("no docker compose here")
        self._compose = cmd
        self.env_file = Path(os.environ.get("TMPDIR", "/tmp")) / f"{self.project}.env"
        self.env_file.write_text("")
        self.env = {**os.environ, "ROB6_TAG": TAG, "ROB6_PORT": str(self.port), "ROB6_LAB_SUBNET": self.subnet,
                    "ROB6_HEALTH_INTERVAL": self.health_interval}
        self.control_port = free_port() if self.rsi else 0
        self._docker_rt_before: str | None = None
        if self.rsi:
            self.env.update(ROB6_ROBOT="kr16rt", ROB6_LINK="rsi", ROB6_KUKA_SIM_CONTROL_PORT=str(self.control_port),
                            ROB6_RT_RUNTIME=self._realtime_budget())
        self._netem: list[tuple[str, subprocess.Popen[str], list[list[str]]]] = []

    # ------------------------------------------------------------------ compose
    def compose(self, *args: str, timeout: float = 300, check: bool = True) -> subprocess.CompletedProcess[str]:
        profiles = [*(["--profile", "local-kinematics"] if self.local_kinematics else []),
                    *(["--profile", "rsi"] if self.rsi else [])]
        files = ["-f", str(COMPOSE_FILE), *(["-f", str(REALTIME_FILE)] if self.rsi else [])]
        return run([*self._compose, "-p", self.project, *files, "--env-file", str(self.env_file),
                    *profiles, *args], timeout=timeout, check=check, env=self.env, cwd=REPO)

    def _realtime_budget(self) -> str:
        """ROB6_RT_RUNTIME for realtime.yml. On a cgroup v1 host Docker's parent cgroup gets
        room for the two real-time containers first (its default is none; given back in
        ``down``); a cgroup v2 host has no real-time group budget to set: 0ms."""
        if not DOCKER_RT_RUNTIME.exists():
            return "0ms"
        current = DOCKER_RT_RUNTIME.read_text().strip()
        if int(current) < 2 * RT_RUNTIME_US:
            DOCKER_RT_RUNTIME.write_text(str(2 * RT_RUNTIME_US))
            self._docker_rt_before = current
        return f"{RT_RUNTIME_US // 1000}ms"

    def up(self, timeout: float = 240) -> float:
        """Start everything; seconds until every service is healthy."""
        start = time.monotonic()
        services = [*HOSTS, *self._services()]
        self.compose("up", "-d", "--no-build", "--scale", f"kinematics-c1={self.replicas_c1}", *services)
        self.wait_healthy(timeout=timeout)
        return time.monotonic() - start

    def _services(self) -> list[str]:
        return [*SERVICES, *(["kinematics-pc"] if self.local_kinematics else []),
                *(["kuka-rsi-sim"] if self.rsi else [])]

    def containers(self, service: str | None = None) -> list[str]:
        return project_containers(self.project, service)

    def container(self, service: str) -> str:
        ids = self.containers(service)
        if not ids:
            raise RuntimeError(f"no container for {service} in {self.project}")
        return ids[0]

    def inspect(self, container: str, fmt: str) -> str:
        return run(["docker", "inspect", "-f", fmt, container]).stdout.strip()

    def wait_healthy(self, services: tuple[str, ...] | None = None, timeout: float = 240) -> None:
        deadline = time.monotonic() + timeout
        wanted = services or self._services()
        while True:
            pending = unhealthy(self.project, wanted)
            if not pending:
                return
            if time.monotonic() > deadline:
                logs = self.compose("logs", "--tail", "20", check=False).stdout
                raise RuntimeError(f"not healthy after {timeout:.0f} s: {pending}\n{logs[-5000:]}")
            time.sleep(1)

    def down(self) -> None:
        for host in list({h for h, _p, _r in self._netem}):
            self.clear_netem(host)
        if os.environ.get("ROB6_E2E_KEEP") == "1":
            print(f"\nROB6_E2E_KEEP=1: project {self.project} left running")
            return
        self.compose("down", "-v", "--remove-orphans", "-t", "3", check=False, timeout=180)
        self.env_file.unlink(missing_ok=True)
        if self._docker_rt_before is not None:
            with contextlib.suppress(OSError):  # refused while another container keeps a budget
                DOCKER_RT_RUNTIME.write_text(self._docker_rt_before)

    # ------------------------------------------------------------------ hosts
    @property
    def lab(self) -> str:
        return f"{self.project}_lab"

    def pid(self, host: str) -> int:
        return int(self.inspect(self.container(host), "{{.State.Pid}}"))

    def ip(self, host: str) -> str:
        return self.inspect(self.container(host), "{{(index .NetworkSettings.Networks \"%s\").IPAddress}}" % self.lab)

    # ------------------------------------------------------------------ faults
    def netem(self, host: str, *, delay_ms: float = 0.0, jitter_ms: float = 0.0, loss: float = 0.0,
              reorder: float = 0.0, peer: str = "robot-pc") -> None:
        """Delay/jitter/loss/reordering on every packet between ``host`` and ``peer``, both
        ways (so ``delay_ms`` is the added one-way delay), until ``clear_netem(host)``."""
        self.clear_netem(host)
        pid, peer_ip = self.pid(host), self.ip(peer)
        queue = 10 + HOSTS.index(host)
        ns = ["nsenter", "-t", str(pid), "-n"]
        rules = [["OUTPUT", "-d", peer_ip], ["INPUT", "-s", peer_ip]]
        # real-time priority: on a busy machine a packet must not wait for the emulator's turn
        # on the CPU (that would add the machine's scheduling delay to the one asked for)
        rt = ["chrt", "-f", "20"] if shutil.which("chrt") else []
        proc = subprocess.Popen([*ns, *rt, sys.executable, str(NETEM), "--queue", str(queue), "--delay-ms", str(delay_ms),
                                 "--jitter-ms", str(jitter_ms), "--loss", str(loss), "--reorder", str(reorder)],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        line = proc.stdout.readline() if proc.stdout else ""
        if not line.startswith("nfq_netem: queue"):
            proc.kill()
            raise RuntimeError(f"nfq_netem did not start in {host}: {line}")
        added = []
        for chain, *match in rules:
            run([*ns, "iptables", "-I", chain, *match, "-j", "NFQUEUE", "--queue-num", str(queue), "--queue-bypass"])
            added.append([*ns, "iptables", "-D", chain, *match, "-j", "NFQUEUE", "--queue-num", str(queue),
                          "--queue-bypass"])
        self._netem.append((host, proc, added))

    def clear_netem(self, host: str) -> None:
        for entry in [e for e in self._netem if e[0] == host]:
            _host, proc, rules = entry
            for rule in rules:
                run(rule, check=False)
            proc.terminate()
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            self._netem.remove(entry)

    @contextlib.contextmanager
    def impaired(self, hosts: tuple[str, ...] = REMOTE_HOSTS, *, delay_ms: float = 0.0, jitter_ms: float = 0.0,
                 loss: float = 0.0, reorder: float = 0.0) -> Iterator[None]:
        """``netem`` on each of ``hosts``' links with the robot PC until the block ends."""
        for host in hosts:
            self.netem(host, delay_ms=delay_ms, jitter_ms=jitter_ms, loss=loss, reorder=reorder)
        try:
            yield
        finally:
            for host in hosts:
                self.clear_netem(host)

    @contextlib.contextmanager
    def partitioned(self, *hosts: str) -> Iterator[None]:
        """The hosts lose the lab network (cable pulled) until the block ends."""
        addresses = {h: self.ip(h) for h in hosts}
        for host in hosts:
            run(["docker", "network", "disconnect", self.lab, self.container(host)])
        try:
            yield
        finally:
            for host, address in addresses.items():
                run(["docker", "network", "connect", "--ip", address, "--alias", host, self.lab, self.container(host)])

    # ------------------------------------------------------------------ the KR C4 (rsi)
    def kuka(self) -> dict[str, Any]:
        """The stand-in KR C4's status (its control channel): state, trips, late_total, aipos..."""
        with socket.create_connection(("127.0.0.1", self.control_port), timeout=10) as sock, \
                sock.makefile("rwb") as control:
            control.write(b'{"cmd": "status"}\n')
            control.flush()
            status: dict[str, Any] = json.loads(control.readline())
            return status

    # ------------------------------------------------------------------ the client's side
    def client(self, attempts: int = 50) -> Client:
        return connect(self.port, attempts=attempts, timeout=15)


def backward_line(client: Client) -> str:
    """A BackwardCalc line that succeeds (the pose of FK_LINE and its status); asks again while
    kinematics answers ``ERROR: ...`` / ``false`` (e.g. right after a partition healed)."""
    deadline = time.monotonic() + 60
    while True:
        reply = ask_reply(client, FK_LINE, timeout=15)
        if not reply.startswith("ERROR"):
            pose, status = reply, client.read_lines(1, timeout=15)
            return f"BackwardCalc {pose.strip()} {status.strip()}"
        if time.monotonic() > deadline:
            raise RuntimeError(f"{FK_LINE} -> {reply.strip()}")
        time.sleep(0.2)


def ask_true(client: Client, line: str) -> None:
    """``line`` (a command answering true or false) answered ``true``, asked once: a lab's
    client does not send a move twice, so neither does the test. An ``ERROR: ...`` line is
    read with its ``false`` and shown in the failure."""
    reply = ask_reply(client, line, timeout=30)
    assert reply == "true\n", (line, reply)


def alter_session(client: Client) -> int:
    """2 s of Alter targets at 250 Hz (a sine on A1), then a final one, reached; returns how
    many targets were refused with an ERROR line (a busy machine: the driver's reply came
    later than the quick-call deadline; the next target replaces it)."""
    ask_true(client, "EnableAlter")
    here = [float(x) for x in client.ask("GetPositionJoints").split()]
    refused = 0
    for k in range(500):
        target = list(here)
        target[0] += 3.0 * math.sin(2 * math.pi * 0.5 * k / 250)
        reply = client.ask("MoveRTJoints " + " ".join(f"{x:f}" for x in target))
        assert reply == "true\n" or reply.startswith("ERROR: driver"), reply
        if reply != "true\n":
            assert client.read_lines(1, timeout=30) == "false\n"  # ERROR: ... then false
        refused += reply != "true\n"
        time.sleep(0.004)
    final = list(here)
    final[0] += 2.0
    ask_true(client, "MoveRTJoints " + " ".join(f"{x:f}" for x in final))
    time.sleep(1.5)
    reached = [float(x) for x in client.ask("GetPositionJoints").split()]
    assert all(abs(a - b) < 1e-3 for a, b in zip(reached, final, strict=True)), (reached, final)
    ask_true(client, "DisableAlter")
    return refused


def correct(reply: str) -> bool:
    try:
        values = [float(x) for x in reply.split()]
    except ValueError:
        return False
    return len(values) == 6 and all(abs(a - b) < 1e-3 for a, b in zip(values, JOINTS, strict=True))


@dataclass
class Call:
    t: float  # monotonic time the call was sent
    seconds: float
    reply: str

    @property
    def ok(self) -> bool:
        return correct(self.reply)

    @property
    def error(self) -> bool:
        return self.reply.startswith("ERROR")


def ask_reply(client: Client, line: str, timeout: float) -> str:
    """The first line of ``line``'s reply; an ``ERROR: ...`` line's ``false`` after it (the
    gateway answers a failed BackwardCalc or ForwardCalc with both) is read too, and checked."""
    reply = client.ask(line, timeout=timeout)
    if reply.startswith("ERROR"):
        after = client.read_lines(1, timeout=timeout)
        assert after == "false\n", (line, reply, after)
    return reply


def calls(client: Client, line: str, count: int, timeout: float = 10.0) -> list[Call]:
    out = []
    for _ in range(count):
        t = time.monotonic()
        reply = ask_reply(client, line, timeout)
        out.append(Call(t, time.monotonic() - t, reply))
    return out


class Load:
    """A client calling ``line`` in a loop on its own thread until stopped."""

    def __init__(self, client: Client, line: str, pause: float = 0.01, timeout: float = 10.0) -> None:
        self.client, self.line, self.pause, self.timeout = client, line, pause, timeout
        self.calls: list[Call] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            t = time.monotonic()
            reply = ask_reply(self.client, self.line, self.timeout)
            self.calls.append(Call(t, time.monotonic() - t, reply))
            if not reply:  # no answer within the timeout: a hang; stop here
                return
            time.sleep(self.pause)

    def __enter__(self) -> Load:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(self.timeout + 5)


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    return ordered[min(len(ordered) - 1, max(0, round(q / 100 * (len(ordered) - 1))))]


def recovery(calls_: list[Call], since: float, streak: int = 20) -> float | None:
    """Seconds from ``since`` until the start of the first run of ``streak`` successful calls
    (a lone late reply on a busy machine afterwards does not count as not recovered)."""
    after = [c for c in calls_ if c.t >= since]
    run_start, length = None, 0
    for c in after:
        if c.ok:
            run_start = c.t if length == 0 else run_start
            length += 1
            if length >= streak and run_start is not None:
                return max(0.0, run_start - since)
        else:
            length = 0
    return None
