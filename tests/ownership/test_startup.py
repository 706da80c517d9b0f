"""Plain start-up failures, ready that means ready, and a shutdown that loses nothing."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness.client import Client
from harness.ports import free_port
from harness.system import System
from rob6.messages import SERVICES
from rob6_recorder.reader import read_records

pytestmark = pytest.mark.slow


def _rob6_run(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rob6.cli", "run", "--dummy", *args],
                          env={**os.environ, "ROB6_LIVE_PORT": "0", **env}, capture_output=True, check=False, text=True,
                          timeout=30)


def _one_line(result: subprocess.CompletedProcess[str]) -> str:
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stdout + result.stderr
    return lines[0]


@pytest.mark.parametrize("taken", ["client", "router"])
def test_a_port_in_use_is_one_line_and_a_non_zero_exit(taken: str) -> None:
    port, router_port = free_port(), free_port()
    with socket.socket() as squatter:
        squatter.bind(("127.0.0.1" if taken == "router" else "0.0.0.0", port if taken == "client" else router_port))
        squatter.listen()
        started = time.monotonic()
        result = _rob6_run("--port", str(port), "--router-port", str(router_port))
        assert time.monotonic() - started < 5
    assert result.returncode != 0
    line = _one_line(result)
    if taken == "client":
        assert line.startswith(f"rob6: the client port 0.0.0.0:{port} is in use") and "ROB6_PORT" in line
    else:
        assert line.startswith(f"rob6: the Zenoh router port 127.0.0.1:{router_port} is in use")
        assert "ROB6_ROUTER_PORT" in line


def test_an_unknown_setting_is_refused_before_anything_starts() -> None:
    result = _rob6_run("--port", str(free_port()), ROB6_LINK="serial")
    assert result.returncode != 0
    assert "Invalid value for '--link'" in result.stderr and "Traceback" not in result.stderr


def test_a_router_that_cannot_bind_says_so_in_one_line() -> None:
    with socket.socket() as squatter:
        squatter.bind(("127.0.0.1", 0))
        squatter.listen()
        port = squatter.getsockname()[1]
        result = subprocess.run([sys.executable, "-m", "rob6.cli", "router", "--listen", f"tcp/127.0.0.1:{port}"],
                                capture_output=True, check=False, text=True, timeout=30)
    assert result.returncode == 78
    assert _one_line(result).startswith(f"rob6-router: cannot listen on tcp/127.0.0.1:{port}: address already in use")


def test_a_client_connecting_the_instant_the_port_opens_gets_real_answers() -> None:
    """20 cold starts in a row: the first motion command of a client that connected as
    soon as the port accepted is executed, never 'planner unavailable'."""
    for attempt in range(20):
        system = System("kr16", dummy=True)
        try:
            deadline = time.monotonic() + 60
            while True:
                assert system.process.poll() is None, "\n".join(system.output)
                assert time.monotonic() < deadline, "the gateway never opened its port"
                try:
                    client = Client(system.port, timeout=10)
                    break
                except OSError:
                    time.sleep(0.002)
            with client:
                assert client.ask("MovePTPJoints 10 -60 80 0 40 0") == "true\n", f"cold start {attempt}"
                assert client.ask("ForwardCalc 0 0 0 0 0 0", 2).endswith("noflip up lefty\n")
        finally:
            system.stop()


def test_ctrl_c_after_a_session_loses_no_record(tmp_path: Path) -> None:
    system = System("kr16", dummy=False, log_dir=str(tmp_path))
    try:
        system.wait_ready()
        with system.client() as client:
            for k in range(20):
                assert client.ask(f"MovePTPJoints {k % 3} -60 80 0 40 0") in ("true\n",)
            assert client.ask("GetRobot") == "kr16\n"
            client.send("Quit\n")
            assert client.read_lines(1) == "bye!\n"
        system.process.send_signal(signal.SIGINT)
        assert system.process.wait(10) == 0
    finally:
        system.stop()
    assert not [line for line in system.output if "dropping" in line or "dropped" in line], system.output
    session = sorted(tmp_path.glob("*_session*.mcap"))
    assert session
    records = list(read_records(session[0]))
    assert [r.data["event"] for r in records if r.topic.endswith("/event")] == ["open", "close"]
    assert [r.data["text"] for r in records if r.topic.endswith("/client_out")][-1] == "bye!\n"
    system_files = [p for p in tmp_path.glob("*.mcap") if "_session" not in p.name]
    assert system_files and all(any(True for _ in read_records(p)) for p in system_files)


@pytest.mark.parametrize("client_at_stop", ["in Alter mode", "gone after DisableAlter"])
def test_ctrl_c_is_a_clean_stop_one_line_per_service_at_most(tmp_path: Path, client_at_stop: str) -> None:
    """Ctrl-C in the terminal of ``make run`` (SIGINT to its whole process group) after a PTP
    and an Alter stream: every service exits 0 by itself, nothing is reported leaked, and
    what is printed after ``ready`` is no warning or error, one line per service at most,
    the recorder's saying the recordings are closed. ``exit_probe`` makes a Ruckig object
    still alive at exit certain to show, where nanobind reports it only now and then."""
    probe = str(Path(__file__).parent / "exit_probe")
    system = System("kr16", dummy=False, log_dir=str(tmp_path),
                    extra_env={"PYTHONPATH": os.pathsep.join(filter(None, (probe, os.environ.get("PYTHONPATH"))))})
    try:
        system.wait_ready()
        client = system.client()
        assert client.ask("MovePTPJoints 10 -60 80 20 40 30") == "true\n"
        assert client.ask("EnableAlter") == "true\n"
        for k in range(50):
            assert client.ask(f"MoveRTJoints {10 + 0.02 * k:.2f} -60 80 20 40 30") == "true\n"
        if client_at_stop == "gone after DisableAlter":
            assert client.ask("DisableAlter") == "true\n"
            client.close()
        ready = len(system.output)
        os.killpg(system.process.pid, signal.SIGINT)  # what the terminal does with Ctrl-C
        code = system.process.wait(60)
        client.close()
    finally:
        system.stop()
    after = system.output[ready:]
    assert code == 0, after  # the launcher's 0: every child exited 0 by itself, none was killed
    assert not [line for line in after if "leaked" in line or "Traceback" in line
                or " WARNING " in line or " ERROR " in line], after
    assert len(after) <= len(SERVICES) + 1, after  # the services and the router: a line each at most
    assert [line for line in after if line.startswith("rob6-recorder: recordings closed: ")], after
