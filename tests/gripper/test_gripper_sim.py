"""Physics of the simulated gripper (rob6_gripper.sim): exact, steppable, no wall clock."""

from __future__ import annotations

import math
import time

import pytest
from hypothesis import given, settings, strategies as st

from rob6_gripper.backend import GRIPPING, IDLE, MOVING, GripperStatus, VirtualClock
from rob6_gripper.sim import GripperModel, GripperParams, SimGripper
from tests.gripper.stopping import stopped_mid_move

P = GripperParams()


def current_move_time(amps: float, distance: float, p: GripperParams = P) -> float:
    """What the model implies: accelerate at a_max to v_t, then cruise (or a pure
    acceleration if the distance is shorter than the run-up)."""
    vt = p.terminal_velocity(amps)
    a = p.max_acceleration
    run_up = vt * vt / (2 * a)
    if distance <= run_up:
        return math.sqrt(2 * distance / a)
    return vt / a + (distance - run_up) / vt


def position_move_time(distance: float, p: GripperParams = P) -> float:
    a, v = p.max_acceleration, p.max_velocity
    if distance <= v * v / a:
        return 2 * math.sqrt(distance / a)
    return v / a + distance / v


# ---------------------------------------------------------------- figures
def test_documented_figures() -> None:
    assert (P.stroke_min, P.stroke_max, P.home_position) == (0.0, 0.070, 0.040)
    assert P.max_velocity == 0.082 and P.max_acceleration == 0.32
    assert P.force(5.0) == pytest.approx(200.0)  # PG 70 class maximum gripping force
    assert P.terminal_velocity(-1.0) == pytest.approx(0.032)
    assert P.terminal_velocity(5.0) == P.max_velocity  # speed limit
    assert P.breakaway_current == pytest.approx(0.2)


# ---------------------------------------------------------------- closing onto an object
def test_close_from_home_onto_30mm_object_at_minus_1A() -> None:
    m = GripperModel(object_width=0.030)
    mid = m.command_current(-1.0)
    expected = current_move_time(-1.0, 0.010)
    assert expected == pytest.approx(0.3625)  # 0.1 s run-up over 1.6 mm, 8.4 mm at 32 mm/s
    assert m.time_to_completion() == pytest.approx(expected, abs=1e-12)
    m.advance(expected - 1e-3)
    assert m.mode == MOVING and m.outcome(mid) is None and m.w > 0.030
    m.advance(2e-3)
    out = m.outcome(mid)
    assert out is not None and out.ok and out.status == "gripping"
    assert m.w == 0.030 and m.v == 0.0 and m.mode == GRIPPING
    assert m.current == -1.0 and m.force == pytest.approx(40.0)


def test_stepping_in_small_steps_matches_one_big_step() -> None:
    a = GripperModel(object_width=0.030)
    b = GripperModel(object_width=0.030)
    a.command_current(-1.0)
    b.command_current(-1.0)
    for _ in range(1000):
        a.advance(0.0005)
    b.advance(0.5)
    assert a.w == b.w == 0.030
    assert a.mode == b.mode == GRIPPING and a.current == b.current == -1.0


@settings(max_examples=60, deadline=None)
@given(amps=st.floats(0.25, 5.0), width=st.floats(0.0005, 0.039))
def test_close_time_is_what_the_model_implies(amps: float, width: float) -> None:
    m = GripperModel(object_width=width)
    mid = m.command_current(-amps)
    expected = current_move_time(amps, 0.040 - width)
    assert m.time_to_completion() == pytest.approx(expected, rel=1e-9)
    m.advance(expected * 0.999)
    assert m.outcome(mid) is None
    m.advance(expected * 0.002)
    out = m.outcome(mid)
    assert out is not None and out.status == "gripping"
    assert m.w == pytest.approx(width)
    assert m.force == pytest.approx(P.force_constant * amps)


def test_state_observable_while_moving() -> None:
    m = GripperModel(object_width=0.030)
    m.command_current(-1.0)
    m.advance(0.05)  # in the run-up: v = a t, w = w0 - a t^2 / 2
    s = m.status()
    assert isinstance(s, GripperStatus) and s.mode == MOVING
    assert s.velocity == pytest.approx(-0.32 * 0.05)
    assert s.position == pytest.approx(0.040 - 0.5 * 0.32 * 0.05**2)
    assert s.current == -1.0
    m.advance(0.15)  # cruising
    assert m.status().velocity == pytest.approx(-0.032)


@pytest.mark.parametrize("amps", [-0.5, -1.0, -2.0, -3.0, -5.0])
def test_gripping_force_proportional_to_current(amps: float) -> None:
    m = GripperModel(object_width=0.030)
    m.command_current(amps)
    m.advance(2.0)
    assert m.mode == GRIPPING
    assert m.force == pytest.approx(40.0 * abs(amps))
    assert m.force / abs(amps) == pytest.approx(P.force_constant)


def test_opening_runs_to_the_stroke_end_object_does_not_block() -> None:
    m = GripperModel(object_width=0.030)
    mid = m.command_current(+1.0)
    expected = current_move_time(1.0, 0.030)
    assert m.time_to_completion() == pytest.approx(expected)
    m.advance(expected + 0.01)
    out = m.outcome(mid)
    assert out is not None and out.ok and out.status == "end_stop" and m.w == P.stroke_max and m.mode == IDLE


def test_closing_without_object_stops_at_zero() -> None:
    m = GripperModel()
    mid = m.command_current(-2.0)
    m.advance(5.0)
    out = m.outcome(mid)
    assert out is not None and out.status == "end_stop" and m.w == 0.0 and m.force == 0.0


def test_object_narrower_than_jaws_only() -> None:
    m = GripperModel(position=0.020, object_width=0.030)  # object not between the jaws
    m.command_current(-1.0)
    m.advance(5.0)
    assert m.w == 0.0


def test_current_limits() -> None:
    g = SimGripper(clock=VirtualClock())
    r = g.move_current(-0.1)
    assert not r and "cannot move" in r.error and "0.200 A" in r.error
    r = g.move_current(-7.5)
    assert not r and "exceeds" in r.error and "5.000 A" in r.error
    for bad in (float("nan"), float("inf"), "x"):
        r = g.move_current(bad)  # type: ignore[arg-type]
        assert not r and "invalid current" in r.error


# ---------------------------------------------------------------- position moves
@pytest.mark.parametrize("target", [0.025, 0.039, 0.0, 0.070, 0.06])
def test_move_to_position_reaches_target_in_trapezoid_time(target: float) -> None:
    m = GripperModel()
    mid = m.command_position(target)
    expected = position_move_time(abs(target - 0.040))
    assert m.time_to_completion() == pytest.approx(expected, abs=1e-12)
    m.advance(expected)
    out = m.outcome(mid)
    assert out is not None and out.status == "reached" and m.w == target and m.v == 0 and m.mode == IDLE


def test_speed_and_acceleration_limits_respected() -> None:
    m = GripperModel(position=0.0)
    m.command_position(0.070)
    prev_v, dt = 0.0, 0.001
    while m.moving:
        m.advance(dt)
        assert abs(m.v) <= P.max_velocity + 1e-12
        assert abs(m.v - prev_v) <= P.max_acceleration * dt + 1e-9
        prev_v = m.v
    assert m.w == 0.070


@pytest.mark.parametrize("target", [-0.001, 0.0701, 0.5, -1.0])
def test_move_outside_stroke_rejected(target: float) -> None:
    g = SimGripper(clock=VirtualClock())
    r = g.move_to_position(target)
    assert not r.ok
    assert "outside the stroke 0.000..0.070 m" in r.error
    assert g.state().position == 0.040 and g.state().mode == IDLE  # nothing moved


def test_position_move_blocked_by_object_fails_and_grips() -> None:
    g = SimGripper(clock=VirtualClock(), object_width=0.030)
    r = g.move_to_position(0.020)
    assert not r and "blocked by an object at 0.0300 m" in r.error and r.position == 0.030
    s = g.state()
    assert s.mode == GRIPPING and s.current == -P.position_current


def test_go_home_references_and_returns_to_40mm() -> None:
    clock = VirtualClock()
    g = SimGripper(clock=clock, referenced=False, position=0.010)
    r = g.move_to_position(0.02)
    assert not r and "not referenced" in r.error
    r = g.go_home()
    assert r and r.position == 0.040
    assert clock.t == pytest.approx(position_move_time(0.030), abs=1e-5)
    assert g.move_to_position(0.02)


# ---------------------------------------------------------------- backend behaviour
def test_virtual_clock_fast_forwards() -> None:
    clock = VirtualClock()
    g = SimGripper(clock=clock, object_width=0.030)
    t0 = time.monotonic()
    r = g.move_current(-1.0)
    assert r and r.position == 0.030
    assert time.monotonic() - t0 < 0.5  # no wall-clock waiting
    assert clock.t == pytest.approx(0.3625, abs=1e-5)
    assert g.state().mode == GRIPPING


def test_timeout_stops_and_fails() -> None:
    clock = VirtualClock()
    g = SimGripper(clock=clock, position=0.0)
    r = g.move_to_position(0.070, timeout=0.5)
    assert not r and "not finished within 0.500 s" in r.error
    assert clock.t == pytest.approx(0.5)
    clock.advance(1.0)  # braking done
    assert g.state().mode == IDLE and g.state().velocity == 0.0


@pytest.mark.parametrize("timeout", [0, -1, float("nan")])
def test_bad_timeout(timeout: float) -> None:
    assert "invalid timeout" in SimGripper(clock=VirtualClock()).go_home(timeout).error


def test_stop_from_another_thread_ends_blocking_call_real_time() -> None:
    g = SimGripper(position=0.0)  # real clock: a full-stroke move takes ~1.1 s
    t0 = time.monotonic()
    r = stopped_mid_move(g, lambda: g.move_to_position(0.070), 0.070, 0.002)
    assert time.monotonic() - t0 < 0.6
    assert not r and "stopped by a stop command" in r.error
    time.sleep(0.3)  # braking from <= 82 mm/s takes <= 0.26 s
    assert g.state().mode == IDLE


def test_fault_and_acknowledge() -> None:
    g = SimGripper(clock=VirtualClock())
    g.fault("ERROR TOW")
    s = g.state()
    assert s.mode == "error" and s.error == "ERROR TOW"
    r = g.move_current(-1)
    assert not r and "acknowledge" in r.error
    assert g.acknowledge() and g.state().mode == IDLE
    assert g.move_current(-1)


def test_no_gripper() -> None:
    g = SimGripper(clock=VirtualClock(), present=False)
    assert not g.has_gripper()
    assert not g.go_home() and "no gripper" in g.go_home().error
    assert g.state().mode == "error"


def test_reversing_current_keeps_velocity_continuous() -> None:
    m = GripperModel()
    m.command_current(-2.0)
    m.advance(0.2)
    v_before, w_before = m.v, m.w
    m.command_current(+2.0)
    assert (m.v, m.w) == (v_before, w_before)
    m.advance(0.001)
    assert m.v - v_before == pytest.approx(P.max_acceleration * 0.001)
