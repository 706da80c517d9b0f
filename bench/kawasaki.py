"""Point streaming on the Kawasaki link: kaw_fs over ``--link kawasaki`` against kawasaki-as-sim
(rob6's AS program pair stand-in, TCP): three PTP moves, a LIN move, then MoveRTJoints every
16 ms (Alter); points acknowledged, the acknowledgement's latency (driver: point sent ->
answered; controller: line in -> answer out), points merged for a late answer, and underruns
of the controller's queue (it ran dry before a final point: the arm stopped mid-motion).

    .venv/bin/python -m bench.kawasaki [seconds of Alter, default 20]
"""

from __future__ import annotations

import sys
import tempfile
import time

import numpy as np

from rob6.bus import Bus
from rob6.config import BusSettings
from rob6.messages import LinkQuery
from tests.system import free_port, running

from .links import ControllerSim
from .tables import Table, table

START = [0.0, -30.0, 40.0, 0.0, 30.0, 0.0]
PTP = ([30.0, -20.0, 50.0, 10.0, 20.0, -20.0], [-20.0, -40.0, 60.0, -10.0, 40.0, 20.0], START)


def kawasaki_stream(seconds: float) -> dict:
    port = free_port()
    sim = ControllerSim("kawasaki_as_sim", "--port", str(port))
    try:
        with tempfile.TemporaryDirectory() as logs, \
                running("kaw_fs", dummy=False, log_dir=logs,
                        extra_env={"ROB6_LINK": "kawasaki", "ROB6_KAS_PORT": str(port)}) as system:
            bus = Bus(BusSettings(robot="kaw_fs", robot_id=system.robot_id,
                                  connect=(f"tcp/127.0.0.1:{system.router_port}",)), "bench")
            try:
                bus.wait_for(["driver"], 10)
                with system.client() as client:
                    start = " ".join(map(str, START))
                    deadline = time.monotonic() + 30
                    while client.ask("MovePTPJoints " + start, lines=1, timeout=60) != "true\n":
                        client.read_lines(1, timeout=1)  # the "false" after the ERROR line
                        assert time.monotonic() < deadline, "the Kawasaki link did not come up"
                        time.sleep(0.2)
                    before = sim.status()
                    bus.request("driver", "link", LinkQuery(reset=True))
                    moves = []
                    for target in PTP:
                        began = time.perf_counter()
                        assert client.ask("MovePTPJoints " + " ".join(map(str, target)), timeout=60) == "true\n"
                        moves.append(time.perf_counter() - began)
                    pose = [float(x) for x in client.ask("GetPositionHomRowWise").split()]
                    pose[7] += 60.0
                    assert client.ask("EnableLin") == "true\n"
                    began = time.perf_counter()
                    assert client.ask("MoveLINHomRowWise " + " ".join(f"{x:f}" for x in pose), timeout=60) == "true\n"
                    moves.append(time.perf_counter() - began)
                    assert client.ask("DisableLin") == "true\n"
                    assert client.ask("MovePTPJoints " + start, timeout=60) == "true\n"
                    assert client.ask("EnableAlter") == "true\n"
                    period, n = 0.016, int(seconds / 0.016)
                    began = time.perf_counter()
                    for k in range(n):
                        q = list(START)
                        q[0] = 10.0 * np.sin(2 * np.pi * 0.2 * k * period)
                        client.send("MoveRTJoints " + " ".join(f"{x:f}" for x in q) + "\n")
                        client.read_lines(1)
                        delay = began + (k + 1) * period - time.perf_counter()
                        if delay > 0:
                            time.sleep(delay)
                    time.sleep(0.5)
                    assert client.ask("DisableAlter", timeout=10) == "true\n"
                    link = bus.request("driver", "link", LinkQuery())
                    after = sim.status()
            finally:
                bus.close()
    finally:
        sim.close()
    refused_before = sum(before["refused"].values())
    return {"received": after["points_received"] - before["points_received"],
            "accepted": after["points_accepted"] - before["points_accepted"],
            "refused": sum(after["refused"].values()) - refused_before,
            "underruns": after["underruns"] - before["underruns"], "merged": link.late,
            "link_latency_us": link.latency_us or [float("nan")] * 3, "controller_ack_ms": after["ack_ms"],
            "packets": link.packets, "moves": moves, "max_speed_ratio": after["max_speed_ratio"]}


def kawasaki_table(seconds: float, table: Table) -> dict:
    r = kawasaki_stream(seconds)
    lat = r["link_latency_us"]
    table(f"The Kawasaki over rob6's AS program: 3 PTP moves, a LIN move, then MoveRTJoints every 16 ms for "
          f"{seconds:.0f} s on kaw_fs against kawasaki-as-sim (TCP, state every 50 ms)",
          ("measure", "--link kawasaki", "goal"), [
              ("points sent / acknowledged (controller)", f"{r['received']} / {r['accepted']}", "all"),
              ("points refused / merged (a late acknowledgement)", f"{r['refused']} / {r['merged']}", "0 / 0"),
              ("underruns of the controller's queue", str(r["underruns"]), "0"),
              ("point sent -> acknowledged (driver) p50 / p99 / max, ms",
               " / ".join(f"{x / 1000:.1f}" for x in lat), "p99 < 48 (one period)"),
              ("line in -> answer out (controller) p50 / p99 / max, ms",
               " / ".join(f"{x:.2f}" for x in r["controller_ack_ms"]), ""),
              ("fastest axis, fraction of its rated speed", f"{r['max_speed_ratio']:.3f}", "<= 1"),
              ("PTP x3, LIN: command -> true, s", " / ".join(f"{m:.2f}" for m in r["moves"]), ""),
          ])
    return r


if __name__ == "__main__":
    kawasaki_table(float(sys.argv[1]) if len(sys.argv) > 1 else 20.0, table)
