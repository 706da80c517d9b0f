"""The driver's limit monitor on its own: which setpoints it admits, which it refuses and
why, its last resorts, and how its limits follow a limit change under a motion.

Round numbers: dt 0.01 s, |q| < 10 deg, 100 deg/s (1 deg a cycle), 1000 deg/s^2
(the velocity may change by 10 deg/s, i.e. the step by 0.1 deg, from one cycle to the next).
"""

import numpy as np
import pytest

from rob6.robots import get_robot
from rob6_driver.limits import OUTSIDE_TOL, Breach, LimitMonitor, Limits, turn_bad, within
from rob6_driver.motion import MotionCore

DT = 0.01
ZERO = np.zeros(6)


def limits(vmax: float = 100.0, amax: float = 1000.0, turn: float = 10.0) -> Limits:
    six = np.ones(6)
    return Limits(-turn * six, turn * six, vmax * six, amax * six, amax / 0.048 * six, 5.0 * six)


def monitor(**kw: float) -> LimitMonitor:
    return LimitMonitor(limits(**kw), DT)


def joint(j: int, value: float, base: np.ndarray = ZERO) -> np.ndarray:
    q = base.copy()
    q[j] = value
    return q


# ---------------------------------------------------------------- one setpoint
def test_a_setpoint_within_every_limit_passes() -> None:
    mon = monitor()
    assert mon.check(joint(2, 0.05), ZERO, ZERO) is None
    # cruising at 90 deg/s, one more step at the same speed
    q = np.full(6, 3.0)
    assert mon.check(q + 0.9, q, np.full(6, 90.0)) is None


def test_a_setpoint_beyond_a_turn_limit_is_caught() -> None:
    mon = monitor()
    q = np.full(6, 9.95)
    assert mon.check(joint(3, 10.05, q), q, ZERO) == Breach("turn", 3, 10.05, 10.0)
    q = np.full(6, -9.95)
    assert mon.check(joint(1, -10.05, q), q, ZERO) == Breach("turn", 1, -10.05, -10.0)


def test_turn_limits_are_strict() -> None:
    mon = monitor()
    q = np.full(6, 9.95)
    breach = mon.check(joint(0, 10.0, q), q, ZERO)
    assert breach is not None and breach.kind == "turn" and breach.joint == 0


def test_a_joint_already_outside_may_only_move_back_in() -> None:
    mon = monitor()
    outside = joint(4, 10.5)  # the limits were narrowed while it stood there
    assert mon.check(outside, outside, ZERO) is None  # standing still
    assert mon.check(joint(4, 10.45), outside, ZERO) is None  # inwards
    breach = mon.check(joint(4, 10.55), outside, ZERO)  # further out
    assert breach is not None and breach.kind == "turn" and breach.joint == 4


def test_a_setpoint_too_fast_is_caught() -> None:
    mon = monitor(amax=1e9)  # acceleration out of the way
    breach = mon.check(joint(5, 1.5), ZERO, ZERO)  # 150 deg/s
    assert breach is not None and breach.kind == "speed" and breach.joint == 5
    assert breach.value == pytest.approx(150.0) and breach.limit == 100.0
    backwards = mon.check(joint(5, -1.5), ZERO, ZERO)
    assert backwards is not None and backwards.value == pytest.approx(-150.0)
    assert mon.check(joint(5, 1.0), ZERO, ZERO) is None  # exactly the limit


def test_a_setpoint_accelerating_too_hard_is_caught() -> None:
    mon = monitor()
    breach = mon.check(joint(2, 0.2), ZERO, ZERO)  # 0 -> 20 deg/s in one cycle: 2000 deg/s^2
    assert breach is not None and breach.kind == "acceleration" and breach.joint == 2
    assert breach.value == pytest.approx(2000.0) and breach.limit == 1000.0
    assert mon.check(joint(2, 0.1), ZERO, ZERO) is None  # 1000 deg/s^2: the limit
    # braking counts too: at 50 deg/s, standing still at once is -5000 deg/s^2
    breach = mon.check(ZERO, ZERO, joint(2, 50.0))
    assert breach is not None and breach.kind == "acceleration" and breach.value == pytest.approx(-5000.0)


def test_the_turn_limit_is_reported_before_speed() -> None:
    mon = monitor()
    q = np.full(6, 9.0)
    breach = mon.check(joint(0, 12.0, q), q, ZERO)  # too far and too fast: turn first
    assert breach is not None and breach.kind == "turn"


# ---------------------------------------------------------------- a whole trajectory
def test_a_trajectory_is_checked_up_front_including_the_stop_at_its_end() -> None:
    mon = monitor()
    ramp = np.cumsum([0.0, 0.1, 0.2, 0.3, 0.3, 0.2, 0.1, 0.0])
    good = np.outer(ramp, np.ones(6))
    assert mon.check_trajectory(good, ZERO, ZERO) == ""
    # the same ramp, cut off at full speed: holding the last sample brakes too hard
    cut = good[:4]
    assert "acceleration" in mon.check_trajectory(cut, ZERO, ZERO)
    assert mon.check_trajectory(cut, ZERO, ZERO, dynamics=False) == ""  # a dummy robot jumps
    far = good.copy()
    far[-1, 1] = 11.0
    assert mon.check_trajectory(far, ZERO, ZERO, dynamics=False).startswith("joint 2 sample 7 at 11.000000")


# ---------------------------------------------------------------- last resorts
def test_clamp_gives_the_admissible_sample_closest_to_a_bad_one() -> None:
    mon = monitor()
    q_new = mon.clamp(joint(0, 0.5), ZERO, ZERO)
    assert mon.check(q_new, ZERO, ZERO) is None
    assert q_new[0] == pytest.approx(0.1) and np.all(q_new[1:] == 0)


def test_brake_slows_down_as_hard_as_allowed() -> None:
    mon = monitor()
    v = np.full(6, 50.0)
    q = np.zeros(6)
    for _ in range(10):
        q_new, v_new = mon.brake(q, v)
        assert mon.check(q_new, q, v) is None
        q, v = q_new, v_new
    assert np.allclose(v, 0.0, atol=1e-5) and np.all(q > 0)


# ---------------------------------------------------------------- limit changes
def test_slower_limits_under_a_motion_are_enforced_once_the_state_is_within_them() -> None:
    mon = monitor()
    slow = limits(vmax=20.0)
    mon.loosen(slow)
    assert mon.enforced.vmax[0] == 100.0  # still the old ones: the robot is at 90 deg/s
    fast = np.full(6, 90.0)
    mon.update(slow, moving=True, on_current_plan=True, v_prev=fast, qd=fast, qdd=ZERO)
    assert mon.enforced.vmax[0] == 100.0
    slow_v = np.full(6, 15.0)
    for _ in range(2):
        mon.update(slow, moving=True, on_current_plan=True, v_prev=slow_v, qd=slow_v, qdd=ZERO)
        assert mon.enforced.vmax[0] == 100.0
    mon.update(slow, moving=True, on_current_plan=True, v_prev=slow_v, qd=slow_v, qdd=ZERO)
    assert mon.enforced.vmax[0] == 20.0  # settled for three cycles
    breach = mon.check(joint(0, 0.3), ZERO, np.full(6, 20.0))
    assert breach is not None and breach.kind == "speed"


def test_loosened_limits_close_at_rest() -> None:
    mon = monitor()
    mon.loosen(limits(vmax=20.0))
    mon.update(limits(vmax=20.0), moving=False, on_current_plan=False, v_prev=ZERO, qd=ZERO, qdd=ZERO)
    assert mon.enforced.vmax[0] == 20.0


def test_turn_limits_crossed_by_a_stop_are_widened_just_enough_then_close_at_rest() -> None:
    mon = monitor()
    lo, hi = -10.0 * np.ones(6), joint(2, 3.0, 10.0 * np.ones(6))
    start = joint(2, 2.0)
    fmin, fmax = start.copy(), joint(2, 4.0)  # the stop will run to 4 deg on joint 3
    assert not within(fmin, fmax, lo, hi, start)
    assert mon.widen_turn(lo, hi, fmin, fmax, start) == 3
    assert mon.enforced.turn_max[2] == pytest.approx(4.0 + 1e-6)
    assert mon.enforced.turn_max[0] == 10.0
    assert mon.check(joint(2, 3.9), joint(2, 3.85), ZERO) is None  # the stop passes
    current = Limits(lo, hi, mon.enforced.vmax, mon.enforced.amax, mon.enforced.jmax, mon.enforced.max_change)
    mon.update(current, moving=False, on_current_plan=False, v_prev=ZERO, qd=ZERO, qdd=ZERO)
    assert mon.enforced.turn_max[2] == 3.0


def joint_respects_turn(low: float, high: float, lo: float, hi: float, start: float) -> bool:
    """The turn rule read joint by joint from the module's docstring: strict limits, but a
    joint starting on or outside one may only move back inwards."""
    low_ok = low >= start - OUTSIDE_TOL if start <= lo else low > lo
    high_ok = high <= start + OUTSIDE_TOL if start >= hi else high < hi
    return low_ok and high_ok


def test_the_turn_checks_follow_the_rule_inside_on_and_outside_the_limits() -> None:
    """``turn_bad`` and ``within`` take a shortcut for samples strictly inside (every cycle's
    case); with starts and samples inside, on and outside the limits they still say what
    the rule says."""
    rng = np.random.default_rng(25)
    lo, hi = np.full(6, -10.0), np.full(6, 10.0)
    values = np.array([-10.5, -10.0, -10.0 + 1e-12, -9.0, 0.0, 9.0, 10.0 - 1e-12, 10.0, 10.5])
    for _ in range(3000):
        start, a, b = (rng.choice(values, 6) for _ in range(3))
        low, high = np.minimum(a, b), np.maximum(a, b)
        rule = [joint_respects_turn(low[j], high[j], lo[j], hi[j], start[j]) for j in range(6)]
        assert within(low, high, lo, hi, start) == all(rule)
        single = [joint_respects_turn(a[j], a[j], lo[j], hi[j], start[j]) for j in range(6)]
        first_bad = next((j for j, ok in enumerate(single) if not ok), None)
        assert turn_bad(a[None], lo, hi, start) == (None if first_bad is None else (0, first_bad))


# ---------------------------------------------------------------- the core cannot go around it
def test_the_motion_core_checks_every_sample_with_its_monitor() -> None:
    core = MotionCore("kr16")
    lim = Limits.defaults(get_robot("kr16"))
    assert np.array_equal(core.enforced_limits().vmax, lim.vmax)
    step = lim.vmax[0] * core.dt * 3  # three times too fast, from rest
    q = np.zeros((3, 6))
    q[1:, 0] = [step, 2 * step]
    motion = core.execute(q, check=False)  # the up-front check skipped: the monitor still acts
    core.run_until_idle()
    assert motion.done.is_set() and not motion.ok
    assert [(v.kind, v.joint, v.source) for v in core.violations] == [("speed", 1, "trajectory")]
    assert core.state().q[0] < step  # the bad sample was never applied
