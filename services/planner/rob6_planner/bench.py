"""Planning-time benchmark: ``python -m rob6_planner.bench [robot] [n]``.

``bench_ptp`` plans ``n`` random PTP moves (targets uniform inside the default turn
limits, 5 % margin, from random start positions) with the default limits and returns
percentiles in microseconds. ``sample=True`` (default) includes validation and
sampling at the driver cycle, i.e. everything the planner does before handing the
trajectory to the driver; ``sample=False`` is validation + Ruckig only.
"""

from __future__ import annotations

import json
import sys
import time
from typing import TypedDict

import numpy as np

from rob6.robots import DEFAULT_ROBOT

from .config import MotionSettings
from .trajectory import TrajectoryPlanner


def _random_joints(config: MotionSettings, rng: np.random.Generator, n: int) -> np.ndarray:
    lo = np.asarray(config.turn_min, float)
    hi = np.asarray(config.turn_max, float)
    margin = 0.05 * (hi - lo)
    return rng.uniform(lo + margin, hi - margin, size=(n, 6))


class PtpBench(TypedDict):
    robot: str
    n: int
    sample: bool
    p50_us: float
    p99_us: float
    max_us: float
    mean_us: float
    mean_samples: float


def bench_ptp(robot: str = DEFAULT_ROBOT, n: int = 2000, seed: int = 0, sample: bool = True,
              warmup: int = 50) -> PtpBench:
    """PTP planning time percentiles (µs): {'p50_us', 'p99_us', 'max_us', 'mean_us', 'n', ...}."""
    config = MotionSettings(robot)
    planner = TrajectoryPlanner(robot)
    rng = np.random.default_rng(seed)
    starts = _random_joints(config, rng, n + warmup)
    targets = _random_joints(config, rng, n + warmup)
    times = np.empty(n)
    samples = 0
    for i in range(n + warmup):
        t0 = time.perf_counter()
        res = planner.plan_ptp(starts[i], targets[i], config, sample=sample)
        dt = time.perf_counter() - t0
        if not res.ok:
            raise RuntimeError(f"benchmark move refused: {res.reason}")
        if i >= warmup:
            times[i - warmup] = dt
            if res.trajectory is not None:
                samples += res.trajectory.n
    us = times * 1e6
    return {
        "robot": robot,
        "n": n,
        "sample": sample,
        "p50_us": float(np.percentile(us, 50)),
        "p99_us": float(np.percentile(us, 99)),
        "max_us": float(us.max()),
        "mean_us": float(us.mean()),
        "mean_samples": samples / n if sample else 0.0,
    }


def ptp_p50_us(robot: str = DEFAULT_ROBOT, n: int = 2000) -> float:
    return bench_ptp(robot, n)["p50_us"]


def ptp_p99_us(robot: str = DEFAULT_ROBOT, n: int = 2000) -> float:
    return bench_ptp(robot, n)["p99_us"]


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    robot = argv[0] if argv else DEFAULT_ROBOT
    n = int(argv[1]) if len(argv) > 1 else 2000
    for sample in (False, True):
        print(json.dumps(bench_ptp(robot, n, sample=sample)))


if __name__ == "__main__":
    main()
