"""Benchmark of the multi-host deployment under real network faults (latency, partitions, loss, router kill).

The multi-host figures (issue 14, deploy/MULTI_HOST.md): deploy/multihost/docker-compose.yml
with real network faults from this machine (harness/topology.py).

    sudo .venv/bin/python -m bench.multihost        # Docker, root (nsenter, iptables); ~6 min

- BackwardCalc p50/p99 through the gateway with kinematics on the robot PC vs on the compute
  hosts (two replicas on compute1, one on compute2), at 0, 1 and 5 ms added one-way delay
  between the robot PC and the compute hosts;
- compute1 partitioned for 8 s under a BackwardCalc loop: answers, errors, time until every
  call succeeds again after the heal;
- 5 % loss and 0..20 ms jitter each way between the robot PC and the compute hosts: share
  answered correctly, p99;
- the robot PC's router killed: the robot PC's services, the remote replicas, and the time
  until they are reached again after the router is started.

``ROB6_BENCH_MH_COUNT`` calls per latency cell (default 400).
"""

from __future__ import annotations

import os
import sys
import time

from harness import images
from harness.client import Client
from harness.compose import run
from harness.topology import (
    REMOTE_KINEMATICS,
    Call,
    Load,
    Topology,
    backward_line,
    calls,
    fault_tools_missing,
    percentile,
    recovery,
)

from .tables import Row, Table, table

COUNT = int(os.environ.get("ROB6_BENCH_MH_COUNT", "400"))
DELAYS_MS = (0, 1, 5)


def _ms(values: list[float], q: float) -> str:
    return f"{percentile(values, q) * 1000:.2f}"


def _wait_only(client: Client, line: str, timeout: float = 60) -> None:
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


def latency_rows(topo: Topology, client: Client, line: str, rounds: int = 8) -> list[Row]:
    """Each placement: ``rounds`` rounds of COUNT/rounds calls at each delay in turn, so a
    machine that gets busier or quieter meanwhile weighs on every delay alike."""
    rows: list[Row] = []
    for where in ("robot PC", "compute hosts (3 replicas)"):
        _place(topo, where)
        _wait_only(client, line)
        results: dict[int, list[Call]] = {delay: [] for delay in DELAYS_MS}
        for _ in range(rounds):
            for delay in DELAYS_MS:
                for host in ("compute1", "compute2"):
                    if delay:
                        topo.netem(host, delay_ms=delay)
                    else:
                        topo.clear_netem(host)
                calls(client, line, 5)  # warm up
                results[delay] += calls(client, line, max(1, COUNT // rounds))
        for host in ("compute1", "compute2"):
            topo.clear_netem(host)
        for delay in DELAYS_MS:
            seconds = [c.seconds for c in results[delay]]
            rows.append((where, f"{delay} ms", _ms(seconds, 50), _ms(seconds, 99),
                         f"{sum(c.ok for c in results[delay])}/{len(results[delay])}"))
    return rows


def partition_row(topo: Topology, client: Client, line: str, seconds: float = 8.0, watch: float = 10.0) -> Row:
    with Load(client, line) as load:
        time.sleep(2)
        with topo.partitioned("compute1"):
            cut = time.monotonic()
            time.sleep(seconds)
        healed = time.monotonic()
        time.sleep(watch)
    during = [c for c in load.calls if cut <= c.t < healed]
    after = [c for c in load.calls if c.t >= healed]
    back = recovery(load.calls, healed)
    first_ok = next((c.t - cut for c in during if c.ok and c.t - cut > 0.5), None)
    last_error = max((c.t - healed for c in after if not c.ok), default=None)
    hung = sum(not c.reply for c in load.calls)
    return (f"compute1 cut {seconds:.0f} s", f"{sum(c.ok for c in during)}/{len(during)}",
            "never" if first_ok is None else f"{first_ok:.2f}", f"{max(c.seconds for c in load.calls) * 1000:.0f}",
            hung, "never" if back is None else f"{back:.2f}",
            "none" if last_error is None else f"{last_error:.2f}", f"{sum(not c.ok for c in after)}/{len(after)}")


def loss_row(topo: Topology, client: Client, line: str) -> Row:
    with topo.impaired(delay_ms=10, jitter_ms=10, loss=0.05):
        results = calls(client, line, COUNT)
    seconds = [c.seconds for c in results]
    ok = sum(c.ok for c in results)
    first_error = next((c.reply.strip() for c in results if c.error), "")
    return ("5 % loss + 0..20 ms jitter", f"{ok}/{len(results)} ({ok / len(results):.1%})", _ms(seconds, 50),
            _ms(seconds, 99), first_error[:60])


def router_kill_rows(topo: Topology, client: Client, line: str) -> list[Row]:
    """BackwardCalc in a loop (remote kinematics) while the robot PC's router is killed and,
    8 s later, started again; the robot PC's own services meanwhile."""
    router = topo.container("router-pc")
    with Load(client, line) as load:
        time.sleep(2)
        run(["docker", "kill", router])
        killed = time.monotonic()
        time.sleep(4)
    without = [c for c in load.calls if c.t >= killed]
    try:
        t = time.monotonic()
        ping = client.ask("CM_PING") == "PONG\n"
        ping_ms = (time.monotonic() - t) * 1000
        moved = client.ask("MovePTPJoints 11 -20 30 40 50 60", timeout=30) == "true\n"
        moved = moved and client.ask("MovePTPJoints 10 -20 30 40 50 60", timeout=30) == "true\n"
    finally:
        with Load(client, line) as load:
            run(["docker", "start", router])
            restarted = time.monotonic()
            while time.monotonic() - restarted < 30:
                time.sleep(0.5)
                if recovery(load.calls, restarted) is not None:
                    break
    back = recovery(load.calls, restarted)
    return [("remote kinematics without the router (4 s loop)",
             f"{sum(c.ok for c in without)}/{len(without)} correct, {sum(c.error for c in without)} ERROR, "
             f"{sum(not c.reply for c in without)} hangs",
             f"slowest {max(c.seconds for c in without) * 1000:.0f} ms"),
            ("robot PC services without their router", "CM_PING + 2 PTPs " + ("ok" if ping and moved else "FAILED"),
             f"CM_PING {ping_ms:.1f} ms"),
            ("router started again (docker start)", "remote replicas reached again",
             "never" if back is None else f"all-success {back:.2f} s after docker start")]


def multihost_table(table: Table) -> None:
    why = fault_tools_missing()
    if why:
        print(f"\nmulti-host bench skipped: {why}")
        return
    outcome = images.build()
    print("\n" + "\n".join(outcome.steps))
    if outcome.error:
        print(f"multi-host bench skipped: rob6 images not built: {outcome.error}")
        return
    topo = Topology(f"rob6mhbench{os.getpid()}", local_kinematics=True, health_interval="60s")
    try:
        print(f"multi-host topology up in {topo.up():.0f} s")
        client = topo.client()
        try:
            line = backward_line(client)
            table(f"BackwardCalc through the gateway (multi-host, {COUNT} calls per cell, ms)",
                  ("kinematics on", "added one-way delay", "p50", "p99", "correct"),
                  latency_rows(topo, client, line))
            table("Compute host partitioned under a BackwardCalc loop (compute2's replica stays)",
                  ("fault", "correct during", "compute2 serving from s", "slowest call ms", "hangs",
                   "20 ok in a row from s after heal", "last error s after heal", "errors in 10 s after heal"),
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
    multihost_table(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
