"""The robot's configuration rules, in their one home (rob6.status): reading a pattern,
matching it, and the flags' formulas on floats and on numpy arrays alike."""

import math

import numpy as np
import pytest

from rob6.robots import ROBOTS
from rob6.status import elbow_term, parse_status, reach_term, status_flags, status_matches, status_words


def test_parse_status() -> None:
    assert parse_status(["lefty", "up", "noflip"]) == ("noflip", "up", "lefty")
    assert parse_status(["righty", "down", "flip"]) == ("flip", "down", "righty")
    assert parse_status(["noflip", "up"]) == ("noflip", "up", "toggleArm")
    assert parse_status(["noflip"]) == ("noflip", "toggleElbow", "toggleArm")
    assert parse_status(["toggleArm", "toggleElbow", "toggleHand"]) == ("toggleHand", "toggleElbow", "toggleArm")
    assert parse_status(["up", "noflip", "lefty", "extra"]) == ("noflip", "up", "lefty")  # a 4th word: ignored
    for bad in (["NOFLIP", "UP", "LEFTY"], ["Flip", "down", "righty"], ["foo", "up", "lefty"],
                ["flip", "flip", "righty"], []):
        with pytest.raises(ValueError):
            parse_status(bad)


def test_status_matches() -> None:
    cur = ("noflip", "up", "lefty")
    assert status_matches(["toggleHand", "toggleElbow", "toggleArm"], ("flip", "down", "righty"), cur)
    assert status_matches(["noToggleHand", "up", "toggleArm"], ("noflip", "up", "righty"), cur)
    assert not status_matches(["noToggleHand", "up", "toggleArm"], ("flip", "up", "righty"), cur)
    assert not status_matches(["noflip", "up", "lefty"], ("noflip", "down", "lefty"), cur)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_flags_on_arrays_equal_flags_on_floats(name: str) -> None:
    robot = ROBOTS[name]
    q = np.random.default_rng(1).uniform(-170, 170, (500, 6))
    q2, q3 = np.radians(q[:, 1]), np.radians(q[:, 2])
    flags = status_flags(robot, q2, q3, q[:, 4], sin=np.sin, cos=np.cos)
    for k, row in enumerate(q):
        one = status_flags(robot, math.radians(row[1]), math.radians(row[2]), row[4])
        assert tuple(bool(f[k]) for f in flags) == one
        assert status_words(*one) == robot.status(row)
    assert np.allclose(elbow_term(robot, q3, sin=np.sin, cos=np.cos), robot.d4 * np.sin(q3) - robot.a3 * np.cos(q3))
    lefty = reach_term(robot, q2, q3, sin=np.sin, cos=np.cos) > 0
    assert lefty.tolist() == [robot.status(row)[2] == "lefty" for row in q]
