"""The multi-host figures (issue 14, deploy/MULTI_HOST.md): deploy/multihost/docker-compose.yml
with real network faults from this machine (tests/deploy/multihost/topology.py).

    sudo .venv/bin/python -m bench.multihost        # Docker, root (nsenter, iptables); ~6 min

- BackwardCalc p50/p99 through the gateway with kinematics on the robot PC vs on the compute
  hosts (two replicas on compute1, one on compute2), at 0, 1 and 5 ms added one-way delay
  between the robot PC and the compute hosts;
- compute1 partitioned for 8 s under a BackwardCalc loop: answers, errors, time until every
  call succeeds again after the heal;
- 5 % loss and 0..20 ms jitter each way between the robot PC and the compute hosts: share
  answered correctly, p99;
- the robot PC's router killed: the robot PC's services, the remote replicas.

``ROB6_BENCH_MH_COUNT`` calls per latency cell (default 400).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable

from tests.deploy.multihost.topology import (
    REMOTE_KINEMATICS,
    Load,
    Topology,
    backward_line,
    calls,
    ensure_images,
    fault_tools_missing,
    percentile,
    recovery,
    run,
)

Table = Callable[[str, tuple[str, ...], list[tuple]], None]
COUNT = int(os.environ.get("ROB6_BENCH_MH_COUNT", "400"))
DELAYS_MS = (0, 1, 5)


def _ms(values: list[float], q: float) -> str:
    return f"{percentile(values, q) * 1000:.2f}"


def _wait_only(client, line: str, timeout: float = 60) -> None:
    """Until 20 calls in a row succeed (the liveliness of the replicas settled)."""
    deadline = time.monotonic() + timeout
    streak = 0
    while streak < 20:
        if time.monotonic() > deadline:
            raise RuntimeError("BackwardCalc does not succeed")
        streak = streak + 1 if calls(client, line, 1)[0].ok else 0


def _place(topo: Topology, where: str) -> None:
    """Kinematics only on the robot PC, or only on the compute hosts (stopped, not removed)."""
    remote = [c for s in REMOTE_KINEMATICS for c in topo.containers(s)]
    local = topo.containers("kinematics-pc")
    if where == "robot PC":
        run(["docker", "start", *local])
        topo.wait_healthy(("kinematics-pc",), timeout=90)
        run(["docker", "stop", "-t", "3", *remote])
    else:
        run(["docker", "start", *remote])
        topo.wait_healthy(REMOTE_KINEMATICS, timeout=90)
        run(["docker", "stop", "-t", "3", *local])


def latency_rows(topo: Topology, client, line: str) -> list[tuple]:
    rows = []
    for where in ("robot PC", "compute hosts (3 replicas)"):
        _place(topo, where)
        _wait_only(client, line)
        for delay in DELAYS_MS:
            for host in ("compute1", "compute2"):
                if delay:
                    topo.netem(host, delay_ms=delay)
                else:
                    topo.clear_netem(host)
            calls(client, line, 30)  # warm up
            results = calls(client, line, COUNT)
            seconds = [c.seconds for c in results]
            rows.append((where, f"{delay} ms", _ms(seconds, 50), _ms(seconds, 99),
                         f"{sum(c.ok for c in results)}/{len(results)}"))
        for host in ("compute1", "compute2"):
            topo.clear_netem(host)
    return rows


def partition_row(topo: Topology, client, line: str, seconds: float = 8.0) -> tuple:
    with Load(client, line) as load:
        time.sleep(2)
        with topo.partitioned("compute1"):
            cut = time.monotonic()
            time.sleep(seconds)
        healed = time.monotonic()
        while time.monotonic() - healed < 30:
            time.sleep(0.5)
            if recovery(load.calls, healed) is not None and load.calls[-1].t - healed > 5:
                break
    during = [c for c in load.calls if cut <= c.t < healed]
    back = recovery(load.calls, healed)
    hung = sum(not c.reply for c in load.calls)
    return (f"compute1 cut {seconds:.0f} s", f"{sum(c.ok for c in during)}/{len(during)}",
            sum(c.error for c in during), f"{max(c.seconds for c in load.calls) * 1000:.0f}", hung,
            "never" if back is None else f"{back:.2f}")


def loss_row(topo: Topology, client, line: str) -> tuple:
    for host in ("compute1", "compute2"):
        topo.netem(host, delay_ms=10, jitter_ms=10, loss=0.05)
    try:
        results = calls(client, line, COUNT)
    finally:
        for host in ("compute1", "compute2"):
            topo.clear_netem(host)
    seconds = [c.seconds for c in results]
    ok = sum(c.ok for c in results)
    first_error = next((c.reply.strip() for c in results if c.error), "")
    return ("5 % loss + 0..20 ms jitter", f"{ok}/{len(results)} ({ok / len(results):.1%})", _ms(seconds, 50),
            _ms(seconds, 99), first_error[:60])


def router_kill_rows(topo: Topology, client, line: str) -> list[tuple]:
    router = topo.container("router-pc")
    run(["docker", "kill", router])
    killed = time.monotonic()
    try:
        ping = client.ask("CM_PING") == "PONG\n"
        moved = client.ask("MovePTPJoints 11 -20 30 40 50 60", timeout=30) == "true\n"
        local = time.monotonic() - killed
        results = calls(client, line, 100)
        first_ok = next((c.t - killed for c in results if c.ok), None)
        ok = sum(c.ok for c in results)
    finally:
        run(["docker", "start", router])
    restarted = time.monotonic()
    topo.wait_healthy(("router-pc",), timeout=60)
    _wait_only(client, line)
    return [("robot PC services (CM_PING, a PTP)", "ok" if ping and moved else "FAILED", f"{local:.2f} s"),
            ("remote kinematics, 100 BackwardCalc", f"{ok}/100 correct",
             "never" if first_ok is None else f"first ok {first_ok:.2f} s after the kill"),
            ("router restarted: all-success again", "ok", f"{time.monotonic() - restarted:.2f} s")]


def multihost_table(table: Table) -> None:
    why = fault_tools_missing()
    if why:
        print(f"\nmulti-host bench skipped: {why}")
        return
    print("\n" + ensure_images())
    topo = Topology(f"rob6mhbench{os.getpid()}", local_kinematics=True)
    try:
        print(f"multi-host topology up in {topo.up():.0f} s")
        client = topo.client()
        try:
            line = backward_line(client)
            table(f"BackwardCalc through the gateway (multi-host, {COUNT} calls per cell, ms)",
                  ("kinematics on", "added one-way delay", "p50", "p99", "correct"),
                  latency_rows(topo, client, line))
            table("Compute host partitioned under a BackwardCalc loop (compute2's replica stays)",
                  ("fault", "correct during", "errors during", "slowest call ms", "hangs",
                   "all-success after heal s"),
                  [partition_row(topo, client, line)])
            table(f"Loss and jitter between the robot PC and the compute hosts ({COUNT} calls)",
                  ("link", "correct", "p50 ms", "p99 ms", "first error"),
                  [loss_row(topo, client, line)])
            table("Robot PC's router killed", ("what", "result", "time"), router_kill_rows(topo, client, line))
        finally:
            client.close()
    finally:
        topo.down()


def main() -> int:
    from bench.__main__ import table
    multihost_table(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
