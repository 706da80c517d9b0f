"""MotionSettings semantics (REFERENCE.md 6.3, 6.3a, 6.4) beyond the transcripts."""

import json

import msgspec
import pytest

from rob6 import messages
from rob6.robots import ROBOT_TYPES
from rob6_planner.config import MotionSettings


@pytest.mark.parametrize("robot", ROBOT_TYPES)
def test_defaults(robot: str) -> None:
    c = MotionSettings(robot)
    r = c.robot
    assert c.speed == list(r.default_speed)
    assert c.accel == [0.005] * 6
    assert c.max_change == [hi - lo for lo, hi in zip(r.turn_min, r.turn_max, strict=True)]
    assert c.weights == [4, 1, 1, 1, 1, 1]
    assert c.allowed == ["toggleHand", "toggleElbow", "toggleArm"]
    assert c.rt_speed_control == 1


def test_partial_update_speed_and_accel() -> None:
    c = MotionSettings("kr16")
    assert not c.set_speed([0.1, 0.1, 0.1, 0.1, 0.1, -0.1])
    assert c.speed == [0.1] * 5 + [0.7380]
    assert not c.set_accel([0.005, 0.001, 0.01, 0.01, 0.01, 0.05])
    assert c.accel == [0.005, 0.001, 0.01, 0.01, 0.01, 0.005]
    assert c.set_speed([1.872, 1.872, 1.872, 3.96, 3.96, 7.38])  # bounds inclusive
    assert not c.set_single_speed(1, 1.872001)
    assert c.set_single_accel(6, 0.02) and not c.set_single_accel(6, 0.020001)


def test_max_change_all_or_nothing_and_single() -> None:
    c = MotionSettings("kr16")
    assert c.set_max_change([0] * 6)
    assert not c.set_max_change([10, 10, 10, 10, 10, -10])
    assert c.max_change == [0.0] * 6
    assert not c.set_single_max_change(4, 0.0)
    assert not c.set_single_max_change(4, -0.0)
    assert c.set_single_max_change(4, 1e-9)
    assert not c.set_single_max_change(0, 5) and not c.set_single_max_change(7, 5)


def test_turn_limits_unchecked_and_independent_of_max_change() -> None:
    c = MotionSettings("kr16")
    assert c.set_turn_max([-200] * 6) and c.set_turn_min([1e9] * 6)
    assert c.max_change == list(c.robot.default_max_change)
    assert c.set_max_change([5] * 6) and c.reset_turn()
    assert c.max_change == [5.0] * 6  # ResetJointsMaxTurn does not reset max change
    assert c.set_single_turn_max(1, 100) and c.reset_max_change()
    assert c.max_change == list(c.robot.default_max_change)
    assert not c.set_single_turn_min(-1, 3)


def test_weights_status_rt() -> None:
    c = MotionSettings("kr16")
    assert not c.set_weights([1, 1, 1, 0, 1, 1]) and c.weights == [4, 1, 1, 1, 1, 1]
    assert not c.set_weights([-0.0] * 6)
    assert c.set_weights([1e-9] * 6)
    assert c.set_allowed(["lefty", "up", "noflip"]) and c.allowed == ["noflip", "up", "lefty"]
    assert c.set_allowed(["noflip"]) and c.allowed == ["noflip", "toggleElbow", "toggleArm"]
    assert not c.set_allowed(["flip", "flip", "flip"]) and not c.set_allowed(["NOFLIP"])
    assert not c.set_allowed([])
    assert c.set_rt_speed_control(0) and c.rt_speed_control == 0
    assert not c.set_rt_speed_control(2) and not c.set_rt_speed_control(-1)
    assert not c.apply("SetKukaRTSpeed", [0.1] * 6)
    assert c.apply("SetAdeptSpeed", [50])
    assert not c.apply("NoSuchCommand")


def test_allowed_status() -> None:
    cur = ("noflip", "up", "lefty")
    c = MotionSettings("kr16")
    c.set_allowed(["noflip", "up", "lefty"])
    assert not c.status_allowed(("noflip", "down", "lefty"), cur)


def test_dict_roundtrip_and_bus_schema() -> None:
    c = MotionSettings("ad850")
    c.set_speed([0.2] * 6)
    c.set_allowed(["flip"])
    c.set_rt_speed_control(0)
    d = json.loads(json.dumps(c.to_dict()))
    assert MotionSettings.from_dict("ad850", d) == c
    msg = msgspec.convert(d, messages.MotionConfig)
    assert msgspec.to_builtins(msg) == d
