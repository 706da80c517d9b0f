"""The Viper s850's joints as the controller knows them, and how rob6's joints map onto them.

The V+ server sends and takes the controller's own joint angles (``DECOMPOSE`` of
``HERE`` out, ``#PPOINT`` in), converted between degrees and radians and nothing else.
rob6 (rob6server) uses its own convention for every robot: q1 positive clockwise seen
from above, q = 0 the arm stretched forward horizontally. The two differ in signs and
one offset; the table below was checked by forward kinematics against the published
ROS-Industrial Viper URDF (whose joints are the controller's) and is consistent with
both joint-range tables.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

N_JOINTS = 6

#: controller joint (deg) = ROB6_TO_CONTROLLER_SIGN[i] * rob6 joint (deg)
#:                          + ROB6_TO_CONTROLLER_OFFSET_DEG[i]
#: The controller's J1 turns counter-clockwise seen from above (rob6's clockwise),
#: its J3 = 0 has the forearm pointing up (rob6: stretched forward, hence +90),
#: and J4/J6 turn the other way. On the wire the controller's values are in radians.
ROB6_TO_CONTROLLER_SIGN = (-1.0, 1.0, 1.0, -1.0, 1.0, -1.0)
ROB6_TO_CONTROLLER_OFFSET_DEG = (0.0, 0.0, 90.0, 0.0, 0.0, 0.0)

#: Joint ranges in the controller's convention, degrees, inclusive (the controller's
#: soft limits): the ROS-Industrial Viper URDF's joint limits (adept_experimental,
#: adept_viper_s650_support/urdf/viper_s650_macro.xacro lines 129-169, radians): J3 up to
#: 256 deg, where rob6's own ad850 table (J3 -119..169) would map to 259.
CONTROLLER_LIMITS_DEG = (
    (-170.0, 170.0),
    (-190.0, 45.0),
    (-29.0, 256.0),
    (-190.0, 190.0),
    (-120.0, 120.0),
    (-360.0, 360.0),
)

#: Rated joint speeds of the Viper s850, deg/s (V+ "SPEED 100" at monitor speed 100).
MAX_SPEED_DEG_S = (250.0, 250.0, 250.0, 375.0, 375.0, 600.0)

#: Seconds from rest to full speed at 100 % (``ACCEL 100``): Adept publishes no joint
#: accelerations; 0.25 s is plausible for the Viper and is the stand-in's default
#: (``--accel-time``), a figure a first session measures (deploy/adept/README.md section 6).
ACCEL_TIME_S = 0.25

#: E-stop: the controller brakes as hard as it can, from full speed to rest in 0.1 s.
ESTOP_DECEL_DEG_S2 = tuple(10.0 * v for v in MAX_SPEED_DEG_S)

#: float32 on the wire rounds radians to ~1e-7 rad; a point exactly at a limit stays legal
LIMIT_TOL_DEG = 1e-4


def rob6_to_controller(q_rob6_deg: Iterable[float]) -> tuple[float, ...]:
    return tuple(
        s * q + o
        for s, q, o in zip(ROB6_TO_CONTROLLER_SIGN, q_rob6_deg, ROB6_TO_CONTROLLER_OFFSET_DEG, strict=True)
    )


def controller_to_rob6(q_ctrl_deg: Iterable[float]) -> tuple[float, ...]:
    return tuple(
        (q - o) / s
        for s, q, o in zip(ROB6_TO_CONTROLLER_SIGN, q_ctrl_deg, ROB6_TO_CONTROLLER_OFFSET_DEG, strict=True)
    )


def limit_violation(q_ctrl_deg: Iterable[float]) -> str | None:
    """Why the controller would not move to these joints (controller degrees), or None."""
    for i, (q, (lo, hi)) in enumerate(zip(q_ctrl_deg, CONTROLLER_LIMITS_DEG, strict=True), start=1):
        if not math.isfinite(q):
            return f"joint {i} is not a number"
        if q < lo - LIMIT_TOL_DEG or q > hi + LIMIT_TOL_DEG:
            return f"joint {i} at {q:.3f} deg is outside the controller range [{lo:g}, {hi:g}]"
    return None
