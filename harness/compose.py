"""Run docker and docker compose commands for the Docker tests and the multi-host benchmark.

Used by tests/deploy/test_compose_e2e.py and harness/topology.py (which bench/multihost.py uses).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Iterable
from typing import Any


def run(cmd: list[str], *, timeout: float = 900, check: bool = True, **kw: Any) -> subprocess.CompletedProcess[str]:
    """``cmd`` with its output captured as text; with ``check``, a non-zero exit raises an
    AssertionError naming the command, its exit code and the tail of its output."""
    proc = subprocess.run(cmd, capture_output=True, check=False, text=True, timeout=timeout, **kw)
    if check and proc.returncode != 0:
        raise AssertionError(f"{' '.join(cmd)} -> {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc


def compose_cmd() -> list[str] | None:
    """The compose command that works here: ``docker compose`` or ``docker-compose`` (None: neither)."""
    for cmd in (["docker", "compose"], ["docker-compose"]):
        if shutil.which(cmd[0]) and subprocess.run([*cmd, "version"], capture_output=True, check=False).returncode == 0:
            return cmd
    return None


def project_containers(project: str, service: str | None = None) -> list[str]:
    """The ids of a compose project's containers, stopped ones too (one service's with ``service``)."""
    filters = ["--filter", f"label=com.docker.compose.project={project}"]
    if service:
        filters += ["--filter", f"label=com.docker.compose.service={service}"]
    return run(["docker", "ps", "-a", "-q", *filters]).stdout.split()


def unhealthy(project: str, services: Iterable[str]) -> list[str]:
    """What keeps a compose project's ``services`` from being healthy, a line each
    ("<service>: no container", "<service> <id>: <status>/<health>"); empty: all healthy."""
    pending = []
    for service in services:
        ids = project_containers(project, service)
        if not ids:
            pending.append(f"{service}: no container")
        for cid in ids:
            state = json.loads(run(["docker", "inspect", "-f", "{{json .State}}", cid]).stdout)
            health = (state.get("Health") or {}).get("Status", "none")
            if health != "healthy":
                pending.append(f"{service} {cid[:12]}: {state['Status']}/{health}")
    return pending
