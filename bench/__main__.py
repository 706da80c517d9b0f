"""Run every benchmark and print the tables (``make bench``).

Each figure stands next to a baseline measured in the same run (a bare asyncio TCP
echo, Pinocchio's numeric IK, one replica), so it means something on a noisy machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from rob6.bus import Bus
from rob6.config import BusSettings
from rob6.messages import IkBatchRequest
from rob6.testing import running

from .latency import echo_baseline, measure, percentiles
from .links import links_table

COUNT = int(os.environ.get("ROB6_BENCH_COUNT", "3000"))


def table(title: str, header: tuple[str, ...], rows: list[tuple]) -> None:
    print(f"\n{title}\n")
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows, strict=True)]
    print("| " + " | ".join(str(h).ljust(w) for h, w in zip(header, widths, strict=True)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for row in rows:
        print("| " + " | ".join(str(x).ljust(w) for x, w in zip(row, widths, strict=True)) + " |")


def latency_row(name: str, samples: list[float], target: str) -> tuple:
    p50, p99 = percentiles(samples)
    return (name, f"{p50:.3f}", f"{p99:.3f}", target)


def gateway_latency(services: tuple[str, ...] = (), log_dir: str | None = None) -> dict[str, list[float]]:
    results = {}
    with running("kr16", dummy=True, services=services, log_dir=log_dir) as system:
        with system.client() as client:
            results["CM_PING"] = measure(client, "CM_PING", 1, COUNT)
            results["GetPositionJoints"] = measure(client, "GetPositionJoints", 1, COUNT)
            results["PingRobot"] = measure(client, "PingRobot 1 0", 1, COUNT)
            results["ForwardCalc"] = measure(client, "ForwardCalc 10 -20 30 40 50 60", 2, COUNT)
    return results


def gateway_tables() -> None:
    echo = echo_baseline(COUNT)
    with tempfile.TemporaryDirectory() as logs:
        on = gateway_latency(log_dir=logs)
    off = gateway_latency(services=("driver", "kinematics", "planner", "gripper", "gateway"))
    table(f"Gateway round trips, ms ({COUNT} requests each, one client, TCP_NODELAY, recording on)",
          ("request", "p50", "p99", "target"), [
              latency_row("bare asyncio TCP echo (baseline)", echo, "floor"),
              latency_row("CM_PING (gateway only)", on["CM_PING"], "p50<=0.15 p99<=0.5"),
              latency_row("GetPositionJoints (live state in gateway)", on["GetPositionJoints"], "p50<=0.6"),
              latency_row("PingRobot 1 0 (one bus round trip, driver)", on["PingRobot"], "p50<=0.6 p99<=2"),
              latency_row("ForwardCalc (bus to kinematics, 2 lines)", on["ForwardCalc"], "p50<=0.6"),
          ])
    rows = []
    for name in on:
        p50_on, _ = percentiles(on[name])
        p50_off, _ = percentiles(off[name])
        rows.append((name, f"{p50_off:.3f}", f"{p50_on:.3f}", f"{(p50_on / p50_off - 1) * 100:+.1f} %"))
    table("Recording overhead (p50 ms, recorder service off vs on, same run)",
          ("request", "off", "on", "overhead (target <= 10 %)"), rows)


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
        settings = BusSettings(robot="kr16", robot_id=system.robot_id,
                               connect=(f"tcp/127.0.0.1:{system.router_port}",))
        bus = Bus(settings, "bench")
        try:
            bus.wait_for(["kinematics"], 10)

            def rate() -> float:
                def worker(n):
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
    from bench.bench_recording import bench_burst, bench_replay, bench_sustained

    rows = [bench_burst(100_000, session=True), bench_sustained(50_000, 2.0, session=True)]
    replay = bench_replay(2000)
    table("Recording (MCAP, zstd chunks, session + system file)",
          ("case", "msgs/s (target >= 50,000)", "dropped", "max backlog"),
          [(r["case"], f"{r['msgs_per_s']:,.0f}", r["dropped"], r["max_backlog"]) for r in rows]
          + [(replay["case"], f"{replay['lines_per_s']:,.0f} lines/s", "-", "-")])


def main() -> int:
    gateway_tables()
    kinematics_tables()
    planner_table()
    links_table(float(os.environ.get("ROB6_BENCH_ALTER_S", "60")), table)
    recording_table()
    return 0


if __name__ == "__main__":
    sys.exit(main())
