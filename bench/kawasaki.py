"""Benchmark of point streaming on the Kawasaki link (kaw_fs against kawasaki-as-sim).

``--link kawasaki`` against kawasaki-as-sim executing deploy/kawasaki/rob6.as (TCP): three PTP moves, a LIN move, then MoveRTJoints every
16 ms (Alter); points acknowledged, the acknowledgement's latency (driver: point sent ->
answered; controller: line in -> answer out), points merged for a late answer, and underruns
of the controller's queue (it ran dry before a final point: the arm stopped mid-motion).

Then the program alone on the stand-in's simulated clock (kawasaki_as_sim.simclock, no wall
time: the figures do not depend on this machine's load): a point every 48 ms, JT1 at 50 deg/s,
under the default PC step budget (``--pc-steps``): the arm's JT1 speed across the points, the
underruns, and what a line costs in interpreted steps.

    .venv/bin/python -m bench.kawasaki [seconds of Alter, default 20]
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path
from typing import Any

from harness.ports import free_port
from kawasaki_as_sim.asrun import PC_STEPS_PER_TICK
from kawasaki_as_sim.simclock import TICK_S, SimCell

from .links import ControllerSim, streamed_points_run
from .tables import Table, table

START = [0.0, -30.0, 40.0, 0.0, 30.0, 0.0]
PTP = ([30.0, -20.0, 50.0, 10.0, 20.0, -20.0], [-20.0, -40.0, 60.0, -10.0, 40.0, 20.0], START)
ROB6_AS = Path(__file__).resolve().parents[1] / "deploy" / "kawasaki" / "rob6.as"
PORT, STATE_PORT = 49200, 49201  # rob6.as's kport and kport + 1
PERIOD_S = 0.048
SPEED_DEG_S = 50.0
FROM_JT1 = -145.0  # the stream runs JT1 up from here: 120 points end at +143 (the range is +-160)


def kawasaki_simclock(points: int = 120, pc_steps: int = PC_STEPS_PER_TICK) -> dict[str, Any]:
    """rob6.as on the simulated clock: ``points`` lines a period apart, JT1 at SPEED_DEG_S,
    the last one final, as rob6 sends them (each answered before the next: they never overlap)."""
    cell = SimCell(ROB6_AS.read_text(), (FROM_JT1, 90.0, 0.0, 0.0, 0.0, 0.0), pc_steps)
    cell.start(("pc1", "rob6_pc"), ("robot", "rob6_motion"))
    cell.connect(PORT, cell.t)
    cell.connect(STATE_PORT, cell.t)
    cell.run(0.2)
    pc, state = cell.interp.tasks["pc1"], cell.interp.tasks["pc2"]
    pc_steps0, state_steps0, states0 = pc.steps, state.steps, len(cell.port(STATE_PORT).sent)
    t0 = cell.t + 0.1
    arrivals = [t0 + PERIOD_S * n for n in range(points)]
    for n, at in enumerate(arrivals, 1):
        cell.send(PORT, at, f"P {n} {FROM_JT1 + SPEED_DEG_S * PERIOD_S * n:.3f} 90.000 0.000 0.000 0.000 0.000 "
                            f"{round(PERIOD_S * 1000)} {int(n == points)}\n")
    cell.run(0.1 + PERIOD_S * points + 1.5)
    port = cell.port(PORT)
    answered = [t for text, t in zip(port.sent, port.sent_at, strict=True) if text.startswith("A ")]
    moving = [t for t, v in cell.speeds if v > 1.0]
    middle = [v for t, v in cell.speeds if moving[0] + 0.3 < t < moving[-1] - 0.3]
    states = len(cell.port(STATE_PORT).sent) - states0
    under, done = cell.value("kunder"), cell.value("kdone")
    assert isinstance(under, float) and isinstance(done, float)
    return {"points": points, "pc_steps": pc_steps, "errors": cell.errors,
            "speed": (min(middle), statistics.fmean(middle), max(middle)),
            "underruns": int(under), "done": int(done),
            "arrived": cell.arm.q[0] == round(FROM_JT1 + SPEED_DEG_S * PERIOD_S * points, 3) and not cell.arm.moving,
            "refused": sum(1 for text in port.sent if text.startswith("A ") and text.split()[2] != "0"),
            # rob6_pc's steps per line: rob6_line and the receive/answer loop around it
            "line_steps": (pc.steps - pc_steps0) / points,
            "state_steps": (state.steps - state_steps0) / max(states, 1),
            "answer_ms": sorted((a - b) * 1000.0 for a, b in zip(answered, arrivals, strict=False)),
            "answers": len(answered)}


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


def kawasaki_simclock_table(table: Table, points: int = 120) -> dict[str, Any]:
    r = kawasaki_simclock(points)
    lo, mean, hi = r["speed"]
    ms = r["answer_ms"]
    budget = r["pc_steps"] * PERIOD_S / TICK_S
    table(f"rob6.as alone on the stand-in's simulated clock: {points} points every {PERIOD_S * 1000:.0f} ms, "
          f"JT1 at {SPEED_DEG_S:.0f} deg/s, default PC step budget {r['pc_steps']} steps / {TICK_S * 1000:.0f} ms "
          f"tick (a guess until a first session measures it)",
          ("measure", "rob6.as", "goal"), [
              ("JT1 speed across the points (min / mean / max, deg/s)",
               f"{lo:.1f} / {mean:.1f} / {hi:.1f}", f"{SPEED_DEG_S:.0f} throughout"),
              ("underruns (the queue ran dry before the final point)", str(r["underruns"]), "0"),
              ("points refused / done / final point reached exactly",
               f"{r['refused']} / {r['done']} / {'yes' if r['arrived'] else 'no'}", f"0 / {points} / yes"),
              ("line cost: rob6_pc steps per P line (rob6_line and the receive loop)",
               f"{r['line_steps']:.0f}", f"well under {budget:.0f} (a period's budget)"),
              ("rob6_state: steps per state line", f"{r['state_steps']:.0f}", ""),
              ("line arrives -> answered (simulated) p50 / max, ms",
               f"{ms[len(ms) // 2]:.0f} / {ms[-1]:.0f}", f"< {PERIOD_S * 1000:.0f}"),
              ("run-time errors", str(len(r["errors"])), "0"),
          ])
    return r


if __name__ == "__main__":
    kawasaki_simclock_table(table)
    kawasaki_table(float(sys.argv[1]) if len(sys.argv) > 1 else 20.0, table)
