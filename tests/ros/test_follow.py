"""The planner's sampling and checks of time-parameterised trajectories (rob6_planner.follow)."""

from __future__ import annotations

import numpy as np
import pytest

from rob6_planner.follow import FollowRefused, sample as sample_with
from rob6_planner.trajectory import SampledTrajectory

HOME = [0.0, -90.0, 90.0, 0.0, 45.0, 0.0]


def sample(t: list[float], q: list[list[float]], qd: list[list[float]] | None, qdd: list[list[float]] | None, *,
           current: list[float]) -> SampledTrajectory:
    """At 4 ms with turn limits +-170 deg, 100 deg/s, 400 deg/s^2 and a 1 deg start tolerance."""
    return sample_with(t, q, qd, qdd, current=current, dt=0.004, turn_min=[-170.0] * 6, turn_max=[170.0] * 6,
                       speed=[100.0] * 6, accel=[400.0] * 6, start_tolerance=1.0)


def _target(delta: float) -> list[float]:
    return [HOME[0] + delta, *HOME[1:]]


def test_quintic_goes_through_every_point_and_ends_at_rest() -> None:
    mid, end = _target(10.0), _target(20.0)
    traj = sample([0.0, 1.0, 2.0], [HOME, mid, end], [[0.0] * 6, [15.0] + [0.0] * 5, [0.0] * 6],
                  [[0.0] * 6] * 3, current=HOME)
    assert traj.q[0].tolist() == HOME and traj.q[-1].tolist() == end
    k = int(round(1.0 / traj.dt))
    assert traj.q[k][0] == pytest.approx(10.0, abs=1e-9) and traj.qd[k][0] == pytest.approx(15.0, abs=1e-6)
    assert np.all(np.abs(traj.qd) <= 100.0) and traj.qd[-1].tolist() == [0.0] * 6
    # what the driver checks: finite differences of the samples within the limits
    v = np.diff(traj.q, axis=0) / traj.dt
    assert np.abs(v).max() <= 100.0 and np.abs(np.diff(v, axis=0) / traj.dt).max() <= 400.0 * 1.01


def test_without_velocities_they_are_estimated_and_the_path_is_smooth() -> None:
    traj = sample([0.0, 1.0, 2.0], [HOME, _target(5.0), _target(10.0)], None, None, current=HOME)
    assert traj.q[-1][0] == 10.0
    assert np.all(np.diff(traj.q[:, 0]) >= -1e-12)  # monotonic towards the end


def test_a_first_point_later_than_zero_starts_from_the_arm_at_rest() -> None:
    here = _target(-3.0)
    traj = sample([1.5], [_target(3.0)], None, None, current=here)
    assert traj.q[0].tolist() == here and traj.q[-1][0] == 3.0 and traj.duration == pytest.approx(1.5)


@pytest.mark.parametrize(("t", "q", "current", "message"), [
    ([0.0, 1.0], [HOME, _target(200.0)], HOME, "point 1: joint 1 at 200.000 deg is outside its turn limits"),
    ([0.0, 0.1], [HOME, _target(30.0)], HOME, "joint 1 speed"),
    ([0.0, 1.0], [_target(2.0), _target(5.0)], HOME, "starts 2.000 deg away from where joint 1 is"),
    ([0.0, 1.0, 1.0], [HOME, _target(1.0), _target(2.0)], HOME, "strictly increasing"),
    ([], [], HOME, "no points"),
])
def test_refusals_say_why(t: list[float], q: list[list[float]], current: list[float], message: str) -> None:
    with pytest.raises(FollowRefused, match=message.replace("(", r"\(")):
        sample(t, q, None, None, current=current)


def test_the_path_between_points_is_checked_too() -> None:
    # both points inside, but a velocity at the first makes the quintic overshoot the limit
    near = [165.0, *HOME[1:]]
    with pytest.raises(FollowRefused, match="above its upper turn limit"):
        sample([0.0, 1.0], [near, near], [[90.0] + [0.0] * 5, [0.0] * 6], None, current=near)


def test_the_last_point_must_be_at_rest() -> None:
    with pytest.raises(FollowRefused, match="not at rest"):
        sample([0.0, 1.0], [HOME, _target(10.0)], [[0.0] * 6, [5.0] + [0.0] * 5], None, current=HOME)
