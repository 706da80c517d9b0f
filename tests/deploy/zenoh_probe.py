"""Zenoh probes of the secure profile: who may connect, who gets replies, who receives samples.

Reusable from tests and by hand, against any router (in-process, a container, a lab PC)::

    # against a running secure router (certificates from deploy/certs/make-certs.sh, which
    # must include an extra participant "intruder": a valid certificate with no rights)
    .venv/bin/python tests/deploy/zenoh_probe.py --endpoint tls/127.0.0.1:7447 --certs deploy/certs/out

    # the same against a router started here from deploy/zenoh/router-secure.json5
    .venv/bin/python tests/deploy/zenoh_probe.py --serve-router deploy/zenoh/router-secure.json5 --certs DIR

Each probe session is a Zenoh *client* identified by a certificate of ``--certs`` (its CN is
the participant); probes use the instance name ``probe`` so they never touch real services.
Exit status 0 when every check gives the expected answer; one line per check either way.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import zenoh

from harness.ports import free_port

ROBOT_ID = "robot1"
WAIT_S = 1.0  # how long a reply/sample is awaited before "none"
SETTLE_S = 0.5  # declarations need a moment to reach the router and the other clients


class Refused(Exception):
    """The router refused the session (TLS handshake, certificate, protocol)."""


# ---------------------------------------------------------------------- configurations
def client_config(endpoint: str, certs: Path | None = None, name: str | None = None,
                  *, ca: Path | None = None, connect_timeout_ms: int = 3000) -> zenoh.Config:
    """A Zenoh client to ``endpoint``; with ``name``, mutual TLS as ``certs/<name>.{crt,key}``.

    ``ca`` defaults to ``certs/ca.crt``; without ``name`` the client presents no certificate.
    """
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("connect/timeout_ms", str(connect_timeout_ms))
    config.insert_json5("connect/exit_on_failure", "true")
    config.insert_json5("scouting/multicast/enabled", "false")
    ca = ca or (certs / "ca.crt" if certs else None)
    if ca is not None:
        config.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(ca)))
    if name is not None:
        assert certs is not None, "mutual TLS needs certs"
        config.insert_json5("transport/link/tls/enable_mtls", "true")
        config.insert_json5("transport/link/tls/connect_certificate", json.dumps(str(certs / f"{name}.crt")))
        config.insert_json5("transport/link/tls/connect_private_key", json.dumps(str(certs / f"{name}.key")))
    return config


def router_config(template: Path, certs: Path, listen: str) -> zenoh.Config:
    """``template`` (e.g. deploy/zenoh/router-secure.json5) with its certificate paths
    pointed at ``certs`` and listening on ``listen``."""
    config = zenoh.Config.from_file(str(template))
    config.insert_json5("listen/endpoints", json.dumps([listen]))
    tls = "transport/link/tls/"
    config.insert_json5(tls + "root_ca_certificate", json.dumps(str(certs / "ca.crt")))
    config.insert_json5(tls + "listen_certificate", json.dumps(str(certs / "router.crt")))
    config.insert_json5(tls + "listen_private_key", json.dumps(str(certs / "router.key")))
    return config


CONTAINER_CERTS = "/etc/rob6/certs/"


def localize_config(src: Path, dest: Path, certs: Path, name: str, listen: str | None = None) -> Path:
    """Copy a deploy/zenoh/*-secure.json5 for use outside the containers: the certificate
    paths (/etc/rob6/certs/...) point into ``certs``, as participant ``name``; ``listen``
    replaces the router's listen endpoint. Returns ``dest``."""
    text = src.read_text()
    text = text.replace(CONTAINER_CERTS + "participant.", f"{certs}/{name}.")
    text = text.replace(CONTAINER_CERTS, f"{certs}/")
    if listen:
        text = text.replace('"tls/0.0.0.0:7447"', json.dumps(listen))
    dest.write_text(text)
    return dest


@contextmanager
def local_router(template: Path, certs: Path, port: int | None = None) -> Iterator[str]:
    """A router in this process from ``template``; yields its ``tls/127.0.0.1:<port>`` endpoint."""
    port = port or free_port()
    session = zenoh.open(router_config(template, certs, f"tls/127.0.0.1:{port}"))
    try:
        yield f"tls/127.0.0.1:{port}"
    finally:
        session.close()


def open_session(config: zenoh.Config) -> zenoh.Session:
    try:
        return zenoh.open(config)
    except Exception as exc:  # zenoh.ZError: the only thing a refused client sees
        raise Refused(str(exc)) from None


def refused(config: zenoh.Config) -> bool:
    """True when a session with ``config`` cannot be opened."""
    try:
        session = open_session(config)
    except Refused:
        return True
    session.close()
    return False


# ---------------------------------------------------------------------- primitives
def serve(session: zenoh.Session, key: str, answer: bytes = b"probe-ok") -> zenoh.Queryable[None]:
    """A queryable answering every query on ``key`` (keep the returned object alive)."""
    def on_query(query: zenoh.Query) -> None:
        query.reply(query.key_expr, answer)

    return session.declare_queryable(key, on_query)


def ask(session: zenoh.Session, key: str, timeout: float = WAIT_S) -> list[bytes]:
    """The payloads of all OK replies to a query on ``key`` within ``timeout``."""
    replies = []
    for reply in session.get(key, timeout=timeout):
        if reply.ok is not None:
            replies.append(reply.ok.payload.to_bytes())
    return replies


class Inbox:
    """Samples received by a subscriber (``declare`` it before publishing)."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.samples: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        # remote samples only: a session's own puts would otherwise reach its own subscriber
        self._sub = session.declare_subscriber(key, self._on_sample, allowed_origin=zenoh.Locality.REMOTE)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.samples.append((str(sample.key_expr), sample.payload.to_bytes()))

    def key_exprs(self) -> list[str]:
        with self._lock:
            return [key for key, _ in self.samples]


def alive(session: zenoh.Session, key: str, timeout: float = WAIT_S) -> list[str]:
    """Liveliness tokens matching ``key`` seen by ``session``."""
    return [str(r.ok.key_expr) for r in session.liveliness().get(key, timeout=timeout) if r.ok is not None]


# ---------------------------------------------------------------------- the check list
@dataclass
class Check:
    name: str
    expected: bool
    actual: bool

    @property
    def ok(self) -> bool:
        return self.expected == self.actual

    def __str__(self) -> str:
        return f"{'PASS' if self.ok else 'FAIL'}  {self.name}: {self.actual} (expected {self.expected})"


def secure_profile_checks(endpoint: str, certs: Path, robot_id: str = ROBOT_ID,
                          foreign_certs: Path | None = None) -> list[Check]:
    """Every check of the secure profile against the router at ``endpoint``.

    ``certs`` must hold ca.crt and certificates for driver, planner, gateway, kinematics,
    recorder and ``intruder`` (signed by the same CA, CN matching no ACL subject). ``foreign_certs``
    (optional): a second CA's directory with an ``intruder`` certificate.
    """
    host_port = endpoint.split("/", 1)[1]
    checks: list[Check] = []

    def check(name: str, expected: bool, actual: bool) -> None:
        checks.append(Check(name, expected, actual))

    # 1. connecting: mutual TLS is mandatory
    check("no certificate: session refused", True, refused(client_config(endpoint, certs)))
    check("plain tcp: session refused", True, refused(client_config(f"tcp/{host_port}")))
    if foreign_certs is not None:
        check("certificate of another CA: session refused", True,
              refused(client_config(endpoint, foreign_certs, "intruder", ca=certs / "ca.crt")))
    check("driver certificate: session opens", False, refused(client_config(endpoint, certs, "driver")))

    prefix = f"rob6/{robot_id}"
    with ExitStack() as stack:
        s = {}
        for name in ("driver", "planner", "gateway", "kinematics", "recorder", "intruder"):
            session = open_session(client_config(endpoint, certs, name))
            stack.callback(session.close)
            s[name] = session

        # 2. queries: who may command whom
        keep = [serve(s["driver"], f"{prefix}/driver/probe/*"),
                serve(s["planner"], f"{prefix}/planner/probe/*"),
                serve(s["kinematics"], f"{prefix}/kinematics/probe/*")]
        token = s["driver"].liveliness().declare_token(f"{prefix}/alive/driver/probe")
        time.sleep(SETTLE_S)
        driver_cmd = f"{prefix}/driver/probe/execute"
        check("planner commands driver (execute): replied", True, bool(ask(s["planner"], driver_cmd)))
        check("gateway commands driver (execute): replied", False, bool(ask(s["gateway"], driver_cmd)))
        check("gateway reads driver (state): replied", True, bool(ask(s["gateway"], f"{prefix}/driver/probe/state")))
        check("kinematics commands driver (execute): replied", False, bool(ask(s["kinematics"], driver_cmd)))
        check("intruder commands driver (execute): replied", False, bool(ask(s["intruder"], driver_cmd)))
        check("intruder reads driver (state): replied", False, bool(ask(s["intruder"], f"{prefix}/driver/probe/state")))
        check("intruder wildcard query rob6/**: replied", False, bool(ask(s["intruder"], "rob6/**")))
        planner_cmd = f"{prefix}/planner/probe/move"
        check("gateway calls planner (move): replied", True, bool(ask(s["gateway"], planner_cmd)))
        check("driver calls planner (move): replied", False, bool(ask(s["driver"], planner_cmd)))
        check("intruder calls planner (move): replied", False, bool(ask(s["intruder"], planner_cmd)))
        check("planner calls kinematics (ik_batch): replied", True,
              bool(ask(s["planner"], f"{prefix}/kinematics/probe/ik_batch")))
        check("intruder calls kinematics (fk): replied", False,
              bool(ask(s["intruder"], f"{prefix}/kinematics/probe/fk")))

        # 3. reading: samples and liveliness
        inbox = {"gateway": Inbox(s["gateway"], f"{prefix}/driver/state"),
                 "gateway-control": Inbox(s["gateway"], f"{prefix}/control/**"),
                 "intruder": Inbox(s["intruder"], f"{prefix}/**"),
                 "intruder-all": Inbox(s["intruder"], "**"),
                 "intruder-state": Inbox(s["intruder"], f"{prefix}/driver/state"),
                 "driver-control": Inbox(s["driver"], f"{prefix}/control/**"),
                 "recorder": Inbox(s["recorder"], f"{prefix}/**")}
        time.sleep(SETTLE_S)
        s["driver"].put(f"{prefix}/driver/state", b'{"probe": true}')
        s["driver"].put(f"{prefix}/trace/driver/execute", b'{"probe": true}')
        s["intruder"].put(f"{prefix}/control/shutdown", b"{}")
        s["gateway"].put(f"{prefix}/control/verbosity", b'{"level": 2}')
        time.sleep(WAIT_S)
        check("gateway receives driver state", True, f"{prefix}/driver/state" in inbox["gateway"].key_exprs())
        check("intruder receives anything (rob6/<id>/**, **, driver/state)", False,
              bool(inbox["intruder"].key_exprs() or inbox["intruder-all"].key_exprs() or inbox["intruder-state"].key_exprs()))
        check("members receive the intruder's control/shutdown", False,
              bool(inbox["gateway-control"].key_exprs()))
        check("driver receives the gateway's control/verbosity", True,
              f"{prefix}/control/verbosity" in inbox["driver-control"].key_exprs())
        check("recorder receives traces", True, f"{prefix}/trace/driver/execute" in inbox["recorder"].key_exprs())
        check("gateway sees driver liveliness", True, bool(alive(s["gateway"], f"{prefix}/alive/**")))
        check("intruder sees liveliness", False, bool(alive(s["intruder"], f"{prefix}/alive/**")))
        del keep, token
    return checks


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--endpoint", help="router endpoint, e.g. tls/127.0.0.1:7447")
    parser.add_argument("--certs", type=Path, required=True, help="directory from make-certs.sh (with intruder)")
    parser.add_argument("--foreign-certs", type=Path, help="certificates of another CA (with intruder)")
    parser.add_argument("--robot-id", default=ROBOT_ID)
    parser.add_argument("--serve-router", type=Path, metavar="JSON5",
                        help="start a router here from this config instead of using --endpoint")
    args = parser.parse_args(argv)
    with ExitStack() as stack:
        endpoint = args.endpoint
        if args.serve_router:
            endpoint = stack.enter_context(local_router(args.serve_router, args.certs))
        if not endpoint:
            parser.error("--endpoint or --serve-router is required")
        checks = secure_profile_checks(endpoint, args.certs, args.robot_id, args.foreign_certs)
    for c in checks:
        print(c)
    failed = [c for c in checks if not c.ok]
    print(f"{len(checks) - len(failed)}/{len(checks)} checks as expected")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
