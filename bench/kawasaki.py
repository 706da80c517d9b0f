"""Benchmark of point streaming on the Kawasaki link (kaw_fs against kawasaki-as-sim).

``--link kawasaki`` against kawasaki-as-sim executing deploy/kawasaki/rob6.as (TCP): three PTP moves, a LIN move, then MoveRTJoints every
16 ms (Alter); points acknowledged, the acknowledgement's latency (driver: point sent ->
answered; controller: line in -> answer out), points merged for a late answer, and underruns
of the controller's queue (it ran dry before a final point: the arm stopped mid-motion).

    .venv/bin/python -m bench.kawasaki [seconds of Alter, default 20]
"""

from __future__ import annotations

import sys
from typing import Any

from harness.ports import free_port

from .links import ControllerSim, streamed_points_run
from .tables import Table, table

START = [0.0, -30.0, 40.0, 0.0, 30.0, 0.0]
PTP = ([30.0, -20.0, 50.0, 10.0, 20.0, -20.0], [-20.0, -40.0, 60.0, -10.0, 40.0, 20.0], START)


def kawasaki_stream(seconds: float) -> dict[str, Any]:
    port, state_port = free_port(), free_port()
    sim = ControllerSim("kawasaki_as_sim", "--port", str(port), "--state-port", str(state_port))
    before, after, link, moves = streamed_points_run("kaw_fs", {"ROB6_LINK": "kawasaki", "ROB6_KAS_PORT": str(port),
                                                                 "ROB6_KAS_STATE_PORT": str(state_port)},
                                                     sim, "the Kawasaki link", START, PTP, "EnableAlter", seconds,
                                                     lin_y_mm=60.0)
    def refused(st: dict[str, Any]) -> int:
        return sum(n for code, n in st["answers"].items() if code != "0")
    return {"received": after["lines_received"] - before["lines_received"],
            "accepted": after["answers"].get("0", 0) - before["answers"].get("0", 0),
            "refused": refused(after) - refused(before),
            "underruns": after["underruns_reported"] - before["underruns_reported"], "merged": link.late,
            "link_latency_us": link.latency_us or [float("nan")] * 3, "controller_ack_ms": after["ack_ms"],
            "packets": link.packets, "moves": moves, "max_speed_ratio": after["max_speed_ratio"]}


def kawasaki_table(seconds: float, table: Table) -> dict[str, Any]:
    r = kawasaki_stream(seconds)
    lat = r["link_latency_us"]
    table(f"The Kawasaki over rob6's AS program (executed by kawasaki-as-sim): 3 PTP moves, a LIN move, then MoveRTJoints every 16 ms for "
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
