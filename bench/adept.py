"""Benchmark of the Adept link's pacing: ad850 over simple_message at monitor speeds 3, 10 and 100 %.

The whole system on ``--link simple_message`` against adept-sm-sim (TCP, playing
``adept_ros.v2``: every point a MOVE planned at 100 % and stretched by the monitor speed,
one MOVE ahead), at each monitor speed in turn after ``SetAdeptSpeed 100``, with rob6's
default speed and acceleration limits and with them raised to the protocol's bounds
(``SetJointsMaxSpeed``, ``SetJointsMaxAcceleration``): a long PTP (its arrival against the plan's own duration, the points merged,
the longest segment in degrees against ``MAX_SEGMENT_DEG``, the acknowledgements'
latency, lost links), a client that vanishes mid-move (how far and how long the arm ran
on after rob6's last point, against the stated bound), and, at the default limits, Alter
streaming (MoveRTJoints every 16 ms).

    .venv/bin/python -m bench.adept [seconds of Alter, default 10]
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

from harness.ports import free_port
from harness.system import System, running
from rob6.messages import LinkQuery, LinkStatus
from rob6.robots import get_robot
from rob6_driver.links.simple_message import MAX_SEGMENT_DEG
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import TrajectoryPlanner

from .links import ControllerSim
from .tables import Table, table

ROBOT = get_robot("ad850")
MONITOR_SPEEDS = (3.0, 10.0, 100.0)
START = [0.0, -60.0, 40.0, 0.0, 30.0, 0.0]
LONG = [60.0, -40.0, 60.0, 20.0, 40.0, 30.0]
#: the stand-in's J1 acceleration on its path at 100 % (90 % of full speed in 0.25 s) and its servo's settling
ACCEL_J1_DEG_S2 = 0.9 * 250.0 / 0.25
SERVO_TAIL_S = 0.1


def _fmt(q: list[float]) -> str:
    return " ".join(f"{x:f}" for x in q)


def run_on_bound(monitor: float) -> tuple[float, float]:
    """The stated stop bound (deploy/adept/README.md): three segments of J1's MAX_SEGMENT_DEG,
    and their time from rest to rest at 100 % stretched by the monitor speed."""
    distance = 3 * float(MAX_SEGMENT_DEG[0])
    return distance, (2 * float(np.sqrt(distance / ACCEL_J1_DEG_S2)) + SERVO_TAIL_S) * 100 / monitor


def _link(system: System, reset: bool = False) -> LinkStatus:
    """The driver's link status (``reset``: its latencies counted afresh from now)."""
    bus = system.bus("bench")
    try:
        bus.wait_for(["driver"], 10)
        status: LinkStatus = bus.request("driver", "link", LinkQuery(reset=reset))
        return status
    finally:
        bus.close()


def _ready(system: System, sim: ControllerSim, raised: bool) -> None:
    with system.client() as client:
        deadline = time.monotonic() + 30
        while True:
            here = _fmt(sim.status()["position_rob6_deg"])
            if client.ask("MovePTPJoints " + here, lines=1, timeout=60) == "true\n":
                break
            client.read_lines(1, timeout=1)  # the "false" after the ERROR line
            assert time.monotonic() < deadline, "the Adept link did not come up"
            time.sleep(0.2)
        assert client.ask("SetAdeptSpeed 100") == "true\n"
        limits = ROBOT.speed_bound if raised else ROBOT.default_speed
        assert client.ask("SetJointsMaxSpeed " + _fmt(list(limits))) == "true\n"
        accel = [ROBOT.max_accel_bound] * 6 if raised else list(ROBOT.default_accel)
        assert client.ask("SetJointsMaxAcceleration " + _fmt(accel)) == "true\n"
        assert client.ask("MovePTPJoints " + _fmt(START), timeout=120) == "true\n"


def run_at(system: System, motion: int, state: int, monitor: float, seconds: float, raised: bool) -> dict[str, Any]:
    sim = ControllerSim("adept_sm_sim", "--motion-port", str(motion), "--state-port", str(state), "--io-port", "off",
                        "--monitor-speed", str(monitor))
    try:
        _ready(system, sim, raised)
        before_link, before = _link(system, reset=True), sim.status()
        config = MotionSettings(ROBOT)
        if raised:
            config.speed, config.accel = list(ROBOT.speed_bound), [ROBOT.max_accel_bound] * 6
        planned = TrajectoryPlanner(ROBOT).plan_ptp(START, LONG, config).trajectory
        assert planned is not None
        with system.client() as client:
            began = time.perf_counter()
            assert client.ask("MovePTPJoints " + _fmt(LONG), timeout=120) == "true\n"
            arrived = time.perf_counter() - began
        ptp_link, ptp = _link(system), sim.status()
        # a client that vanishes mid-move
        with system.client() as client:
            assert client.ask("MovePTPJoints " + _fmt(START), timeout=120) == "true\n"
            client.send("MovePTPJoints " + _fmt(LONG) + "\n")
            while sim.status()["position_rob6_deg"][0] < 20.0:
                time.sleep(0.01)
        vanished = time.perf_counter()
        while (stop := sim.status())["in_motion"]:
            time.sleep(0.01)
        at_rest = time.perf_counter() - vanished
        # Alter
        with system.client() as client:
            assert client.ask("MovePTPJoints " + _fmt(START), timeout=120) == "true\n"
            alter_before, alter_link = sim.status(), _link(system)
            assert client.ask("EnableAdeptAlter") == "true\n"
            n = int(seconds / 0.016) if not raised else 0
            began = time.perf_counter()
            for k in range(n):
                q = list(START)
                q[0] = 10.0 * np.sin(2 * np.pi * 0.2 * k * 0.016)
                client.send("MoveRTJoints " + _fmt(q) + "\n")
                client.read_lines(1)
                delay = began + (k + 1) * 0.016 - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
            assert client.ask("DisableAlter", timeout=60) == "true\n"
        alter, end_link = sim.status(), _link(system)
    finally:
        sim.close()
    return {
        "planned": len(planned.q) * planned.dt, "arrived": arrived,
        "points": ptp_link.packets - before_link.packets, "merged": ptp_link.late - before_link.late,
        "segment_s": ptp["longest_segment_s"], "segment_deg": ptp["longest_segment_deg"],
        "ran_on_deg": stop["ran_on_deg"],
        "latency_ms": [x / 1000 for x in (ptp_link.latency_us or [float("nan")] * 3)],
        "lost": end_link.runs - before_link.runs, "task_errors": alter["task_errors"] - before["task_errors"],
        "underruns": ptp["underruns"] - before["underruns"],
        "at_rest": at_rest, "ran_on": stop["ran_on_s"], "stop_segment_s": stop["longest_segment_s"],
        "alter_points": alter["points_acknowledged"] - alter_before["points_acknowledged"],
        "alter_merged": end_link.late - alter_link.late, "alter_underruns": alter["underruns"] - alter_before["underruns"],
    }


def adept_table(seconds: float, table: Table) -> dict[tuple[float, bool], dict[str, Any]]:
    motion, state = free_port(), free_port()
    env = {"ROB6_LINK": "simple_message", "ROB6_SM_MOTION_PORT": str(motion), "ROB6_SM_STATE_PORT": str(state)}
    cases = [(m, raised) for raised in (False, True) for m in MONITOR_SPEEDS]
    with running("ad850", dummy=False, extra_env=env) as system:
        runs = {c: run_at(system, motion, state, c[0], seconds, c[1]) for c in cases}

    def each(fmt: Any) -> tuple[str, ...]:
        return tuple(fmt(c[0], runs[c]) for c in cases)

    travel = max(abs(a - b) for a, b in zip(START, LONG, strict=True))
    bound = " ".join(f"{x:g}" for x in MAX_SEGMENT_DEG)
    table("The Adept over simple_message, paced by its acknowledgements: ad850 against adept-sm-sim (adept_ros.v2: "
          f"every point a MOVE planned at 100 % and stretched by the monitor speed), SetAdeptSpeed 100; a PTP of "
          f"{travel:.0f} deg, a client vanishing mid-move, MoveRTJoints every 16 ms for {seconds:.0f} s (default "
          "limits only); at rob6's default speed and acceleration limits and at their protocol bounds (raised)",
          ("measure", *(f"{m:g} %{', raised' if r else ''}" for m, r in cases), "goal"), [
              ("PTP: planned -> arrived (true), s", *each(lambda _m, r: f"{r['planned']:.2f} -> {r['arrived']:.2f}"),
               "arrives; slower only as the arm is"),
              ("PTP: points acknowledged / merged", *each(lambda _m, r: f"{r['points']} / {r['merged']}"), ""),
              ("PTP: longest segment per joint, deg (J1..J6)",
               *each(lambda _m, r: " ".join(f"{x:.2f}" for x in r["segment_deg"])), f"<= {bound}"),
              ("PTP: longest segment on the arm's clock, s", *each(lambda _m, r: f"{r['segment_s']:.3f}"), ""),
              ("PTP: point sent -> acknowledged (driver) p50 / p99 / max, ms",
               *each(lambda _m, r: " / ".join(f"{x:.1f}" for x in r["latency_ms"])), "may exceed 2000 while the arm moves"),
              ("PTP: the arm stopped at a point, its next MOVE late (underruns)", *each(lambda _m, r: str(r["underruns"])),
               ""),
              ("vanished client: arm at rest after, s (wall)", *each(lambda _m, r: f"{r['at_rest']:.2f}"), ""),
              ("vanished client: ran on after rob6's last point, deg / bound",
               *each(lambda m, r: f"{r['ran_on_deg']:.2f} / {run_on_bound(m)[0]:.1f}"), "<= bound, same at every speed"),
              ("vanished client: ran on after rob6's last point, s / bound",
               *each(lambda m, r: f"{r['ran_on']:.2f} / {run_on_bound(m)[1]:.2f}"), "<= bound"),
              ("Alter: points acknowledged / merged / underruns",
               *each(lambda _m, r: f"{r['alter_points']} / {r['alter_merged']} / {r['alter_underruns']}"), ""),
              ("false 'link lost' / motion tasks ended (whole run)",
               *each(lambda _m, r: f"{r['lost']} / {r['task_errors']}"), "0 / 0"),
          ])
    return runs


if __name__ == "__main__":
    adept_table(float(sys.argv[1]) if len(sys.argv) > 1 else 10.0, table)
