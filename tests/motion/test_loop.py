"""Real-time cycle runner (short wall-clock runs) and the planner benchmark functions."""

import threading
import time

from rob6_driver.loop import CycleRunner
from rob6_driver.motion import CoreState, MotionCore
from rob6_planner.bench import bench_ptp


def test_runner_publishes_every_cycle_on_time() -> None:
    sim = MotionCore("kr16rt")  # 4 ms
    published: list[CoreState] = []
    runner = CycleRunner(sim.step, sim.dt, published.append)
    t0 = time.monotonic()
    runner.start()
    time.sleep(0.3)
    runner.stop()
    elapsed = time.monotonic() - t0
    assert not runner.running
    n = runner.stats.cycles
    assert n == len(published)
    assert [s.cycle for s in published] == list(range(1, n + 1))
    # monotonic deadlines: no drift (skipped ticks are counted)
    assert abs(n + runner.stats.missed - elapsed / sim.dt) <= 10
    assert runner.stats.errors == 0


def test_runner_counts_missed_cycles_and_survives_errors() -> None:
    calls = []

    def step() -> int:
        calls.append(time.monotonic())
        if len(calls) == 3:
            time.sleep(0.035)  # overruns ~3 periods of 10 ms
        if len(calls) == 5:
            raise RuntimeError("boom")
        return len(calls)

    runner = CycleRunner(step, 0.010)
    runner.start()
    time.sleep(0.15)
    runner.stop()
    assert runner.stats.missed >= 2
    assert runner.stats.errors == 1
    assert runner.stats.cycles >= 8


def test_trajectory_completion_is_awaitable_in_real_time() -> None:
    from rob6_planner.config import MotionSettings
    from rob6_planner.trajectory import TrajectoryPlanner

    sim = MotionCore("kr16rt")
    tr = TrajectoryPlanner("kr16rt").plan_ptp(sim.state().q, [2, 0, 0, 0, 0, 0],
                                              MotionSettings("kr16rt")).trajectory
    assert tr is not None
    done = threading.Event()
    with CycleRunner(sim.step, sim.dt):
        motion = sim.execute(tr.q, tr.dt, tr.qd, tr.qdd)
        motion.add_done_callback(lambda m: done.set())
        assert motion.wait(tr.duration + 1.0)
    assert motion.ok and done.is_set()
    assert motion.final is not None and motion.final.q[0] == 2.0


def test_bench_functions() -> None:
    r = bench_ptp("kr16", n=50, warmup=5)
    assert r["p50_us"] > 0 and r["p99_us"] >= r["p50_us"]
    r = bench_ptp("kr16rt", n=50, warmup=5, sample=False)
    assert r["p50_us"] < 5000
