"""Robot models of the original rob6server: geometry, limits, defaults, status flags.

Every number here is from ``../shared/robots.md`` (measured on the original to 5e-7).
Units on the wire and here: millimetres and degrees; speeds in degrees per 12 ms
controller cycle, accelerations in degrees per cycle squared (the original's units).

This module is pure Python (no numpy) so that every service, the gateway included,
can use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The unit cycle of the protocol's speed/acceleration figures (not the driver rate).
UNIT_CYCLE_S = 0.012

# Standard DH chain shared by all robots (robots.md "Kinematic chain"):
# theta_i = s_i * q_i + o_i, twists alpha_i; T = A1..A6 * Ry(180 deg).
DH_SIGNS = (-1.0, 1.0, 1.0, -1.0, 1.0, -1.0)
DH_OFFSETS_DEG = (0.0, 0.0, -90.0, 0.0, 0.0, 0.0)
DH_ALPHA_DEG = (-90.0, 0.0, -90.0, 90.0, -90.0, 0.0)


#: Status words per category (hand, elbow, arm): the two explicit words, then the
#: word for "may change" and the word for "keep the current one".
STATUS_WORDS = (
    ("flip", "noflip", "toggleHand", "noToggleHand"),
    ("up", "down", "toggleElbow", "noToggleElbow"),
    ("lefty", "righty", "toggleArm", "noToggleArm"),
)
TOGGLE_ALL = ("toggleHand", "toggleElbow", "toggleArm")
NO_TOGGLE_ALL = ("noToggleHand", "noToggleElbow", "noToggleArm")
#: MovePTPHomRowWise takes no status: it chooses among these (the transcripts show it
#: never picks righty)
PTP_HOM_PATTERN = ("toggleHand", "toggleElbow", "lefty")


@dataclass(frozen=True)
class RobotModel:
    """One robot type as the original knew it."""

    name: str  # type name as given on the command line (kr16, kr16rt, ...)
    geometry: str  # which geometry/URDF it uses (kr16rt -> kr16)
    vendor: str  # "kuka" | "adept" | "kawasaki"
    rt: bool  # KUKA RSI real-time variant (kr3rt, kr16rt)
    # DH lengths (mm); robots.md table
    d1: float
    a1: float
    a2: float
    a3: float
    d4: float
    d6: float
    # default (software) turn limits, strict: min < q < max
    turn_min: tuple[float, ...]
    turn_max: tuple[float, ...]
    # hardware J2 maximum (the original overrides it with 20 for every robot);
    # used to fill the joints missing in a short ForwardCalc
    hw_j2_max: float
    # default max speed (deg / 12 ms cycle); the accepted upper bound is 10x this
    default_speed: tuple[float, ...]
    # driver cycle of the (simulated) controller, seconds
    cycle_s: float

    # ---- derived defaults -------------------------------------------------
    @property
    def default_accel(self) -> tuple[float, ...]:
        return (0.005,) * 6

    @property
    def max_accel_bound(self) -> float:
        return 0.02

    @property
    def speed_bound(self) -> tuple[float, ...]:
        return tuple(round(10.0 * v, 9) for v in self.default_speed)

    @property
    def default_max_change(self) -> tuple[float, ...]:
        return tuple(hi - lo for lo, hi in zip(self.turn_min, self.turn_max))

    @property
    def hw_min(self) -> tuple[float, ...]:
        return self.turn_min

    @property
    def hw_max(self) -> tuple[float, ...]:
        return (self.turn_max[0], self.hw_j2_max) + self.turn_max[2:]

    @property
    def opw(self) -> dict[str, float]:
        """OPW parameters (opw_kinematics convention), see robots.md."""
        return {
            "a1": self.a1,
            "a2": -self.a3,
            "b": 0.0,
            "c1": self.d1,
            "c2": self.a2,
            "c3": self.d4,
            "c4": self.d6,
        }

    # ---- identity answers of the protocol ----------------------------------
    @property
    def is_adept(self) -> bool:
        return self.vendor == "adept"

    @property
    def is_kuka(self) -> bool:
        return self.vendor == "kuka"

    @property
    def is_kawa(self) -> bool:
        return self.vendor == "kawasaki"

    @property
    def is_kr3(self) -> bool:
        return self.geometry == "kr3"

    @property
    def is_kr16(self) -> bool:
        return self.geometry == "kr16"

    # ---- status flags (robots.md "Status flags") ----------------------------
    def status(self, q: tuple[float, ...] | list[float]) -> tuple[str, str, str]:
        """Configuration of joints q (degrees): (flip|noflip, up|down, lefty|righty)."""
        q2, q3, q5 = (math.radians(q[1]), math.radians(q[2]), q[4])
        hand = "flip" if q5 < 0 else "noflip"
        elbow = "up" if self.d4 * math.sin(q3) - self.a3 * math.cos(q3) > 0 else "down"
        reach = (
            self.a1
            + self.a2 * math.cos(q2)
            + self.d4 * math.cos(q2 + q3)
            + self.a3 * math.sin(q2 + q3)
        )
        arm = "lefty" if reach > 0 else "righty"
        return hand, elbow, arm


def _kuka(name, geometry, rt, dh, tmin, tmax, hw_j2, speed, cycle):
    return RobotModel(name, geometry, "kuka", rt, *dh, tmin, tmax, hw_j2, speed, cycle)


_KR16 = dict(
    dh=(675.0, 260.0, 680.0, -35.0, 670.0, 158.0),
    tmin=(-185.0, -155.0, -130.0, -350.0, -125.0, -350.0),
    tmax=(185.0, 20.0, 154.0, 350.0, 125.0, 350.0),
    hw_j2=35.0,
    speed=(0.1872, 0.1872, 0.1872, 0.396, 0.396, 0.738),
)
_KR3 = dict(
    dh=(350.0, 100.0, 265.0, 0.0, 270.0, 75.0),
    tmin=(-180.0, -135.0, -135.0, -180.0, -135.0, -350.0),
    tmax=(180.0, 20.0, 135.0, 180.0, 135.0, 350.0),
    hw_j2=45.0,
    speed=(0.288, 0.252, 0.288, 0.45, 0.36, 0.45),
)

ROBOTS: dict[str, RobotModel] = {
    "kr16": _kuka("kr16", "kr16", False, cycle=0.012, **_KR16),
    # KUKA RSI real-time variants run a 4 ms interpolation cycle
    "kr16rt": _kuka("kr16rt", "kr16", True, cycle=0.004, **_KR16),
    "kr3": _kuka("kr3", "kr3", False, cycle=0.012, **_KR3),
    "kr3rt": _kuka("kr3rt", "kr3", True, cycle=0.004, **_KR3),
    # Adept Viper s850: V+ trajectory generator runs at 16 ms (ALTER period)
    "ad850": RobotModel(
        "ad850", "ad850", "adept", False,
        335.0, 75.0, 365.0, 90.0, 405.0, 80.0,
        (-170.0, -190.0, -119.0, -190.0, -120.0, -360.0),
        (170.0, 20.0, 169.0, 190.0, 120.0, 360.0),
        45.0,
        (0.3, 0.3, 0.3, 0.45, 0.45, 0.72),
        0.016,
    ),
    # Kawasaki FS03N: self-consistent a2 = +250 geometry (robots.md explains why);
    # E-controller interpolation runs at 16 ms
    "kaw_fs": RobotModel(
        "kaw_fs", "kaw_fs", "kawasaki", False,
        250.0, 120.0, 250.0, 0.0, 250.0, 80.0,
        (-160.0, -60.0, -150.0, -360.0, -135.0, -360.0),
        (160.0, 20.0, 120.0, 360.0, 135.0, 360.0),
        150.0,
        (0.432, 0.3, 0.27, 0.648, 0.27, 0.648),
        0.016,
    ),
}

ROBOT_TYPES = tuple(ROBOTS)


def get_robot(name: str) -> RobotModel:
    try:
        return ROBOTS[name]
    except KeyError:
        raise ValueError(
            f"unknown robot type {name!r}; known: {', '.join(ROBOT_TYPES)}"
        ) from None
