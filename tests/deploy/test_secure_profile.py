"""The secure profile without docker: deploy/zenoh configs, make-certs.sh, TLS and the ACL.

The router runs from deploy/zenoh/router-secure.json5 (certificate paths moved to a
temporary directory); the same probes run against the container in test_compose_e2e.py.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh
from pytest import TempPathFactory

from harness.ports import free_port
from tests.deploy import zenoh_probe
from tests.deploy.zenoh_probe import local_router, localize_config, secure_profile_checks

REPO = Path(__file__).resolve().parents[2]
ZENOH_DIR = REPO / "deploy" / "zenoh"
MAKE_CERTS = REPO / "deploy" / "certs" / "make-certs.sh"
PARTICIPANTS = ("router", "gateway", "kinematics", "planner", "driver", "gripper", "recorder", "intruder")
ROB6 = Path(sys.executable).with_name("rob6")


def make_certs(out: Path, *names: str) -> Path:
    subprocess.run(["bash", str(MAKE_CERTS), "--out", str(out), *names], check=True,
                   capture_output=True, text=True)
    return out


@pytest.fixture(scope="module")
def certs(tmp_path_factory: TempPathFactory) -> Path:
    return make_certs(tmp_path_factory.mktemp("certs"), *PARTICIPANTS)


@pytest.fixture(scope="module")
def foreign_certs(tmp_path_factory: TempPathFactory) -> Path:
    """A second CA with its own "intruder": must not get in either."""
    return make_certs(tmp_path_factory.mktemp("foreign"), "intruder")


@pytest.mark.parametrize("path", sorted(ZENOH_DIR.glob("*.json5")), ids=lambda p: p.name)
def test_zenoh_configs_parse(path: Path) -> None:
    config = zenoh.Config.from_file(str(path))
    assert config.get_json("mode").strip('"') in ("router", "client", "peer")
    if "secure" in path.name:
        assert config.get_json("transport/link/tls/enable_mtls") == "true"
        assert config.get_json("transport/link/protocols") == '["tls"]'


def test_make_certs_is_idempotent_and_verifiable(certs: Path, tmp_path: Path) -> None:
    before = (certs / "gateway.crt").read_bytes()
    make_certs(certs, "gateway")  # re-run: keeps what exists
    assert (certs / "gateway.crt").read_bytes() == before
    for name in PARTICIPANTS:
        subprocess.run(["openssl", "verify", "-CAfile", str(certs / "ca.crt"), str(certs / f"{name}.crt")],
                       check=True, capture_output=True)
        subject = subprocess.run(["openssl", "x509", "-noout", "-subject", "-in", str(certs / f"{name}.crt")],
                                 check=True, capture_output=True, text=True).stdout
        assert f"CN = {name}" in subject or f"CN={name}" in subject
        assert oct((certs / f"{name}.key").stat().st_mode & 0o777) == "0o600"


@pytest.mark.slow
def test_tls_and_acl_probes(certs: Path, foreign_certs: Path) -> None:
    with local_router(ZENOH_DIR / "router-secure.json5", certs) as endpoint:
        checks = secure_profile_checks(endpoint, certs, foreign_certs=foreign_certs)
    failed = [str(c) for c in checks if not c.ok]
    assert not failed, "\n".join(failed)


@pytest.mark.slow
def test_rob6_processes_through_the_secure_router(certs: Path, tmp_path: Path) -> None:
    """The real rob6 code paths (router CLI, Bus.serve/request, liveliness, rob6 health)
    with the files the containers use: the ACL must let the system work, and stop the rest."""
    from rob6.bus import Bus, BusError
    from rob6.config import BusSettings
    from rob6.messages import Ack, AlterTarget, Empty, PingReply, SessionEnd

    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    router_cfg = localize_config(ZENOH_DIR / "router-secure.json5", tmp_path / "router.json5", certs,
                                 "router", listen=endpoint)
    env = dict(os.environ, ROB6_ZENOH_CONFIG=str(router_cfg), ROB6_ZENOH_LISTEN=endpoint)
    router = subprocess.Popen([str(ROB6), "router"], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True)
    assert router.stdout is not None  # a pipe
    buses: list[Bus] = []

    def bus(name: str) -> Bus:
        cfg = localize_config(ZENOH_DIR / "client-secure.json5", tmp_path / f"{name}.json5", certs, name)
        b = Bus(BusSettings(connect=(endpoint,), zenoh_config=str(cfg)), name)
        buses.append(b)
        return b

    try:
        deadline = time.monotonic() + 10
        while zenoh_probe.refused(zenoh_probe.client_config(endpoint, certs, "driver")):
            assert router.poll() is None, router.stdout.read()
            assert time.monotonic() < deadline, "router did not come up"
            time.sleep(0.2)
        driver, planner, gateway = bus("driver"), bus("planner"), bus("gateway")
        driver.serve({"ping": lambda req, ctx: PingReply(robot_time=1.0, wall_time=time.time()),
                      "stop": lambda req, ctx: Ack(), "alter_target": lambda req, ctx: Ack()})
        planner.serve({"session_end": lambda req, ctx: Ack()})
        assert not gateway.wait_for(["driver", "planner"], 5.0)
        assert not planner.wait_for(["driver"], 5.0)

        assert planner.request("driver", "stop", Empty(), timeout=2.0).ok  # the planner commands the driver
        assert gateway.request("driver", "ping", Empty(), timeout=2.0).robot_time == 1.0  # gateway may read
        # ... and stream joint Alter targets (the driver checks them)
        assert gateway.request("driver", "alter_target", AlterTarget(q=[0.0] * 6), timeout=2.0).ok
        with pytest.raises(BusError):
            gateway.request("driver", "stop", Empty(), timeout=1.0)  # ... but not command
        assert gateway.request("planner", "session_end", SessionEnd(session="gateway-1:1"), timeout=2.0).ok
        with pytest.raises(BusError):
            driver.request("planner", "session_end", SessionEnd(session="gateway-1:1"), timeout=1.0)

        def health(name: str, service: str) -> int:
            cfg = localize_config(ZENOH_DIR / "client-secure.json5", tmp_path / f"h-{name}.json5", certs, name)
            henv = dict(os.environ, ROB6_ZENOH_CONFIG=str(cfg), ROB6_ZENOH_CONNECT=endpoint)
            return subprocess.run([str(ROB6), "health", service, "--timeout", "2"], env=henv,
                                  capture_output=True, check=False, timeout=30).returncode

        assert health("driver", "driver") == 0  # the container's HEALTHCHECK, secure profile
        assert health("intruder", "driver") != 0  # an unknown participant sees nothing
    finally:
        for b in buses:
            b.close()
        router.terminate()
        router.wait(10)
