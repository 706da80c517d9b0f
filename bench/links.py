"""Benchmark of Alter streaming through the whole system on each robot link (sim, RSI).

Alter streaming through the whole system on each robot link: MoveRTJoints at 250 Hz on
kr16rt (4 ms cycle) with the recorder on, once on the simulation (``--link sim``) and
once on RSI against the KR C4 simulator (kuka-rsi-sim, a separate process speaking
RSI over real UDP), so the RSI figures stand beside the simulation's in the same run.
The links that stream points share ``streamed_points_run`` and ``ControllerSim`` from
here: the Kawasaki's table (bench/kawasaki.py); the Adept's pacing has bench/adept.py."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from harness.client import Client
from harness.ports import free_port
from harness.system import running
from rob6.messages import Empty, LinkQuery, LinkStatus
from rob6.robots import get_robot
from tests.controllers.rsi_controller import SYSTEM_TIMEOUT, install

from .latency import REACH_S, bare_relay, percentiles
from .tables import Table
from .viewer import Viewer

START = "0 -80 100 0 30 0"
#: the stream's period: one target per cycle of kr16rt (4 ms, 250 Hz)
ALTER_PERIOD_S = get_robot("kr16rt").cycle_s
#: more joint_states than a stream's subscriber receives (at most 100 Hz while the arm moves):
#: a full channel would hold up Zenoh's thread
JOINT_STATES_KEPT = 100_000


class ControllerSim:
    """A stand-in controller (``python -m <module> ... --control 127.0.0.1:0``) as a process,
    asked for its status on its JSON-lines control channel (address in its ready line)."""

    def __init__(self, module: str, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", module, *args, "--control", "127.0.0.1:0"],
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        assert self.proc.stdout is not None
        ready = self.proc.stdout.readline()  # "<name> ready: ... control HOST:PORT ..."
        host, port = ready.split("control ", 1)[1].split(",", 1)[0].strip().rsplit(":", 1)
        self.control = socket.create_connection((host, int(port)), timeout=10).makefile("rwb")

    def status(self) -> dict[str, Any]:
        self.control.write(b'{"cmd": "status"}\n')
        self.control.flush()
        reply: dict[str, Any] = json.loads(self.control.readline())
        return reply

    def close(self) -> None:
        self.control.close()
        self.proc.terminate()
        self.proc.wait(10)


def paced(client: Client, lines: Sequence[str], expect: str | None = None) -> tuple[list[float], float]:
    """Send ``lines`` one a period, each after the reply to the last, as a send-and-wait Alter
    client streams: the round trips (s) and the time it all took. ``expect``: the one reply
    each line must get (RuntimeError otherwise).

    The period is ``ALTER_PERIOD_S`` stretched by one part in ``len(lines)``: as if the
    client's clock ran that much slower than the robot's, so the lines meet every phase of
    the robot's cycle once. With the client and the driver on one clock at exactly one
    cycle a line, a run would meet one phase throughout, and a target's time depends on
    it: measured, p50 1.18-1.34 ms when the target reaches the driver between its cycles,
    1.96-2.00 when it arrives as the next cycle runs (p99 4.3-5.4 and 8.8; docs/PERFORMANCE.md).
    """
    rtts = []
    period = ALTER_PERIOD_S * (1 + 1 / max(len(lines), 1))
    start = time.perf_counter()
    for k, line in enumerate(lines):
        sent = time.perf_counter()
        client.send(line)
        reply = client.read_lines(1)
        rtts.append(time.perf_counter() - sent)
        if expect is not None and reply != expect:
            raise RuntimeError(f"{line.strip()!r} answered {reply!r}, not {expect!r}")
        delay = start + (k + 1) * period - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return rtts, time.perf_counter() - start


def paced_floor(seconds: float) -> tuple[float, float]:
    """The floor of an Alter target, p50 / p99 ms: a line over TCP answered after one bare
    Zenoh query between two processes (``bench.bare_zenoh relay`` and ``queryable``, linked
    directly as the gateway and the driver are), sent as the stream sends (``paced``)."""
    with bare_relay() as (relay_port, _), Client(relay_port, handshake=False) as client:
        deadline = time.monotonic() + REACH_S
        while client.ask("reached?") != "pong\n":  # the two peers link a moment after they open
            if time.monotonic() > deadline:
                raise RuntimeError(f"the bare queryable did not answer the relay within {REACH_S:.0f} s")
            time.sleep(0.05)
        paced(client, ["warm-up\n"] * 250, "pong\n")
        rtts, _ = paced(client, ["MoveRTJoints\n"] * int(seconds / ALTER_PERIOD_S), "pong\n")
    return percentiles(rtts)


def stream(link: str, seconds: float, live: bool = False, ros: bool = True) -> dict[str, Any]:
    """Stream for ``seconds``; the client's round trips and what the driver and controller
    counted. ``live``: with the live view on and a Foxglove viewer subscribed to every channel.
    ``ros``: with the ROS 2 service on (ROB6_ROS) and a subscriber of its joint_states."""
    udp = free_port(socket.SOCK_DGRAM)
    extra = {"ROB6_LINK": link, "ROB6_RSI_LISTEN": f"127.0.0.1:{udp}"} if link == "rsi" else {}
    extra["ROB6_ROS"] = "1" if ros else "0"
    joint_states = [0]
    live_port = free_port() if live else 0
    extra["ROB6_LIVE_PORT"] = str(live_port)
    kuka = viewer = None
    with tempfile.TemporaryDirectory() as logs, \
            running("kr16rt", dummy=False, log_dir=logs, extra_env=extra) as system:
        bus = system.bus("bench")
        ros_subscriber = None
        try:
            bus.wait_for(["driver"], 10)
            if ros:  # a ROS 2 subscriber of joint_states: its messages wait in Zenoh's channel,
                # counted at the end, so no Python of this process (the client's) runs for them
                # while the client measures
                ros_subscriber = bus.session.declare_subscriber(
                    "0/joint_states/**", zenoh.handlers.FifoChannel(JOINT_STATES_KEPT))
            if link == "rsi":  # the stand-in runs deploy/kuka as installed on a KSS 8.6 (RSI 4.1)
                program, sensor = install(Path(logs) / "kr-c4", "8.6", "kr16rt")
                kuka = ControllerSim("kuka_rsi_sim", "--program", str(program), "--sensor-interface", str(sensor),
                                     "--kss", "8.6", "--robot", "kr16rt", "--rob6", f"127.0.0.1:{udp}",
                                     "--timeout", str(SYSTEM_TIMEOUT),
                                     "--start-pose", START.replace(" ", ","))
                while bus.request("driver", "link", LinkQuery()).state != "connected":
                    time.sleep(0.05)
            with system.client() as client:
                client.ask("MovePTPJoints " + START, timeout=60)
                assert client.ask("EnableAlter") == "true\n"
                if live:
                    viewer = Viewer(f"ws://127.0.0.1:{live_port}")
                    viewer.subscribe_all()
                before = bus.request("driver", "state", Empty())
                controller_before = kuka.status() if kuka else None
                bus.request("driver", "link", LinkQuery(reset=True))
                n = int(seconds / ALTER_PERIOD_S)
                rtts, elapsed = paced(client, [
                    "MoveRTJoints %f -80 100 0 30 0\n" % (5.0 * np.sin(2 * np.pi * 0.2 * k * ALTER_PERIOD_S))
                    for k in range(n)], "true\n")
                after = bus.request("driver", "state", Empty())
                status = bus.request("driver", "link", LinkQuery())
                controller = kuka.status() if kuka else None
                client.ask("DisableAlter", timeout=10)
        finally:
            if ros_subscriber is not None:
                while ros_subscriber.try_recv() is not None:
                    joint_states[0] += 1
                ros_subscriber.undeclare()
            bus.close()
            if kuka:
                kuka.close()
            received = viewer.close() if viewer is not None else 0
    result = {"n": n, "rate": n / elapsed, "cycles": after.cycle - before.cycle,
              "missed": after.missed - before.missed, "rtt": percentiles(rtts), "latency_us": status.latency_us,
              "realtime": status.realtime, "viewer_received": received, "joint_states": joint_states[0]}
    if controller and controller_before:
        result.update(late=controller["late_total"] - controller_before["late_total"],
                      trips=len(controller["trips"]), controller_rtt=controller["rtt_ms"])
    return result


def streamed_points_run(robot: str, extra_env: dict[str, str], sim: ControllerSim, what: str,
                        start: list[float], ptp: Sequence[list[float]], alter: str, seconds: float,
                        lin_y_mm: float | None = None) -> tuple[dict[str, Any], dict[str, Any], LinkStatus, list[float]]:
    """A link that streams points (Adept, Kawasaki) against its controller simulator ``sim``
    (closed at the end): wait for ``what`` to come up at ``start``, PTP to each of ``ptp``,
    a LIN ``lin_y_mm`` along y and back to ``start`` (when given), then ``alter`` and
    MoveRTJoints every 16 ms for ``seconds``. The controller's status before and after,
    the link's status (latencies since the PTP moves began) and the moves' durations."""
    try:
        with tempfile.TemporaryDirectory() as logs, \
                running(robot, dummy=False, log_dir=logs, extra_env=extra_env) as system:
            bus = system.bus("bench")
            try:
                bus.wait_for(["driver"], 10)
                with system.client() as client:
                    home = " ".join(map(str, start))
                    deadline = time.monotonic() + 30
                    while client.ask("MovePTPJoints " + home, lines=1, timeout=60) != "true\n":
                        client.read_lines(1, timeout=1)  # the "false" after the ERROR line
                        assert time.monotonic() < deadline, f"{what} did not come up"
                        time.sleep(0.2)
                    before = sim.status()
                    bus.request("driver", "link", LinkQuery(reset=True))
                    moves: list[float] = []
                    for target in ptp:
                        began = time.perf_counter()
                        assert client.ask("MovePTPJoints " + " ".join(map(str, target)), timeout=60) == "true\n"
                        moves.append(time.perf_counter() - began)
                    if lin_y_mm is not None:
                        pose = [float(x) for x in client.ask("GetPositionHomRowWise").split()]
                        pose[7] += lin_y_mm
                        assert client.ask("EnableLin") == "true\n"
                        began = time.perf_counter()
                        assert client.ask("MoveLINHomRowWise " + " ".join(f"{x:f}" for x in pose),
                                          timeout=60) == "true\n"
                        moves.append(time.perf_counter() - began)
                        assert client.ask("DisableLin") == "true\n"
                        assert client.ask("MovePTPJoints " + home, timeout=60) == "true\n"
                    assert client.ask(alter) == "true\n"
                    period, n = 0.016, int(seconds / 0.016)
                    began = time.perf_counter()
                    for k in range(n):
                        q = list(start)
                        q[0] = 10.0 * np.sin(2 * np.pi * 0.2 * k * period)
                        client.send("MoveRTJoints " + " ".join(f"{x:f}" for x in q) + "\n")
                        client.read_lines(1)
                        delay = began + (k + 1) * period - time.perf_counter()
                        if delay > 0:
                            time.sleep(delay)
                    time.sleep(0.5)
                    assert client.ask("DisableAlter", timeout=10) == "true\n"
                    link: LinkStatus = bus.request("driver", "link", LinkQuery())
                    after = sim.status()
            finally:
                bus.close()
    finally:
        sim.close()
    return before, after, link, moves


#: how long the Alter floor is measured (3,750 lines)
FLOOR_S = 15.0


def links_table(seconds: float, table: Table) -> None:
    floor = paced_floor(FLOOR_S)
    sim, rsi = stream("sim", seconds), stream("rsi", seconds)
    p50s, p99s = sim["rtt"]
    p50r, p99r = rsi["rtt"]
    lat = rsi["latency_us"] or [float("nan")] * 3
    crtt = rsi["controller_rtt"]
    table(f"Alter streaming: MoveRTJoints at 250 Hz for {seconds:.0f} s on kr16rt (4 ms cycle), recorder on",
          ("measure", "--link sim", "--link rsi (kuka-rsi-sim, UDP)", "goal"), [
              ("commands sent / achieved rate", f"{sim['n']} / {sim['rate']:.1f} Hz",
               f"{rsi['n']} / {rsi['rate']:.1f} Hz", "250 Hz"),
              ("driver cycles run / missed", f"{sim['cycles']} / {sim['missed']}",
               f"{rsi['cycles']} / {rsi['missed']}", "missed 0"),
              ("late packets counted by the controller (shipped Timeout: 100 a run) / RSI stops", "-",
               f"{rsi['late']} / {rsi['trips']}", "0 / 0"),
              ("packet in -> answer out (driver) p50 / p99 / max, ms", "-",
               f"{lat[0] / 1000:.3f} / {lat[1] / 1000:.3f} / {lat[2] / 1000:.3f}"
               f"{'' if rsi['realtime'] else ' (no RT priority)'}", "p99 <= 1, max < 4"),
              ("packet out -> answer in (controller) p50 / p99 / max, ms", "-",
               f"{crtt['p50']} / {crtt['p99']} / {crtt['max']}", ""),
              ("command -> target in the driver p50 / p99, ms", f"{p50s:.3f} / {p99s:.3f}",
               f"{p50r:.3f} / {p99r:.3f}", "p99 <= 4 (one cycle); issue 25: p99 <= 1"),
              (f"floor: a line over TCP + one bare Zenoh query, sent the same way ({FLOOR_S:.0f} s) p50 / p99, ms",
               "%.3f / %.3f" % floor, "%.3f / %.3f" % floor, ""),
              ("command -> target / floor, p50 / p99", f"{p50s / floor[0]:.2f}x / {p99s / floor[1]:.2f}x",
               f"{p50r / floor[0]:.2f}x / {p99r / floor[1]:.2f}x", ""),
          ])


def live_realtime_table(seconds: float, table: Table) -> None:
    """The live view's cost on the real-time path: the RSI Alter stream with it off, then on
    with a Foxglove viewer (a process of its own) subscribed to every channel."""
    off, on = stream("rsi", seconds), stream("rsi", seconds, live=True)

    def row(r: dict[str, Any]) -> tuple[str, ...]:
        lat = r["latency_us"] or [float("nan")] * 3
        return (f"{r['late']} / {r['trips']}", f"{r['cycles']} / {r['missed']}",
                f"{lat[1] / 1000:.3f} / {lat[2] / 1000:.3f}", "%.3f / %.3f" % r["rtt"],
                f"{r['viewer_received']:,}")
    table(f"Live view cost on the real-time path: MoveRTJoints at 250 Hz for {seconds:.0f} s, kr16rt over RSI",
          ("live view", "late packets / RSI stops", "driver cycles / missed", "packet in -> answer out p99 / max, ms",
           "command -> target p50 / p99, ms", "messages the viewer received"),
          [("off", *row(off)), ("on, every channel watched", *row(on))])


def ros_realtime_table(seconds: float, table: Table) -> None:
    """The ROS 2 service's cost on the real-time path: the RSI Alter stream with ROB6_ROS=0,
    then with it on and a subscriber of /joint_states."""
    off, on = stream("rsi", seconds, ros=False), stream("rsi", seconds, ros=True)

    def row(r: dict[str, Any]) -> tuple[str, ...]:
        lat = r["latency_us"] or [float("nan")] * 3
        return (f"{r['late']} / {r['trips']}", f"{r['cycles']} / {r['missed']}",
                f"{lat[1] / 1000:.3f} / {lat[2] / 1000:.3f}", "%.3f / %.3f" % r["rtt"], f"{r['joint_states']:,}")
    table(f"ROS 2 service cost on the real-time path: MoveRTJoints at 250 Hz for {seconds:.0f} s, kr16rt over RSI",
          ("ROB6_ROS", "late packets / RSI stops", "driver cycles / missed", "packet in -> answer out p99 / max, ms",
           "command -> target p50 / p99, ms", "joint_states received"),
          [("0", *row(off)), ("1, joint_states subscribed", *row(on))])
