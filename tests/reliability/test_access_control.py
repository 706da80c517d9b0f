"""Access control of the TCP side: client allowlist, Shutdown and DirectAdeptCmd off by default.

The Zenoh side (TLS, ACL: only the planner may command the driver, only the gateway may call
the planner) is tested in ``tests/deploy/test_secure_profile.py``.
"""

import os
import socket
import subprocess
import sys
import time

import pytest

from harness.client import Client
from harness.ports import free_port
from harness.system import running


def _raw_connect(port: int, source: str = "127.0.0.1") -> bytes:
    sock = socket.create_connection(("127.0.0.1", port), timeout=10, source_address=(source, 0))
    data = b""
    while True:
        chunk = sock.recv(4096)
        if not chunk:
            break
        data += chunk
    sock.close()
    return data


def test_client_outside_the_allowlist_is_refused_with_one_line_and_closed() -> None:
    with running("kr16", dummy=True, extra_env={"ROB6_ALLOW_CLIENTS": "127.0.0.2/32"}) as system:
        gateway = system.pids()["gateway"]
        assert _raw_connect(system.port) == b"ERROR: access denied for 127.0.0.1\n"
        for _ in range(20):  # repeated refusals neither crash nor block the gateway
            assert _raw_connect(system.port).startswith(b"ERROR: access denied")
        # an allowed address gets the normal greeting and a working session
        with socket.create_connection(("127.0.0.2", system.port), timeout=10,
                                      source_address=("127.0.0.2", 0)) as sock:
            sock.settimeout(10)
            assert sock.recv(100) == b"welcome to rob6server 0.1.01 !\n"
            sock.sendall(b"Hello Robot\nGetRobot\n")
            data = b""
            while data.count(b"\n") < 2:
                data += sock.recv(100)
            assert data == b"accepted\nkr16\n"
        assert system.pids()["gateway"] == gateway


def test_allowlist_accepts_networks_and_lists() -> None:
    with running("kr16", dummy=True, extra_env={"ROB6_ALLOW_CLIENTS": "10.0.0.0/8, 127.0.0.0/30"}) as system:
        with Client(system.port) as client:
            assert client.ask("GetRobot") == "kr16\n"
        assert _raw_connect(system.port, "127.0.0.5").startswith(b"ERROR: access denied for 127.0.0.5")


def test_shutdown_and_direct_adept_cmd_are_disabled_by_default_on_the_gateway() -> None:
    """The gateway alone (not ``rob6 run``) defaults to Shutdown disabled; DirectAdeptCmd is off."""
    with running("ad850", dummy=True, services=("driver", "kinematics", "planner", "gripper"),
                 extra_env={"ROB6_ALLOW_SHUTDOWN": "1"}) as system:
        port = free_port()
        env = dict(os.environ, ROB6_ROBOT="ad850", ROB6_ROBOT_ID=system.robot_id, ROB6_PORT=str(port),
                   ROB6_ZENOH_CONNECT=f"tcp/127.0.0.1:{system.router_port}")
        for key in ("ROB6_ALLOW_SHUTDOWN", "ROB6_ALLOW_DIRECT_ADEPT_CMD", "ROB6_ALLOW_CLIENTS"):
            env.pop(key, None)
        gateway = subprocess.Popen([sys.executable, "-m", "rob6_gateway"], env=env, stdin=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 30
            while True:
                try:
                    client = Client(port)
                    break
                except OSError:
                    assert time.monotonic() < deadline and gateway.poll() is None
                    time.sleep(0.1)
            with client:
                reply = client.ask("Shutdown")
                assert reply.startswith("ERROR: Shutdown is disabled"), reply
                assert client.ask("DirectAdeptCmd WHERE", lines=2) == (
                    "ERROR: DirectAdeptCmd is disabled on this server (it forwards raw controller "
                    "commands; start the gateway with --allow-direct-adept-cmd)\nfalse\n")
                assert client.ask("GetRobot") == "ad850\n"  # the session goes on
            assert gateway.poll() is None
        finally:
            gateway.terminate()
            gateway.wait(10)


def test_rob6_run_can_disable_shutdown() -> None:
    with running("kr16", dummy=True, extra_env={"ROB6_ALLOW_SHUTDOWN": "0"}) as system:
        with Client(system.port) as client:
            assert client.ask("Shutdown").startswith("ERROR: Shutdown is disabled")
            assert client.ask("GetRobot") == "kr16\n"
        assert system.process.poll() is None


def test_rob6_run_enables_shutdown() -> None:
    with running("kr16", dummy=True) as system:
        with Client(system.port) as client:
            assert client.ask("Shutdown", lines=2) == "bye!\nshutting down ...\n"
        assert system.process.wait(15) == 0


@pytest.mark.parametrize("robot", ["kr16", "ad850"])
def test_direct_adept_cmd_is_off_in_rob6_run(robot: str) -> None:
    with running(robot, dummy=True) as system, Client(system.port) as client:
        if robot == "kr16":  # not an Adept: false, as the original
            assert client.ask("DirectAdeptCmd SPEED 100") == "false\n"
        else:
            reply = client.ask("DirectAdeptCmd SPEED 100", lines=2)
            assert reply.startswith("ERROR: DirectAdeptCmd is disabled") and reply.endswith("\nfalse\n")
