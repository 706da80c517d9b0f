"""Motion configuration of one robot: the state behind the protocol's limit commands.

Semantics are those of the original rob6server (REFERENCE.md 6.3, 6.3a, 6.4, 7 and the
``limits``/``limits_bounds``/``misc`` transcripts):

* speeds (deg per 12 ms cycle) ``0 <= v <= 10 x default`` per joint, accelerations
  (deg per cycle^2) ``0 <= a <= 0.02`` (``RobotModel.max_accel_bound``); bounds inclusive. The 6-value forms update
  **partially**: joints before the first invalid value are already set.
* max change: 6-value form ``c >= 0`` for all, **all-or-nothing**; single form ``c > 0``
  (``-0`` rejected). Independent of the turn limits after start (6.3a).
* turn limits (strict ``min < q < max`` when moving) are stored unchecked (max < min,
  negative, 1e9 all accepted). Only the joint index is checked.
* min-change weights ``w > 0`` for all, all-or-nothing.
* allowed status: 1..3 words in any order, missing categories ``toggle…``; stored in
  hand/elbow/arm order.
* RTSpeedControl 0 or 1. SetKukaRTSpeed is always ``False`` (on the rt types the
  original parses the values and still refuses them; the gateway does the parsing).
* joint indices are 1..6 (0, 7, -1 -> ``False``).

Input is already-parsed numbers (the gateway reads the text and produces the
``ERROR: incorrect …`` replies); every method answers ``True``/``False``. Non-finite
numbers are refused everywhere (the gateway never produces them).

The whole state is a plain dict (``to_dict``/``from_dict``) with the field names of
``rob6.messages.MotionConfig`` so it travels over the bus as JSON: ``MotionSettings`` is
the planner's live, validated state, ``MotionConfig`` the message that carries a copy.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, TypedDict

from rob6.robots import RobotModel, get_robot
from rob6.status import TOGGLE_ALL, parse_status, status_matches

N_JOINTS = 6


class SettingsDict(TypedDict):
    """``MotionSettings.to_dict()``: the fields of ``rob6.messages.MotionConfig``."""

    speed: list[float]
    accel: list[float]
    max_change: list[float]
    turn_max: list[float]
    turn_min: list[float]
    weights: list[float]
    allowed: list[str]
    rt_speed_control: int


FIELDS = ("speed", "accel", "max_change", "turn_max", "turn_min", "weights",
          "allowed", "rt_speed_control")


def _finite(value: float) -> bool:
    try:
        return math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


def _index(j: float) -> int | None:
    """Protocol joint index 1..6 -> 0..5, or None."""
    try:
        f = float(j)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(f) or not f.is_integer():
        return None
    i = int(f)
    return i - 1 if 1 <= i <= N_JOINTS else None


def _six(values: Iterable[float]) -> list[float] | None:
    """The first 6 values as floats (extras ignored, as the original), or None."""
    values = list(values)
    if len(values) < N_JOINTS:
        return None
    out = []
    for v in values[:N_JOINTS]:
        if not _finite(v):
            return None
        out.append(float(v))
    return out


class MotionSettings:
    """Speeds, accelerations, max change, turn limits, weights, allowed status, RT mode:
    what the protocol's Set*/Reset* commands change, with their checks (the message
    carrying a copy is ``rob6.messages.MotionConfig``)."""

    def __init__(self, robot: RobotModel | str):
        self.robot = get_robot(robot) if isinstance(robot, str) else robot
        self.speed: list[float] = []
        self.accel: list[float] = []
        self.max_change: list[float] = []
        self.turn_max: list[float] = []
        self.turn_min: list[float] = []
        self.weights: list[float] = []
        self.allowed: list[str] = []
        self.rt_speed_control: int = 1
        self.reset_all()

    # ------------------------------------------------------------------ defaults
    @property
    def speed_bound(self) -> tuple[float, ...]:
        return self.robot.speed_bound

    def reset_all(self) -> None:
        self.reset_speed()
        self.reset_accel()
        self.reset_max_change()
        self.reset_turn()
        self.reset_weights()
        self.reset_allowed()
        self.rt_speed_control = 1

    def reset_speed(self) -> bool:
        self.speed = list(self.robot.default_speed)
        return True

    def reset_accel(self) -> bool:
        self.accel = list(self.robot.default_accel)
        return True

    def reset_max_change(self) -> bool:
        # the start-up values (max - min of the *default* turn limits), 6.3a
        self.max_change = list(self.robot.default_max_change)
        return True

    def reset_turn(self) -> bool:
        self.turn_max = list(self.robot.turn_max)
        self.turn_min = list(self.robot.turn_min)
        return True

    def reset_weights(self) -> bool:
        self.weights = list(self.robot.default_weights)
        return True

    def reset_allowed(self) -> bool:
        self.allowed = list(TOGGLE_ALL)
        return True

    # ------------------------------------------------------------------ checks
    def _speed_ok(self, i: int, v: float) -> bool:
        return 0.0 <= v <= self.speed_bound[i]

    def _accel_ok(self, i: int, a: float) -> bool:
        return 0.0 <= a <= self.robot.max_accel_bound

    # ------------------------------------------------------------------ speeds / accels
    def _set_partial(self, target: list[float], values: Iterable[float], ok: Callable[[int, float], bool]) -> bool:
        values = list(values)
        if len(values) < N_JOINTS:
            return False
        for i, v in enumerate(values[:N_JOINTS]):
            if not _finite(v) or not ok(i, float(v)):
                return False  # the joints before this one stay set (partial update)
            target[i] = float(v)
        return True

    def _set_single(self, target: list[float], j: float, v: float, ok: Callable[[int, float], bool]) -> bool:
        i = _index(j)
        if i is None or not _finite(v) or not ok(i, float(v)):
            return False
        target[i] = float(v)
        return True

    def set_speed(self, values: Sequence[float]) -> bool:
        return self._set_partial(self.speed, values, self._speed_ok)

    def set_single_speed(self, j: float, v: float) -> bool:
        return self._set_single(self.speed, j, v, self._speed_ok)

    def set_accel(self, values: Sequence[float]) -> bool:
        return self._set_partial(self.accel, values, self._accel_ok)

    def set_single_accel(self, j: float, a: float) -> bool:
        return self._set_single(self.accel, j, a, self._accel_ok)

    # ------------------------------------------------------------------ max change
    def set_max_change(self, values: Sequence[float]) -> bool:
        six = _six(values)
        if six is None or any(not c >= 0.0 for c in six):
            return False  # all-or-nothing
        self.max_change = six
        return True

    def set_single_max_change(self, j: float, c: float) -> bool:
        return self._set_single(self.max_change, j, c, lambda i, v: v > 0.0)

    # ------------------------------------------------------------------ turn limits
    def set_turn_max(self, values: Sequence[float]) -> bool:
        six = _six(values)
        if six is None:
            return False
        self.turn_max = six
        return True

    def set_turn_min(self, values: Sequence[float]) -> bool:
        six = _six(values)
        if six is None:
            return False
        self.turn_min = six
        return True

    def set_single_turn_max(self, j: float, v: float) -> bool:
        return self._set_single(self.turn_max, j, v, lambda i, x: True)

    def set_single_turn_min(self, j: float, v: float) -> bool:
        return self._set_single(self.turn_min, j, v, lambda i, x: True)

    # ------------------------------------------------------------------ weights / status / rt
    def set_weights(self, values: Sequence[float]) -> bool:
        six = _six(values)
        if six is None or any(not w > 0.0 for w in six):
            return False
        self.weights = six
        return True

    def set_allowed(self, words: Iterable[str]) -> bool:
        try:
            self.allowed = list(parse_status(words))
        except ValueError:
            return False
        return True

    def set_rt_speed_control(self, n: float) -> bool:
        try:
            f = float(n)
        except (TypeError, ValueError):
            return False
        if f not in (0.0, 1.0):
            return False
        self.rt_speed_control = int(f)
        return True

    def set_kuka_rt_speed(self, values: Sequence[float] = ()) -> bool:
        # kr16/kr3/ad850/kaw_fs: refused unparsed; kr16rt/kr3rt: parsed, still refused
        return False

    # ------------------------------------------------------------------ queries
    def status_allowed(self, target: Sequence[str], current: Sequence[str],
                       pattern: Sequence[str] | None = None) -> bool:
        """Is a move to ``target`` status allowed by the allowed status (and ``pattern``)?"""
        if not status_matches(self.allowed, target, current):
            return False
        return pattern is None or status_matches(pattern, target, current)

    def within_turn_limits(self, q: Sequence[float]) -> int | None:
        """Index (0-based) of the first joint not strictly inside its turn limits, or None."""
        for i, (lo, x, hi) in enumerate(zip(self.turn_min, q, self.turn_max, strict=True)):
            if not lo < x < hi:
                return i
        return None

    # ------------------------------------------------------------------ protocol dispatch
    def apply(self, command: str, args: Sequence[float] = (), words: Sequence[str] = ()) -> bool:
        """Apply one parsed Set*/Reset* protocol command; ``False`` for unknown commands."""
        a = list(args)

        def single(fn: Callable[[float, float], bool]) -> bool:
            return fn(a[0], a[1]) if len(a) >= 2 else False

        table: dict[str, Callable[[], bool]] = {
            "SetJointsMaxSpeed": lambda: self.set_speed(a),
            "SetSingleJointMaxSpeed": lambda: single(self.set_single_speed),
            "ResetJointsMaxSpeed": self.reset_speed,
            "SetJointsMaxAcceleration": lambda: self.set_accel(a),
            "SetSingleJointMaxAcceleration": lambda: single(self.set_single_accel),
            "ResetJointsMaxAcceleration": self.reset_accel,
            "SetJointsMaxChange": lambda: self.set_max_change(a),
            "SetSingleJointMaxChange": lambda: single(self.set_single_max_change),
            "ResetJointsMaxChange": self.reset_max_change,
            "SetJointsMaxTurnMax": lambda: self.set_turn_max(a),
            "SetJointsMaxTurnMin": lambda: self.set_turn_min(a),
            "SetSingleJointMaxTurnMax": lambda: single(self.set_single_turn_max),
            "SetSingleJointMaxTurnMin": lambda: single(self.set_single_turn_min),
            "ResetJointsMaxTurn": self.reset_turn,
            "SetMinChangeWeights": lambda: self.set_weights(a),
            "ResetMinChangeWeights": self.reset_weights,
            "SetAllowedStatus": lambda: self.set_allowed(words),
            "ResetAllowedStatus": self.reset_allowed,
            "SetRTSpeedControl": lambda: self.set_rt_speed_control(a[0]) if a else False,
            "SetKukaRTSpeed": lambda: self.set_kuka_rt_speed(a),
            # Adept V+ settings: the original answers true to anything (6.9); not modelled
            "SetAdeptSpeed": lambda: True,
            "SetAdeptAccel": lambda: True,
            "SetAdeptFine": lambda: True,
            "SetAdeptCoarse": lambda: True,
        }
        fn = table.get(command)
        return bool(fn()) if fn is not None else False

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> SettingsDict:
        return {
            "speed": list(self.speed),
            "accel": list(self.accel),
            "max_change": list(self.max_change),
            "turn_max": list(self.turn_max),
            "turn_min": list(self.turn_min),
            "weights": list(self.weights),
            "allowed": list(self.allowed),
            "rt_speed_control": int(self.rt_speed_control),
        }

    @classmethod
    def from_dict(cls, robot: RobotModel | str, data: Mapping[str, Any]) -> MotionSettings:
        config = cls(robot)
        config.update_from_dict(data)
        return config

    def update_from_dict(self, data: Mapping[str, Any]) -> None:
        for key in ("speed", "accel", "max_change", "turn_max", "turn_min", "weights"):
            if key in data:
                values = [float(v) for v in data[key]]
                if len(values) != N_JOINTS:
                    raise ValueError(f"{key}: expected {N_JOINTS} values, got {len(values)}")
                setattr(self, key, values)
        if "allowed" in data:
            try:
                self.allowed = list(parse_status(data["allowed"]))
            except ValueError as exc:
                raise ValueError(f"allowed: bad status pattern {data['allowed']!r}") from exc
        if "rt_speed_control" in data:
            self.rt_speed_control = int(data["rt_speed_control"])

    def copy(self) -> MotionSettings:
        return MotionSettings.from_dict(self.robot, self.to_dict())

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, MotionSettings) and self.robot.name == other.robot.name
                and self.to_dict() == other.to_dict())

    # mutable (the Set* commands change it), so unhashable, as Python makes any class with __eq__
    __hash__ = None  # type: ignore[assignment]  # typeshed declares object.__hash__ a method

    def __repr__(self) -> str:
        return f"MotionSettings({self.robot.name!r}, {self.to_dict()!r})"
