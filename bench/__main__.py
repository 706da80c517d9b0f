"""Run every benchmark and print the tables (``make bench``).

Each figure stands next to a baseline measured in the same run (a bare TCP echo, a bare
Zenoh query, Pinocchio's numeric IK, one replica), so it means something on a noisy machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from harness.client import Client
from harness.system import running
from rob6.messages import IkBatchRequest

from .adept import adept_table
from .background import background_table
from .busy import busy_table
from .kawasaki import kawasaki_simclock_table, kawasaki_table
from .latency import cpu_seconds, echo_baseline, measure, measure_beside, percentiles, usage, zenoh_baselines
from .links import links_table, live_realtime_table, ros_realtime_table
from .tables import table
from .transport import transport_table
from .zones import zones_table

COUNT = int(os.environ.get("ROB6_BENCH_COUNT", "3000"))


# (command, reply lines, kind): "gateway" answered by the gateway alone, "mirror" from
# state the owning service publishes, "bus" one round trip to a service
COMMANDS = (
    ("CM_PING", 1, "gateway"),
    ("IsKuka", 1, "gateway"),
    ("GetPositionJoints", 1, "mirror"),
    ("GetStatus", 1, "mirror"),
    ("GetJointsMaxSpeed", 1, "mirror"),
    ("GetAllowedStatus", 1, "mirror"),
    ("PingRobot 1 0", 1, "bus"),
    ("ForwardCalc 10 -20 30 40 50 60", 2, "bus"),
    ("BackwardCalc", 1, "bus"),  # the pose ForwardCalc gave, and its status
    ("MoveRTJoints", 1, "bus"),  # Alter mode on, a joint target 0.01 deg away each time
    ("MovePTPJoints", 1, "motion"),  # two hops (gateway -> planner -> driver), instantaneous motion
)
#: the floor of a command that crosses the bus once: a TCP round trip and a Zenoh one
BUS_GOAL = 1.5
#: a motion start crosses it twice and plans (about 1 ms of Ruckig and validation)
MOTION_GOAL, PLANNING_MS = 2.0, 1.0
#: the original rob6server's CM_PING p50 on this machine (docs/PERFORMANCE.md: 0.131-0.139)
ORIGINAL_PING_MS = 0.131
GOALS = {"gateway": f"p50 <= original ({ORIGINAL_PING_MS} ms)", "mirror": "p50 <= 1.5x CM_PING",
         "bus": f"p50 and p99 <= {BUS_GOAL}x floor", "motion": f"p50 <= {MOTION_GOAL}x floor + {PLANNING_MS} ms"}


def gateway_latency(services: tuple[str, ...] = (), log_dir: str | None = None,
                    zenoh_floor: bool = False) -> tuple[dict[str, list[float]], dict[str, dict[str, float]]]:
    """Each command's round trips, and the CPU time each process of the system used per
    request while they ran (command -> process -> us)."""
    results = {}
    cpu: dict[str, dict[str, float]] = {}
    with running("kr16", dummy=True, services=services, log_dir=log_dir) as system:
        if zenoh_floor:
            for receive, samples in zenoh_baselines(system.router_port, COUNT).items():
                results[f"bare Zenoh query, {receive}"] = samples
        pids = system.pids()
        with system.client() as client:
            pose = client.ask("ForwardCalc 10 -20 30 40 50 60", 2).replace("\n", " ")
            for command, lines, kind in COMMANDS:
                name = command.split()[0]
                before = {process: cpu_seconds(pid) for process, pid in pids.items()}
                if command == "MoveRTJoints":
                    assert client.ask("EnableAlter") == "true\n"
                    results[name] = measure_alternating(
                        client, ("MoveRTJoints 0.00 0 0 0 0 0\n", "MoveRTJoints 0.01 0 0 0 0 0\n"), COUNT)
                    client.ask("DisableAlter", timeout=10)
                elif command == "MovePTPJoints":
                    results[name] = measure_alternating(
                        client, ("MovePTPJoints 10 -60 80 20 40 30\n", "MovePTPJoints 11 -60 80 20 40 30\n"), COUNT)
                elif kind in ("gateway", "mirror") and name != "CM_PING":  # measured in turn with CM_PING
                    results[name], results[f"CM_PING beside {name}"] = measure_beside(client, command, lines, COUNT)
                else:
                    request = f"BackwardCalc {pose}" if command == "BackwardCalc" else command
                    results[name] = measure(client, request, lines, COUNT)
                requests = len(results[name]) + len(results.get(f"CM_PING beside {name}", ()))
                cpu[name] = {process: (cpu_seconds(pid) - before[process]) / requests * 1e6
                             for process, pid in pids.items()}
    return results, cpu


def measure_alternating(client: Client, lines: tuple[str, str], count: int, warmup: int = 200) -> list[float]:
    """A command that must answer ``true``, sent with two arguments in turn (a target 0.01 deg
    from the last for MoveRTJoints, between two poses for MovePTPJoints on the dummy kr16,
    whose motion takes no time)."""
    samples = []
    for k in range(count + warmup):
        line = lines[k % 2]
        start = time.perf_counter()
        client.send(line)
        reply = client.read_lines(1)
        if k >= warmup:
            samples.append(time.perf_counter() - start)
        if reply != "true\n":
            raise RuntimeError(f"{line.strip()}: {reply!r}")
    return samples


def gateway_tables() -> None:
    echo = echo_baseline(COUNT)
    with tempfile.TemporaryDirectory() as logs:
        on, cpu = gateway_latency(log_dir=logs, zenoh_floor=True)
    off, _ = gateway_latency(services=("driver", "kinematics", "planner", "gripper", "gateway"))
    ping50, _ = percentiles(on["CM_PING"])
    echo50, echo99 = percentiles(echo)
    zenoh50, zenoh99 = percentiles(on["bare Zenoh query, blocking"])
    floor50, floor99 = echo50 + zenoh50, echo99 + zenoh99  # one bus crossing
    recorded50, recorded99 = percentiles(on["bare Zenoh query, recorded"])
    rfloor50, rfloor99 = echo50 + recorded50, echo99 + recorded99  # one recorded bus crossing
    blank = ("",) * 5
    rows = [("bare TCP echo, blocking (floor)", *fmt_ms(echo), *blank),
            ("bare Zenoh query, blocking receive (floor)", *fmt_ms(on["bare Zenoh query, blocking"]), *blank),
            ("bare Zenoh query, awaited on asyncio", *fmt_ms(on["bare Zenoh query, asyncio"]), *blank),
            ("bare Zenoh query, both ends recording it (recorded floor)", f"{recorded50:.3f}", f"{recorded99:.3f}",
             *blank),
            ("floor of a bus crossing: TCP echo + blocking Zenoh", f"{floor50:.3f}", f"{floor99:.3f}", *blank),
            ("floor of a recorded bus crossing: TCP echo + recorded Zenoh", f"{rfloor50:.3f}", f"{rfloor99:.3f}",
             *blank)]
    for command, _, kind in COMMANDS:
        name = command.split()[0]
        p50, p99 = percentiles(on[name])
        recorded = ""
        if kind in ("bus", "motion"):
            ratios = (f"{p50 / floor50:.2f}x", f"{p99 / floor99:.2f}x")
            recorded = f"{p50 / rfloor50:.2f}x / {p99 / rfloor99:.2f}x"
            met = (p50 <= BUS_GOAL * floor50 and p99 <= BUS_GOAL * floor99) if kind == "bus" else (
                p50 <= MOTION_GOAL * floor50 + PLANNING_MS)
        else:
            beside50, _ = percentiles(on[f"CM_PING beside {name}"]) if name != "CM_PING" else (ping50, 0.0)
            ratios = (f"{p50 / beside50:.2f}x CM_PING", "")
            met = p50 <= 1.5 * beside50 if kind == "mirror" else p50 <= ORIGINAL_PING_MS
        rows.append((f"{name} ({kind})", f"{p50:.3f}", f"{p99:.3f}", *ratios, recorded, GOALS[kind],
                     "met" if met else "NOT MET"))
    table(f"Gateway round trips, ms ({COUNT} requests each, one client, kr16 dummy, recording on)",
          ("request", "p50", "p99", "p50 / floor", "p99 / floor", "p50 / p99 to the recorded floor",
           "goal", ""), rows)
    bare_off, bare_on = percentiles(on["bare Zenoh query, blocking"]), percentiles(on["bare Zenoh query, recorded"])
    overhead = [("bare Zenoh query (the floor of recording)", f"{bare_off[0]:.3f} / {bare_off[1]:.3f}",
                 f"{bare_on[0]:.3f} / {bare_on[1]:.3f}", f"{(bare_on[0] / bare_off[0] - 1) * 100:+.1f} %",
                 f"{(bare_on[1] / bare_off[1] - 1) * 100:+.1f} %")]
    for name in on:
        if name in off and not name.startswith("CM_PING beside"):
            p50_on, p99_on = percentiles(on[name])
            p50_off, p99_off = percentiles(off[name])
            overhead.append((name, f"{p50_off:.3f} / {p99_off:.3f}", f"{p50_on:.3f} / {p99_on:.3f}",
                             f"{(p50_on / p50_off - 1) * 100:+.1f} %", f"{(p99_on / p99_off - 1) * 100:+.1f} %"))
    table("Recording overhead (p50 / p99 ms, recorder and ROS node off vs on, same run)",
          ("request", "off", "on", "p50 overhead (goal <= 10 %)", "p99 overhead"), overhead)
    processes = sorted({process for per in cpu.values() for process in per},
                       key=lambda process: -sum(per.get(process, 0.0) for per in cpu.values()))
    table("CPU per request by process (us; the round trips above, recording on; /proc, 10 ms steps)",
          ("request", *processes, "all"),
          [(name, *(f"{per.get(process, 0.0):.0f}" for process in processes), f"{sum(per.values()):.0f}")
           for name, per in cpu.items()])


def fmt_ms(samples: list[float]) -> tuple[str, str]:
    p50, p99 = percentiles(samples)
    return f"{p50:.3f}", f"{p99:.3f}"


def idle_table(seconds: float = 10.0) -> None:
    rows = []
    for robot, dummy in (("kr16", True), ("kr16rt", False)):
        with tempfile.TemporaryDirectory() as logs, running(robot, dummy=dummy, log_dir=logs) as system:
            time.sleep(2.0)  # past start-up
            pids = [system.process.pid, *system.pids().values()]
            cpu, rss, pss = usage(pids, seconds)
        rows.append((f"{robot} ({'dummy' if dummy else 'real time, simulated robot'})", len(pids),
                     f"{cpu * 100:.1f} %", f"{pss:.0f}", f"{rss:.0f}"))
    table(f"The whole system idle ({seconds:.0f} s, recorder on): CPU and memory",
          ("robot", "processes", "CPU, share of one core (goal <= 10 %)", "memory (PSS sum), MB (goal <= 400)",
           "RSS sum, MB (shared pages once per process)"), rows)


def kinematics_tables() -> None:
    from rob6_kinematics.bench import bench_ik
    rows = []
    for robot in ("kr16", "ad850"):
        r = bench_ik(robot, n_batch=20000, n_single=1000, n_clik=40)
        rows.append((robot, f"{r['batch_ik_poses_per_s']:,.0f}", f"{r['single_ik_poses_per_s']:,.0f}",
                     f"{r['clik_poses_per_s']:,.0f}",
                     f"{r['single_ik_poses_per_s'] / r['clik_poses_per_s']:,.0f}x"))
    table("Closed-form IK (all 8 branches) vs Pinocchio CLIK, poses/s, one core",
          ("robot", "batch (target >= 50,000)", "single call", "CLIK (baseline)", "single/CLIK (target >= 100x)"),
          rows)
    one, two = replica_scaling()
    table("Kinematics replicas: ik_batch over the bus (2 concurrent callers, 2,000 poses per request)",
          ("replicas", "poses/s", "vs one replica"),
          [("1", f"{one:,.0f}", "1.00x"), ("2", f"{two:,.0f}", f"{two / one:.2f}x (target >= 1.7x)")])


def replica_scaling(requests: int = 40, poses: int = 2000) -> tuple[float, float]:
    rng = np.random.default_rng(0)
    from rob6.robots import get_robot
    from rob6_kinematics.calc import Kinematics
    T = Kinematics(get_robot("kr16")).fk(rng.uniform(-60, 60, (poses, 6)) * [1, 0.5, 0.5, 1, 1, 1])
    body = IkBatchRequest(poses=T.reshape(-1, 12).tolist())
    with running("kr16", services=("kinematics",)) as system:
        bus = system.bus("bench")
        try:
            bus.wait_for(["kinematics"], 10)

            def rate() -> float:
                def worker(n: int) -> None:
                    for _ in range(n):
                        bus.request("kinematics", "ik_batch", body, timeout=30)
                start = time.perf_counter()
                threads = [threading.Thread(target=worker, args=(requests // 2,)) for _ in range(2)]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
                return requests * poses / (time.perf_counter() - start)

            single = rate()
            env = dict(os.environ, ROB6_ROBOT="kr16", ROB6_ROBOT_ID=system.robot_id,
                       ROB6_ZENOH_CONNECT=f"tcp/127.0.0.1:{system.router_port}")
            extra = subprocess.Popen([sys.executable, "-m", "rob6_kinematics"], env=env)
            try:
                deadline = time.monotonic() + 20
                while len(bus.instances("kinematics")) < 2 and time.monotonic() < deadline:
                    time.sleep(0.05)
                double = rate()
            finally:
                extra.terminate()
                extra.wait(5)
        finally:
            bus.close()
    return single, double


def planner_table() -> None:
    from rob6_planner.bench import bench_ptp
    rows = []
    for robot in ("kr16", "kr16rt"):
        for sample in (False, True):
            r = bench_ptp(robot, 2000, sample=sample)
            rows.append((robot, "with samples" if sample else "plan only", f"{r['p50_us']:.0f}",
                         f"{r['p99_us']:.0f}"))
    table("PTP planning (validation + Ruckig), microseconds", ("robot", "what", "p50", "p99"), rows)


def recording_table() -> None:
    from bench.bench_recording import bench_burst, bench_replay, bench_sustained, bench_writers, live_table

    rows = [bench_burst(100_000, session=True), bench_sustained(50_000, 2.0, session=True)]
    replay = bench_replay(2000)
    table("Recording (MCAP, zstd chunks, session + system file)",
          ("case", "msgs/s (target >= 50,000)", "dropped", "max backlog"),
          [(r["case"], f"{r['msgs_per_s']:,.0f}", r["dropped"], r["max_backlog"]) for r in rows]
          + [(replay["case"], f"{replay['lines_per_s']:,.0f} lines/s", "-", "-")])
    table("MCAP writers alone (joint-state records, zstd), msgs/s: rob6_recorder_native is the recorder's",
          ("writer", "files open", "msgs/s", "bytes/msg"),
          [(w["writer"], w["files"], f"{w['msgs_per_s']:,.0f}", f"{w['bytes_per_msg']:.1f}")
           for w in bench_writers()])
    live_table(table)


def main() -> int:
    gateway_tables()
    background_table(COUNT, table)
    transport_table(COUNT, table)
    idle_table()
    kinematics_tables()
    planner_table()
    zones_table(table)
    alter_s = float(os.environ.get("ROB6_BENCH_ALTER_S", "60"))
    links_table(alter_s, table)
    adept_table(max(5.0, alter_s / 6), table)
    kawasaki_simclock_table(table)
    kawasaki_table(max(5.0, alter_s / 3), table)
    busy_table(float(os.environ.get("ROB6_BENCH_BUSY_S", "60")), table)
    recording_table()
    live_realtime_table(float(os.environ.get("ROB6_BENCH_ALTER_S", "60")) / 2, table)
    ros_realtime_table(float(os.environ.get("ROB6_BENCH_ALTER_S", "60")) / 2, table)
    if os.environ.get("ROB6_BENCH_MULTIHOST") == "1":  # needs Docker and root, ~7 min
        from .multihost import multihost_table
        multihost_table(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
