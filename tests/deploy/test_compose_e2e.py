"""End-to-end test of the containerized lab deployment (docker-compose.yml, deploy/).

    .venv/bin/python -m pytest tests/deploy/test_compose_e2e.py -s     # -s shows timings and sizes

Runs the images tests/conftest.py built before the first test (deploy/build-images.sh: the
base image, the wheelhouse, `compose build` with the build network off), starts the stack
under a unique project name, replays a conformance subset through the gateway port, kills kinematics mid-session, scales
it, stops everything and reads the MCAP recordings from the volume; then the rsi profile (the
driver on RSI drives the stand-in KR C4 container) and the adept profile (the driver on
simple_message drives the stand-in Adept container); then the secure profile:
the router container's TLS and ACL are probed with zenoh-python (tests/deploy/zenoh_probe.py)
and the system must still work through it. Every project is removed (`down -v`) at the end.

Marked ``docker`` (skip with ``-m 'not docker'`` or ROB6_SKIP_DOCKER=1); skipped when no
Docker engine answers. Env: ROB6_E2E_KEEP=1 keeps the stacks up for inspection.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from pytest import TempPathFactory

from harness import images
from harness.client import connect
from harness.compose import compose_cmd, project_containers, run, unhealthy
from harness.images import BASE_IMAGE, TAG
from harness.ports import free_port
from tests.conformance import CONFORMANCE, load, same
from tests.deploy import zenoh_probe

pytestmark = pytest.mark.docker

REPO = Path(__file__).resolve().parents[2]
DEPLOY = REPO / "deploy"
SERVICES = ("gateway", "kinematics", "planner", "driver", "gripper", "recorder", "ros")
ROBOT = "kr16"
FK = "ForwardCalc 10 -60 80 20 40 30"  # first record of conformance/kr16/fk.jsonl
SUBSET = {"GetRobot", "CM_PING", "GetVersion"}  # + each session's handshake line
REPORT: dict[str, object] = {}  # timings and sizes, printed at the end (pytest -s)


# ---------------------------------------------------------------------- docker helpers
def _docker_ok() -> bool:
    return bool(shutil.which("docker")) and subprocess.run(
        ["docker", "info"], capture_output=True, check=False, timeout=30).returncode == 0


_compose = compose_cmd() if _docker_ok() else None
if _compose is None:
    pytest.skip("no Docker engine or docker compose here", allow_module_level=True)
COMPOSE: list[str] = _compose


@dataclass
class Stack:
    """One compose project: `docker compose -p NAME -f ... --env-file <empty>` with its own ports."""

    project: str
    files: tuple[str, ...] = ("docker-compose.yml",)
    settings: dict[str, str] = field(default_factory=dict)
    port: int = field(default_factory=free_port)
    zenoh_port: int = field(default_factory=free_port)
    profiles: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        # an empty env file: a developer's .env must not change the test
        self.env_file = Path(os.environ.get("TMPDIR", "/tmp")) / f"{self.project}.env"
        self.env_file.write_text("")
        self.env = {**os.environ, "ROB6_TAG": TAG, "ROB6_BASE_IMAGE": BASE_IMAGE, "ROB6_ROBOT": ROBOT,
                    "ROB6_DUMMY": "1", "ROB6_PORT": str(self.port), "ROB6_PUBLISH_ADDR": "127.0.0.1",
                    "ROB6_ZENOH_PORT": str(self.zenoh_port), "ROB6_HEALTH_INTERVAL": "3s",
                    **self.settings}

    def compose(self, *args: str, timeout: float = 900, check: bool = True) -> subprocess.CompletedProcess[str]:
        files = [a for f in self.files for a in ("-f", str(REPO / f))]
        profiles = [a for p in self.profiles for a in ("--profile", p)]
        return run([*COMPOSE, "-p", self.project, *files, "--env-file", str(self.env_file), *profiles, *args],
                   timeout=timeout, check=check, env=self.env, cwd=REPO)

    def containers(self, service: str | None = None) -> list[str]:
        return project_containers(self.project, service)

    def state(self, container: str) -> dict[str, Any]:
        state: dict[str, Any] = json.loads(run(["docker", "inspect", "-f", "{{json .State}}", container]).stdout)
        return state

    def wait_healthy(self, services: tuple[str, ...], timeout: float = 180) -> float:
        """Seconds until every container of ``services`` is healthy; fails with the logs otherwise."""
        start = time.monotonic()
        while True:
            pending = unhealthy(self.project, services)
            if not pending:
                return time.monotonic() - start
            if time.monotonic() - start > timeout:
                logs = self.compose("logs", "--tail", "30", check=False).stdout
                raise AssertionError(f"not healthy after {timeout:.0f} s: {pending}\n{logs[-6000:]}")
            time.sleep(1)

    def down(self) -> None:
        if os.environ.get("ROB6_E2E_KEEP") == "1":
            print(f"\nROB6_E2E_KEEP=1: project {self.project} left running")
            return
        self.compose("down", "-v", "--remove-orphans", "-t", "5", check=False, timeout=180)
        self.env_file.unlink(missing_ok=True)


def fk_expected() -> str:
    for record in load(CONFORMANCE / ROBOT / "fk.jsonl"):
        if record.get("send", "").strip() == FK:
            reply: str = record["reply"]
            return reply
    raise AssertionError(f"{FK} not in fk.jsonl")


def conformance_subset(port: int) -> int:
    """Replay the sessions of management.jsonl made only of a handshake and SUBSET commands."""
    records = load(CONFORMANCE / ROBOT / "management.jsonl")
    sessions, current = [], None
    for record in records:
        if "connect" in record:
            current = [record]
            sessions.append(current)
        elif current is not None:
            current.append(record)
    chosen = [s for s in sessions
              if all(r["send"].split()[:1][0] in SUBSET for r in s[2:] if "send" in r and r["send"].split())]
    assert len(chosen) >= 5, "management.jsonl changed: no subset to replay"
    checked = 0
    for session in chosen:
        client = connect(port, handshake=False)
        try:
            assert client.greeting == session[0]["greeting"]
            for record in session[1:]:
                if "send" not in record:
                    continue
                client.send(record["send"])
                got = client.read_lines(record["reply"].count("\n"))
                assert same(record["send"], got, record["reply"]), (record["send"], got, record["reply"])
                checked += 1
                if record.get("then_closed"):
                    assert client.closed(), f"not closed after {record['send']!r}"
        finally:
            client.close()
    return checked


def image_report() -> dict[str, str]:
    sizes = {}
    for name in ("base", *SERVICES, "router"):
        ref = BASE_IMAGE if name == "base" else f"rob6/{name}:{TAG}"
        size = int(run(["docker", "image", "inspect", "-f", "{{.Size}}", ref]).stdout)
        sizes[ref] = f"{size / 1e6:.0f} MB"
    return sizes


# ---------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def built(rob6_images: images.Outcome) -> Iterator[None]:
    """The images (built once per run by tests/conftest.py); their build times and sizes."""
    REPORT["build (deploy/build-images.sh)"] = [*rob6_images.steps, f"{rob6_images.seconds:.0f} s in all"]
    REPORT["images"] = image_report()
    yield
    print("\n--- rob6 deploy e2e report ---\n" + json.dumps(REPORT, indent=2))


@pytest.fixture(scope="module")
def entry_points(built: None) -> None:
    """Every image imports its entry point, with everything it imports in turn: a module
    the image lacks (rob6-shared importing numpy, which the router, gateway, gripper and
    recorder images do not carry) fails here, before any stack is started."""
    for service in ("router", *SERVICES):
        module = "rob6.cli" if service == "router" else f"rob6_{service}.__main__"
        run(["docker", "run", "--rm", "--network", "none", f"rob6/{service}:{TAG}", "python", "-c",
             f"import {module}"], timeout=120)


@pytest.fixture(scope="module")
def plain(built: None, entry_points: None) -> Iterator[Stack]:
    stack = Stack(f"rob6e2e{os.getpid()}")
    try:
        t = time.monotonic()
        stack.compose("up", "-d", "--no-build")
        REPORT["plain: up until all healthy"] = f"{stack.wait_healthy(('router', *SERVICES)) + time.monotonic() - t:.0f} s"
        yield stack
    finally:
        stack.down()


@pytest.fixture(scope="module")
def certs(tmp_path_factory: TempPathFactory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("certs")
    make = DEPLOY / "certs" / "make-certs.sh"
    run(["bash", str(make), "--out", str(out), "router", *SERVICES, "intruder"])
    foreign = tmp_path_factory.mktemp("foreign")
    run(["bash", str(make), "--out", str(foreign), "intruder"])
    return out, foreign


# ---------------------------------------------------------------------- tests: images
def test_images_offline_minimal_non_root(built: None) -> None:
    heavy = {"numpy", "pinocchio", "ruckig", "mcap", "serial"}
    needs = {"router": set(), "gateway": set(), "kinematics": {"numpy", "pinocchio"},
             "planner": {"numpy", "ruckig", "pinocchio"}, "driver": {"numpy", "ruckig", "pinocchio"},
             "gripper": {"serial"}, "recorder": {"mcap", "zstandard"}, "ros": set()}
    for name, mods in needs.items():
        image = f"rob6/{name}:{TAG}"
        config = json.loads(run(["docker", "image", "inspect", "-f", "{{json .Config}}", image]).stdout)
        assert config["User"] == "rob6", (image, config["User"])
        assert config["Healthcheck"]["Test"][0] == "CMD", image
        absent = sorted(heavy - mods)
        script = (f"import importlib.util as u, zenoh, rob6; [__import__(m) for m in {sorted(mods)!r}]; "
                  f"extra = [m for m in {absent!r} if u.find_spec(m)]; assert not extra, extra; "
                  f"import os; assert os.getuid() != 0")
        run(["docker", "run", "--rm", "--network", "none", image, "python", "-c", script], timeout=120)


def test_router_container_tls_and_acl(built: None, certs: tuple[Path, Path]) -> None:
    """Infrastructure on its own: the router image with the secure profile, probed from here."""
    certs_dir, foreign = certs
    stack = Stack(f"rob6e2erouter{os.getpid()}", ("docker-compose.yml", "docker-compose.secure.yml"),
                  {"ROB6_CERTS_DIR": str(certs_dir)})
    try:
        stack.compose("up", "-d", "--no-build", "router")
        stack.wait_healthy(("router",), timeout=60)
        endpoint = f"tls/127.0.0.1:{stack.zenoh_port}"
        checks = zenoh_probe.secure_profile_checks(endpoint, certs_dir, foreign_certs=foreign)
        REPORT["secure router probes"] = [str(c) for c in checks]
        failed = [str(c) for c in checks if not c.ok]
        assert not failed, "\n".join(failed)
    finally:
        stack.down()


# ---------------------------------------------------------------------- tests: the running system
def test_conformance_subset(plain: Stack) -> None:
    checked = conformance_subset(plain.port)
    REPORT["conformance subset (management.jsonl)"] = f"{checked} replies identical"
    with connect(plain.port) as client:  # the whole chain: gateway -> planner -> driver, kinematics
        assert same(FK, client.ask(FK, lines=2), fk_expected())
        assert client.ask("MovePTPJoints 10 -60 80 20 40 30") == "true\n"
        assert client.ask("GetPositionJoints") == "10.000000 -60.000000 80.000000 20.000000 40.000000 30.000000\n"


def test_kinematics_killed_mid_session(plain: Stack) -> None:
    """The client gets `ERROR: ...` at once while kinematics is gone, and the same session
    works again when it is back; then a crash (SIGKILL inside) is restarted by the policy."""
    expected = fk_expected()
    with connect(plain.port) as client:
        assert same(FK, client.ask(FK, lines=2), expected)
        kinematics = plain.containers("kinematics")
        run(["docker", "kill", *kinematics])
        t = time.monotonic()
        reply = client.ask(FK, lines=1, timeout=10)
        REPORT["reply without kinematics"] = f"{reply.strip()!r} after {(time.monotonic() - t) * 1000:.0f} ms"
        assert reply.startswith("ERROR"), reply
        assert client.read_lines(1, timeout=10) == "false\n"  # ForwardCalc's failure shape
        assert time.monotonic() - t < 5, "the client waited instead of getting an error"
        assert client.ask("CM_PING") == "PONG\n"  # the gateway itself is fine
        run(["docker", "start", *kinematics])
        t = time.monotonic()
        while True:  # back as soon as its liveliness token is on the bus
            reply = client.ask(FK, lines=1, timeout=10)
            reply += client.read_lines(1)  # the status line, or an error's false
            if not reply.startswith("ERROR"):
                break
            assert time.monotonic() - t < 60, "kinematics did not come back"
            time.sleep(0.2)
        REPORT["kinematics back after docker start"] = f"{time.monotonic() - t:.1f} s"
        assert same(FK, reply, expected)

        # a crash, not a stop: the restart policy brings it back
        cid = kinematics[0]
        before = int(run(["docker", "inspect", "-f", "{{.RestartCount}}", cid]).stdout)
        run(["docker", "exec", cid, "sh", "-c", "kill -KILL -1"], check=False)  # all but docker-init
        t = time.monotonic()
        while int(run(["docker", "inspect", "-f", "{{.RestartCount}}", cid]).stdout) == before:
            assert time.monotonic() - t < 30, "kinematics was not restarted after a crash"
            time.sleep(0.2)
        plain.wait_healthy(("kinematics",), timeout=90)
        REPORT["kinematics crash -> healthy again"] = f"{time.monotonic() - t:.1f} s"
        assert same(FK, client.ask(FK, lines=2), expected)


def test_two_kinematics_replicas_both_serve(plain: Stack) -> None:
    plain.compose("up", "-d", "--no-build", "--no-recreate", "--scale", "kinematics=2", "kinematics")
    plain.wait_healthy(("kinematics",), timeout=120)
    assert len(plain.containers("kinematics")) == 2
    with ExitStack() as stack:
        session = zenoh_probe.open_session(zenoh_probe.client_config(f"tcp/127.0.0.1:{plain.zenoh_port}"))
        stack.callback(session.close)
        inbox = zenoh_probe.Inbox(session, "rob6/robot1/trace/kinematics/**")
        deadline = time.monotonic() + 30
        while len(zenoh_probe.alive(session, "rob6/robot1/alive/kinematics/*")) < 2:
            assert time.monotonic() < deadline, "second kinematics instance not on the bus"
            time.sleep(0.5)
        client = stack.enter_context(connect(plain.port))
        expected = fk_expected()
        for _ in range(20):
            assert same(FK, client.ask(FK, lines=2), expected)
        time.sleep(0.5)
        served: dict[str, int] = {}
        for _key, batch in inbox.samples:
            for _suffix, record in json.loads(batch):
                served[record["instance"]] = served.get(record["instance"], 0) + 1
    REPORT["ForwardCalc x20 over 2 replicas"] = served
    assert len(served) == 2 and min(served.values()) >= 3, served


def test_replicas_from_outside_the_stack(plain: Stack, tmp_path: Path) -> None:
    """What deploy/MULTI_HOST.md describes, with this machine standing in for the other host:
    a kinematics container outside the compose network (docker run, env settings) and a
    plain process (deploy/zenoh/remote-client.json5), both reaching the router through its
    published port, join the running system and get requests."""
    endpoint = f"tcp/127.0.0.1:{plain.zenoh_port}"
    name = f"{plain.project}-remote-kinematics"
    config = tmp_path / "remote-client.json5"
    config.write_text((DEPLOY / "zenoh" / "remote-client.json5").read_text().replace("tcp/robot-pc:7447", endpoint))
    process = None
    with ExitStack() as stack:
        run(["docker", "run", "-d", "--name", name, "--network", "host", "--init",
             "-e", "ROB6_ZENOH_MODE=client", "-e", f"ROB6_ZENOH_CONNECT={endpoint}", "-e", f"ROB6_ROBOT={ROBOT}",
             f"rob6/kinematics:{TAG}"])
        stack.callback(run, ["docker", "rm", "-f", name], check=False)
        process = subprocess.Popen([str(Path(sys.executable).with_name("rob6-kinematics"))],
                                   env={**os.environ, "ROB6_ZENOH_CONFIG": str(config), "ROB6_ROBOT": ROBOT},
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        stack.callback(process.wait, 10)
        stack.callback(process.terminate)
        session = zenoh_probe.open_session(zenoh_probe.client_config(endpoint))
        stack.callback(session.close)
        inbox = zenoh_probe.Inbox(session, "rob6/robot1/trace/kinematics/**")
        deadline = time.monotonic() + 60
        while len(zenoh_probe.alive(session, "rob6/robot1/alive/kinematics/*")) < 4:
            assert process.poll() is None, "the remote kinematics process died"
            assert time.monotonic() < deadline, zenoh_probe.alive(session, "rob6/robot1/alive/kinematics/*")
            time.sleep(0.5)
        client = stack.enter_context(connect(plain.port))
        for _ in range(24):
            assert same(FK, client.ask(FK, lines=2), fk_expected())
        time.sleep(0.5)
        served = {record["instance"] for _k, batch in inbox.samples for _s, record in json.loads(batch)}
        hostname = socket.gethostname()
        remote_container = run(["docker", "inspect", "-f", "{{.Config.Hostname}}", name]).stdout.strip()
    REPORT["ForwardCalc x24 over 2 compose + 2 outside replicas"] = sorted(served)
    assert len(served) == 4, served
    assert any(i.startswith(remote_container) or i.startswith(hostname) for i in served), served


def test_second_project_for_the_same_robot_is_refused(plain: Stack, tmp_path: Path) -> None:
    """One robot, one owner, in containers: a second compose project with the same robot id
    on the first one's Zenoh network (its network joined as external) gets a one-line
    refusal and exit 78 from each owner service; the first system is not disturbed."""
    override = tmp_path / "same-network.yml"
    override.write_text(f"networks:\n  default:\n    name: {plain.project}_default\n    external: true\n")
    owners = ("driver", "planner", "gripper", "gateway")
    second = Stack(f"{plain.project}dup", ("docker-compose.yml", str(override)),
                   {"ROB6_RESTART": "no", "ROB6_ZENOH_CONNECT": "tcp/router:7447"})
    try:
        with connect(plain.port) as client:
            second.compose("up", "-d", "--no-build", "--no-deps", *owners)
            deadline = time.monotonic() + 90
            states = {}
            while time.monotonic() < deadline:
                states = {s: second.state(second.containers(s)[0]) for s in owners}
                if all(not st["Running"] for st in states.values()):
                    break
                assert client.ask("MovePTPJoints 12 -60 80 0 40 0") == "true\n"
                assert client.ask("GetPositionJoints") == "12.000000 -60.000000 80.000000 0.000000 40.000000 0.000000\n"
                time.sleep(0.5)
            assert {s: st["ExitCode"] for s, st in states.items()} == dict.fromkeys(owners, 78), states
            for service in owners:
                logs = run(["docker", "logs", second.containers(service)[0]]).stderr.strip().splitlines()
                assert len(logs) == 1 and logs[0].startswith(f"rob6: a {service} for robot1 is already running on "), logs
            REPORT["second project, same robot id"] = "driver, planner, gripper, gateway refused (exit 78)"
            assert client.ask("MovePTPJoints 13 -60 80 0 40 0") == "true\n"
            assert same(FK, client.ask(FK, lines=2), fk_expected())
    finally:
        second.compose("down", "-t", "5", check=False)


def test_recordings_readable_after_down(plain: Stack) -> None:
    """Stop the stack (the recorder closes its files on SIGTERM); the MCAP files stay on the
    named volume and read back completely (summary, messages, kinematics traces)."""
    plain.compose("down", "-t", "10")  # keeps the volume
    volume = f"{plain.project}_recordings"
    script = r"""
import glob, json
from mcap.reader import make_reader
files = sorted(glob.glob("/data/logs/**/*.mcap", recursive=True))
out = {"files": len(files), "messages": 0, "topics": set(), "unclosed": []}
for path in files:
    with open(path, "rb") as f:
        reader = make_reader(f)
        if reader.get_summary() is None:
            out["unclosed"].append(path)
        for _schema, channel, _message in reader.iter_messages():
            out["messages"] += 1
            out["topics"].add(channel.topic)
out["topics"] = sorted(out["topics"])
print(json.dumps(out))
"""
    proc = run(["docker", "run", "--rm", "--network", "none", "-v", f"{volume}:/data/logs:ro",
                f"rob6/recorder:{TAG}", "python", "-c", script], timeout=120)
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    REPORT["recordings"] = {k: (v if k != "topics" else v[:12]) for k, v in result.items()}
    assert result["files"] >= 1 and result["messages"] > 0, result
    assert not result["unclosed"], result
    assert any("kinematics" in topic for topic in result["topics"]), result["topics"]


# ---------------------------------------------------------------------- stand-in controllers
@contextmanager
def controller_stack(profile: str, controller: str, *, robot: str, link: str,
                     control_port_setting: str) -> Iterator[tuple[Stack, Callable[[], dict[str, Any]]]]:
    """The stack of compose profile ``profile`` with the driver on ``link`` to the stand-in
    controller container ``controller``: up and healthy. Yields the
    stack and the controller's status request (its control channel, published on the port
    the compose setting ``control_port_setting`` names); the stack is removed at the end."""
    control_port = free_port()
    stack = Stack(f"rob6e2e{profile}{os.getpid()}", settings={
        "ROB6_ROBOT": robot, "ROB6_LINK": link, "ROB6_DUMMY": "0",
        control_port_setting: str(control_port)}, profiles=(profile,))
    try:
        t = time.monotonic()
        stack.compose("up", "-d", "--no-build")
        stack.wait_healthy(("router", *SERVICES, controller))
        REPORT[f"{profile}: up until all healthy"] = f"{time.monotonic() - t:.0f} s"
        with socket.create_connection(("127.0.0.1", control_port), timeout=10) as sock, \
                sock.makefile("rwb") as control:

            def status() -> dict[str, Any]:
                control.write(b'{"cmd": "status"}\n')
                control.flush()
                reply: dict[str, Any] = json.loads(control.readline())
                return reply

            yield stack, status
    finally:
        stack.down()


# ---------------------------------------------------------------------- tests: rsi profile
def test_rsi_profile_drives_the_kr_c4_container(built: None, entry_points: None) -> None:
    """`ROB6_LINK=rsi ROB6_ROBOT=kr16rt compose --profile rsi up`: the driver drives the
    stand-in KR C4 (its own container on the robot network) over RSI in real time; the
    controller's axes end where the client moved them, without a trip."""
    with controller_stack("rsi", "kuka-rsi-sim", robot="kr16rt", link="rsi",
                          control_port_setting="ROB6_KUKA_SIM_CONTROL_PORT") as (stack, kuka):
        # the KR C4 sends from the moment it is up; until the driver answers, RSI times out
        # and the stand-in operator (--auto-ack) restarts it, as on a real controller
        deadline = time.monotonic() + 90
        while not ((before := kuka())["state"] == "running" and before["replies_ok"] >= 250):
            assert time.monotonic() < deadline, f"the driver never answered the KR C4 container: {before}"
            time.sleep(0.5)
        target = [10.0, -80.0, 100.0, 0.0, 30.0, 0.0]
        with connect(stack.port) as client:
            assert client.ask("MovePTPJoints " + " ".join(f"{x:g}" for x in target), timeout=60) == "true\n"
            assert [float(x) for x in client.ask("GetPositionJoints").split()] == target
            status = kuka()
        assert status["state"] == "running" and status["trips"] == before["trips"], status  # no trip in the move
        assert all(abs(a - b) < 2e-4 for a, b in zip(status["aipos"], target, strict=True)), status["aipos"]
        REPORT["rsi: controller after the move"] = {k: status[k] for k in ("cycle_ms", "late_total", "rtt_ms")}


def follow_then_move(port: int, target: list[float], controller: Callable[[], dict[str, Any]]
                     ) -> tuple[float, dict[str, Any]]:
    """A link that streams points to a controller at rob6's zero: wait until rob6 follows it
    (a move to where the arm stands is accepted; until then: ERROR: driver: robot not
    connected ...), then a PTP to ``target``. The move's seconds and the controller's status."""
    with connect(port) as client:
        t = time.monotonic()
        while (reply := client.ask("MovePTPJoints 0 0 0 0 0 0", timeout=30)) != "true\n":
            reply += client.read_lines(1)  # ERROR: ... then false
            assert reply.startswith("ERROR: driver: robot not connected") and reply.endswith("\nfalse\n"), reply
            assert time.monotonic() - t < 30, f"rob6 does not follow the controller: {reply!r}"
            time.sleep(0.2)  # a retry, as a lab client does until its robot is connected
        assert client.ask("GetPositionJoints") == "0.000000 " * 5 + "0.000000\n"
        t = time.monotonic()
        assert client.ask("MovePTPJoints " + " ".join(f"{x:g}" for x in target), timeout=60) == "true\n"
        moved_s = time.monotonic() - t
        assert [float(x) for x in client.ask("GetPositionJoints").split()] == target
        return moved_s, controller()


# ---------------------------------------------------------------------- tests: adept profile
def test_adept_profile_drives_the_adept_container(built: None, entry_points: None) -> None:
    """`ROB6_ROBOT=ad850 ROB6_LINK=simple_message compose --profile adept up`: the driver
    connects to the stand-in Adept controller (its own container on the robot network, found
    by the compose default ROB6_SM_HOST=adept-sm-sim) and streams a PTP motion to it over
    simple_message; the move answers true only once the controller's arm is at the target."""
    with controller_stack("adept", "adept-sm-sim", robot="ad850", link="simple_message",
                          control_port_setting="ROB6_ADEPT_SIM_CONTROL_PORT") as (stack, adept):
        # the driver is the client of both simple_message ports and retries until they answer
        deadline = time.monotonic() + 90
        while not ((before := adept())["clients"]["motion"] and before["clients"]["state"]):
            assert time.monotonic() < deadline, f"the driver never connected to the Adept container: {before}"
            time.sleep(0.5)
        start = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # adept-sm-sim's default start pose (rob6's convention)
        # the link's opening may be a MOVE to where the arm stands, as float32 radians carry it
        assert all(abs(a - b) < 2e-4 for a, b in zip(before["position_rob6_deg"], start, strict=True)), before
        assert not before["in_motion"], before
        target = [30.0, -50.0, 50.0, 10.0, 20.0, -20.0]
        moved_s, status = follow_then_move(stack.port, target, adept)
        # the controller's own arm is at the target and at rest: true means the robot arrived
        assert all(abs(a - b) < 2e-4 for a, b in zip(status["position_rob6_deg"], target, strict=True)), status
        assert not status["in_motion"] and status["queue_length"] == 0, status
        # the motion went over the wire as acknowledged points, every MOVE the program issued ran
        assert status["points_executed"] > before["points_executed"], status
        assert status["points_acknowledged"] > before["points_acknowledged"], status
        assert status["task_errors"] == before["task_errors"] == 0 and not status["e_stopped"], status
        assert status["clients"]["motion"] and status["clients"]["state"], status  # still the same link
        REPORT["adept: controller after the move"] = {
            "move_s": round(moved_s, 2), **{k: status[k] for k in (
                "points_received", "points_acknowledged", "points_executed", "underruns", "ack_latency_ms")}}


# ---------------------------------------------------------------------- tests: kawasaki profile
def test_kawasaki_profile_drives_the_kawasaki_container(built: None, entry_points: None) -> None:
    """`ROB6_ROBOT=kaw_fs ROB6_LINK=kawasaki compose --profile kawasaki up`: the driver connects
    to the stand-in Kawasaki controller (its own container on the robot network, found by the
    compose default ROB6_KAS_HOST=kawasaki-as-sim), whose image executes the rob6.as its wheel
    carries, and streams a PTP motion to it as acknowledged points; the move answers true only
    once the controller's arm is at the target."""
    with controller_stack("kawasaki", "kawasaki-as-sim", robot="kaw_fs", link="kawasaki",
                          control_port_setting="ROB6_KAWASAKI_SIM_CONTROL_PORT") as (stack, kawasaki):
        # the driver is the client of the program's port and retries until it answers
        deadline = time.monotonic() + 90
        while not (before := kawasaki())["client"]:
            assert time.monotonic() < deadline, f"the driver never connected to the Kawasaki container: {before}"
            time.sleep(0.5)
        start = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # kawasaki-as-sim's default start pose (rob6's convention)
        assert before["position_rob6_deg"] == start and not before["moving"], before
        target = [30.0, -20.0, 50.0, 10.0, 20.0, -20.0]
        moved_s, status = follow_then_move(stack.port, target, kawasaki)
        # the controller's own arm is at the target: true means the robot arrived (the program
        # reports it at rest within the wire's 1e-3 deg); its servos then settle there
        assert all(abs(a - b) < 1.5e-3 for a, b in zip(status["position_rob6_deg"], target, strict=True)), status
        deadline = time.monotonic() + 10
        while (status := kawasaki())["moving"]:
            assert time.monotonic() < deadline, f"the arm never came to rest at the target: {status}"
            time.sleep(0.1)
        assert all(abs(a - b) < 1.5e-3 for a, b in zip(status["position_rob6_deg"], target, strict=True)), status
        # the program executed in the container (not a stand-in's stand-in) answered every
        # line of the motion with code 0: none refused or malformed
        assert set(status["answers"]) == {"0"} and status["answers"]["0"] > before["answers"].get("0", 0), status
        assert status["tasks"] == {"pc1": "waiting", "pc2": "waiting", "robot": "waiting"}, status
        assert not status["estop"] and status["motor"] and status["client"], status
        REPORT["kawasaki: controller after the move"] = {
            "move_s": round(moved_s, 2), **{k: status[k] for k in (
                "lines_received", "answers", "segments", "underruns_reported", "ack_ms")}}


# ---------------------------------------------------------------------- tests: secure profile
def test_secure_profile_end_to_end(built: None, entry_points: None, certs: tuple[Path, Path]) -> None:
    certs_dir, foreign = certs
    stack = Stack(f"rob6e2esec{os.getpid()}", ("docker-compose.yml", "docker-compose.secure.yml"),
                  {"ROB6_CERTS_DIR": str(certs_dir)})
    try:
        t = time.monotonic()
        stack.compose("up", "-d", "--no-build")
        REPORT["secure: up until all healthy"] = f"{stack.wait_healthy(('router', *SERVICES)) + time.monotonic() - t:.0f} s"
        # the system works through TLS + ACL ...
        assert conformance_subset(stack.port) > 0
        with connect(stack.port) as client:
            assert same(FK, client.ask(FK, lines=2), fk_expected())
            assert client.ask("MovePTPJoints 10 -60 80 20 40 30") == "true\n"
        # ... and nobody else gets in
        endpoint = f"tls/127.0.0.1:{stack.zenoh_port}"
        assert zenoh_probe.refused(zenoh_probe.client_config(endpoint, certs_dir)), "no certificate got in"
        assert zenoh_probe.refused(zenoh_probe.client_config(f"tcp/127.0.0.1:{stack.zenoh_port}"))
        with ExitStack() as es:
            intruder = zenoh_probe.open_session(zenoh_probe.client_config(endpoint, certs_dir, "intruder"))
            es.callback(intruder.close)
            inbox = zenoh_probe.Inbox(intruder, "**")
            assert not zenoh_probe.alive(intruder, "rob6/**"), "the intruder sees the services"
            assert not zenoh_probe.ask(intruder, "rob6/robot1/driver/*/state"), "the intruder reads the driver"
            with connect(stack.port) as client:  # traffic the intruder must not see
                client.ask("GetPositionJoints")
            time.sleep(1)
            assert not inbox.samples, inbox.key_exprs()[:5]
    finally:
        stack.down()
