"""Property tests: random command sequences never make the simulated robot break a limit.

Commands: PTP moves (planned with the current MotionSettings, with or without exact
derivatives), Alter on/off, Alter targets (single and streamed every cycle, valid and
invalid, just inside a turn limit), idle runs (watchdog), stops, corrupted trajectories (up-front check skipped:
the per-cycle monitor must catch them), speed/acceleration changes and turn-limit
changes at any time. Every produced state is checked against the turn, speed and
acceleration limits the monitor enforces at that cycle (finite differences of the
positions and the reported qd/qdd), with a 1e-6 relative tolerance.

``ROB6_PROPERTY_EXAMPLES`` sets the number of examples (default 150).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any, TypedDict

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st
from pytest import CaptureFixture

from rob6.robots import get_robot
from rob6_driver.motion import MotionCore
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import TrajectoryPlanner

EXAMPLES = int(os.environ.get("ROB6_PROPERTY_EXAMPLES", "150"))


class Stats(TypedDict):
    examples: int
    states: int
    state_violations: int
    reported: dict[str, int]  # "kind/source" -> count


STATS: Stats = {"examples": 0, "states": 0, "state_violations": 0, "reported": {}}
REL = 1e-6
ATOL_V = 1e-9
ATOL_A = 1e-6

unit = st.floats(0.0, 1.0, allow_nan=False)
fractions = st.lists(unit, min_size=6, max_size=6)

command = st.one_of(
    st.tuples(st.just("ptp"), fractions, st.booleans()),
    st.tuples(st.just("alter_on"), st.booleans()),
    st.tuples(st.just("target"), fractions),
    st.tuples(st.just("stream"), fractions, st.integers(1, 120)),
    st.tuples(st.just("invalid"), st.integers(0, 5), st.booleans()),
    st.tuples(st.just("run"), st.integers(1, 400)),
    st.tuples(st.just("stop")),
    st.tuples(st.just("alter_off")),
    st.tuples(st.just("speed"), fractions, st.booleans()),
    st.tuples(st.just("accel"), fractions, st.booleans()),
    st.tuples(st.just("turn"), st.integers(0, 5), unit, st.booleans()),
    st.tuples(st.just("bad"), st.integers(0, 5), st.floats(0.05, 3.0)),
    st.tuples(st.just("edge"), st.integers(0, 5), st.booleans(), st.floats(1e-6, 5.0)),
)


#: one drawn command: its kind, then that kind's own arguments (see ``command``)
Command = tuple[Any, ...]


class Harness:
    def __init__(self, robot: str):
        self.robot = get_robot(robot)
        self.config = MotionSettings(self.robot)
        self.planner = TrajectoryPlanner(self.robot)
        self.sim = MotionCore(self.robot, alter_timeout_s=0.15)
        s = self.sim.state()
        self.prev_q = s.q
        self.prev_v = np.zeros(6)
        self.states = 0
        self.problems: list[str] = []
        self.expected_violations = 0

    # -------------------------------------------------------------- helpers
    def joints(self, f: Sequence[float]) -> np.ndarray:
        lo = np.asarray(self.robot.turn_min, float)
        hi = np.asarray(self.robot.turn_max, float)
        # inside the default range, mostly the central 80 %
        q: np.ndarray = lo + (hi - lo) * (0.1 + 0.8 * np.asarray(f))
        return q

    def push_limits(self) -> None:
        c = self.config
        ok, why = self.sim.set_limits(c.turn_min, c.turn_max, c.speed, c.accel)
        assert ok, why

    def step(self, n: int) -> None:
        sim = self.sim
        for _ in range(n):
            before = sim.enforced_limits()
            s = sim.step()
            after = sim.enforced_limits()
            vmax = np.maximum(before.vmax, after.vmax)
            amax = np.maximum(before.amax, after.amax)
            lo = np.minimum(before.turn_min, after.turn_min)
            hi = np.maximum(before.turn_max, after.turn_max)
            q = s.q
            v = (q - self.prev_q) / sim.dt
            a = (v - self.prev_v) / sim.dt
            bad = []
            if (np.abs(v) > vmax * (1 + REL) + ATOL_V).any():
                bad.append(f"speed {v} > {vmax}")
            if (np.abs(a) > amax * (1 + REL) + ATOL_A).any():
                bad.append(f"acceleration {a} > {amax}")
            if (np.abs(s.qd) > vmax * (1 + REL) + ATOL_V).any():
                bad.append(f"qd {s.qd} > {vmax}")
            if (np.abs(s.qdd) > amax * (1 + REL) + ATOL_A).any():
                bad.append(f"qdd {s.qdd} > {amax}")
            p = self.prev_q
            lo_ok = np.where(p <= lo, q >= p - 1e-9, q > lo)  # outside: not further out
            hi_ok = np.where(p >= hi, q <= p + 1e-9, q < hi)
            if not (lo_ok & hi_ok).all():
                bad.append(f"turn {q} not in ({lo}, {hi})")
            if bad:
                self.problems.append(f"cycle {s.cycle} mode {s.mode}: " + "; ".join(bad))
            self.prev_q, self.prev_v = q, v
            self.states += 1

    # -------------------------------------------------------------- commands
    def do(self, cmd: Command) -> None:
        sim, c = self.sim, self.config
        kind = cmd[0]
        if kind == "ptp":
            q1, with_derivatives = self.joints(cmd[1]), cmd[2]
            res = self.planner.plan_ptp(sim.state().q, q1, c)
            if res.ok:
                tr = res.trajectory
                assert tr is not None
                extra = (tr.qd, tr.qdd) if with_derivatives else ()
                sim.execute(tr.q, tr.dt, *extra)
        elif kind == "alter_on":
            sim.enable_alter(synchronized=cmd[1])
        elif kind == "target":
            sim.set_target(self.joints(cmd[1]), synchronized=c.rt_speed_control == 0)
        elif kind == "stream":
            start = sim.state().q
            goal = self.joints(cmd[1])
            n = cmd[2]
            for k in range(n):
                sim.set_target(start + (goal - start) * (k + 1) / n)
                self.step(1)
        elif kind == "edge":
            # an Alter target just inside a turn limit (often closer than the braking distance)
            j, upper, margin = cmd[1], cmd[2], cmd[3]
            q = sim.state().q.copy()
            q[j] = c.turn_max[j] - margin if upper else c.turn_min[j] + margin
            sim.set_target(q)
        elif kind == "invalid":
            j, nan = cmd[1], cmd[2]
            q = sim.state().q.copy()
            q[j] = float("nan") if nan else c.turn_max[j] + 1.0
            assert not sim.set_target(q)[0]
        elif kind == "run":
            self.step(cmd[1])
        elif kind == "stop":
            sim.stop()
        elif kind == "alter_off":
            sim.disable_alter()
        elif kind == "speed":
            bound = np.asarray(self.robot.speed_bound)
            values = bound * 0.3 * np.asarray(cmd[1]) ** 2  # mostly slow, sometimes 0
            if cmd[2]:
                values[int(np.argmin(cmd[1]))] = 0.0
            assert c.set_speed(values.tolist())
            self.push_limits()
        elif kind == "accel":
            values = 0.02 * np.asarray(cmd[1])
            if cmd[2]:
                values[int(np.argmin(cmd[1]))] = 0.0
            assert c.set_accel(values.tolist())
            self.push_limits()
        elif kind == "turn":
            j, f, upper = cmd[1], cmd[2], cmd[3]
            lo, hi = self.robot.turn_min[j], self.robot.turn_max[j]
            value = lo + (hi - lo) * f
            (c.set_single_turn_max if upper else c.set_single_turn_min)(j + 1, value)
            self.push_limits()
        elif kind == "bad":
            # a corrupted trajectory from the current position: a step on one joint
            j, jump = cmd[1], cmd[2]
            q = sim.state().q
            arr = np.repeat(q[None], 40, axis=0)
            arr[20:, j] += jump
            m = sim.execute(arr, check=False)
            if not m.done.is_set():
                self.expected_violations += 1


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(robot=st.sampled_from(["kr16", "kr16rt", "ad850"]),
       commands=st.lists(command, min_size=1, max_size=18))
def test_random_command_sequences_never_break_a_limit(robot: str, commands: list[Command]) -> None:
    h = Harness(robot)
    for cmd in commands:
        h.do(cmd)
        h.step(3)
    h.sim.stop()
    h.step(1)
    for _ in range(20000):
        if not h.sim.state().moving:
            break
        h.step(1)
    assert not h.sim.state().moving
    STATS["examples"] += 1
    STATS["states"] += h.states
    STATS["state_violations"] += len(h.problems)
    for v in h.sim.violations:
        key = f"{v.kind}/{v.source}"
        STATS["reported"][key] = STATS["reported"].get(key, 0) + 1
    assert h.problems == [], h.problems[:3]
    # reported violations: one per corrupted trajectory, limit changes under motion;
    # the sim's own generator (Alter, stops) never needed the monitor's clamp
    violations = list(h.sim.violations)
    assert [v for v in violations if v.source in ("alter", "stop")] == []
    assert len([v for v in violations if v.source == "trajectory"]) <= h.expected_violations
    assert all(v.kind != "unavoidable" for v in violations)


def test_property_harness_sees_something() -> None:
    """Sanity: the harness really moves the robot and counts states."""
    h = Harness("kr16")
    h.do(("ptp", [0.7] * 6, True))
    h.step(50)
    assert h.states == 50 and np.abs(h.sim.state().qd).max() > 0
    h.do(("bad", 0, 2.0))
    assert h.problems == []


def test_zz_report(capsys: CaptureFixture[str]) -> None:
    with capsys.disabled():
        print("\nproperty tests:", STATS)
