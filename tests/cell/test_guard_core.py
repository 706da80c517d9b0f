"""The driver's motion core with a cell, in fast-forward: whatever is streamed, the tool never enters a zone.

The states are the core's own setpoints, cycle by cycle, as the link would command them;
the tool's height comes from the closed-form kinematics (``zone_rig``), not from the guard's
Pinocchio model.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from rob6.cell import load_cell
from rob6.robots import get_robot
from rob6_driver.motion import MotionCore
from rob6_driver.zones import ZoneGuard, ZoneReason
from tests.cell.zone_rig import HOVER_S, rig

ROBOTS = ("kr16", "kr3", "ad850", "kaw_fs")


def _core(robot: str, tmp: Path, speed_scale: float = 1.0) -> tuple[MotionCore, list[dict[str, object]]]:
    r = rig(robot)
    events: list[dict[str, object]] = []
    core = MotionCore(robot, q0=r.q(HOVER_S), zones=ZoneGuard(get_robot(robot), load_cell(r.write(tmp))),
                      on_event=events.append)
    limits = core.limits()
    core.set_limits(max_speed=(limits.vmax * 0.012 * speed_scale).tolist())
    return core, events


def _stream(core: MotionCore, start: list[float], end: list[float], seconds: float) -> tuple[np.ndarray, list[str]]:
    """Targets from ``start`` to ``end`` over ``seconds``, one per cycle, then hold; the
    states of every cycle and the reasons of refused targets."""
    assert core.enable_alter(synchronized=True)[0]
    cycles = int(seconds / core.dt)
    states, refused = [], []
    for k in range(cycles + int(3.0 / core.dt)):
        f = min(1.0, (k + 1) / cycles)
        ok, why = core.set_target([a + f * (b - a) for a, b in zip(start, end, strict=True)], True)
        if not ok:
            refused.append(why)
        states.append(core.step().q)
    return np.array(states), refused


@pytest.mark.parametrize("robot", ROBOTS)
def test_an_alter_stream_aimed_50_mm_into_the_table_stops_with_the_tool_outside(robot: str, tmp_path: Path) -> None:
    r = rig(robot)
    core, _ = _core(robot, tmp_path)
    states, refused = _stream(core, r.q(HOVER_S), r.q(r.s_at(-50.0)), 2.0)
    clearance = r.tip_clearance(states)
    print(f"{robot}: closest {clearance.min():.1f} mm above the table, at rest {clearance[-1]:.1f} mm; "
          f"{len(refused)} targets refused, the first: {refused[0]}")
    assert clearance.min() > 0.0  # outside at every setpoint
    assert clearance[-1] == pytest.approx(clearance[-50:].min())  # at rest there
    # the guard's stop and then the targets within the margin were refused, each saying why
    assert refused and all(isinstance(why, ZoneReason) and "tool tip" in why and "'table'" in why for why in refused)
    assert any(why.startswith("target refused: tool tip") for why in refused)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(robot=st.sampled_from(ROBOTS), speed=st.floats(0.2, 10.0), depth=st.floats(-120.0, 30.0),
       seconds=st.floats(0.2, 3.0))
def test_whatever_the_speed_and_the_aim_the_tool_stays_out(robot: str, speed: float, depth: float, seconds: float,
                                                           tmp_path: Path) -> None:
    r = rig(robot)
    core, _ = _core(robot, tmp_path, speed)
    states, _ = _stream(core, r.q(HOVER_S), r.q(r.s_at(depth)), seconds)
    assert r.tip_clearance(states).min() > 0.0


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_trajectory_into_the_table_stops_before_it_whatever_the_planner_sent(robot: str, tmp_path: Path) -> None:
    """The driver does not rely on the planner: a trajectory straight into the table (sampled
    here, never checked) is stopped on its ramp, outside, and its end says why."""
    r = rig(robot)
    core, _ = _core(robot, tmp_path)
    start, end = np.array(r.q(HOVER_S)), np.array(r.q(r.s_at(-50.0)))
    n = 400
    f = (1 - np.cos(np.linspace(0, np.pi, n))) / 2  # a smooth rest-to-rest ramp
    motion = core.execute(start + f[:, None] * (end - start), core.dt, check=False)
    states = [s.q for s in core.run_until_idle()]
    assert motion.done.is_set() and not motion.ok
    assert isinstance(motion.reason, ZoneReason) and "'table'" in motion.reason
    assert r.tip_clearance(np.array(states)).min() > 0.0


@pytest.mark.parametrize("robot", ROBOTS)
def test_a_trajectory_whose_poses_enter_the_table_never_starts(robot: str, tmp_path: Path) -> None:
    r = rig(robot)
    core, _ = _core(robot, tmp_path)
    start, end = np.array(r.q(HOVER_S)), np.array(r.q(r.s_at(-50.0)))
    f = (1 - np.cos(np.linspace(0, np.pi, 400))) / 2
    motion = core.execute(start + f[:, None] * (end - start), core.dt)
    assert motion.done.is_set() and not motion.ok
    assert isinstance(motion.reason, ZoneReason)
    assert re.match(r"^trajectory refused: at \d+\.\d\d s tool tip \d+ mm (inside|from) keep-out 'table'", motion.reason)
    assert core.state().q.tolist() == start.tolist()
