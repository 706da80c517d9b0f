"""The protocol's motion units and their SI equivalents, one conversion for planner and driver.

The protocol's motion units and their SI equivalents: one conversion for the planner's
trajectories and the driver's limit monitor, so both enforce the same numbers.

The protocol gives speeds in degrees per 12 ms *unit* cycle and accelerations in degrees per
unit cycle squared, whatever the robot's own controller cycle (robots.md). Jerk has no
protocol setting: it is chosen so that the acceleration ramps from 0 to its maximum in
``JERK_RAMP_S`` (4 unit cycles).
"""

from __future__ import annotations

from collections.abc import Iterable

#: The unit cycle of the protocol's speed/acceleration figures (not the driver rate).
UNIT_CYCLE_S = 0.012
#: time for the acceleration to go from 0 to its maximum (defines the jerk limit)
JERK_RAMP_S = 0.048


def speed_si(speed: Iterable[float]) -> list[float]:
    """deg per unit cycle -> deg/s."""
    return [float(v) / UNIT_CYCLE_S for v in speed]


def accel_si(accel: Iterable[float]) -> list[float]:
    """deg per unit cycle squared -> deg/s^2."""
    return [float(a) / UNIT_CYCLE_S**2 for a in accel]


def jerk_si(accel: Iterable[float], jerk_ramp_s: float = JERK_RAMP_S) -> list[float]:
    """The jerk limit (deg/s^3) of acceleration limits in deg/s^2."""
    return [float(a) / jerk_ramp_s for a in accel]
