"""Robot models of the original rob6server: geometry, limits, defaults, status flags.

Every number here is from ``../shared/robots.md`` (measured on the original to 5e-7).
Units on the wire and here: millimetres and degrees; speeds in degrees per 12 ms
controller cycle, accelerations in degrees per cycle squared (the original's units; their
SI equivalents: ``rob6.units``).

This module is pure Python (no numpy) so that every service, the gateway included,
can use it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .status import Status, status_flags, status_words

#: the arms' URDFs, one per geometry (written by rob6_kinematics.urdf)
URDF_DIR = Path(__file__).resolve().parent / "urdf"

# Standard DH chain shared by all robots (robots.md "Kinematic chain"):
# theta_i = s_i * q_i + o_i, twists alpha_i; T = A1..A6 * Ry(180 deg).
DH_SIGNS = (-1.0, 1.0, 1.0, -1.0, 1.0, -1.0)
DH_OFFSETS_DEG = (0.0, 0.0, -90.0, 0.0, 0.0, 0.0)
DH_ALPHA_DEG = (-90.0, 0.0, -90.0, 90.0, -90.0, 0.0)



@dataclass(frozen=True, kw_only=True)
class RobotModel:
    """One robot type as the original knew it (built by keyword: a dozen numbers that
    must not be confused)."""

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
        """The largest acceleration a client may set (deg per cycle^2, inclusive)."""
        return 0.02

    @property
    def default_weights(self) -> tuple[float, ...]:
        """Min-change weights at start-up (GetMinChangeWeights, ResetMinChangeWeights)."""
        return (4.0, 1.0, 1.0, 1.0, 1.0, 1.0)

    @property
    def speed_bound(self) -> tuple[float, ...]:
        return tuple(round(10.0 * v, 9) for v in self.default_speed)

    @property
    def default_max_change(self) -> tuple[float, ...]:
        return tuple(hi - lo for lo, hi in zip(self.turn_min, self.turn_max, strict=True))

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
    def urdf(self) -> str:
        """The arm's URDF: the live view's drawing, ROS 2's robot_description, the cell's model."""
        return (URDF_DIR / f"{self.geometry}.urdf").read_text()

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

    # ---- status flags (robots.md "Status flags"; the formulas: rob6.status) -------
    def status(self, q: Sequence[float]) -> Status:
        """Configuration of joints q (degrees): (flip|noflip, up|down, lefty|righty)."""
        return status_words(*status_flags(self, math.radians(q[1]), math.radians(q[2]), q[4]))


def _kuka(name: str, geometry: str, *, rt: bool, cycle_s: float) -> RobotModel:
    """A KUKA type: its geometry's numbers, its own name, variant and cycle."""
    return RobotModel(name=name, vendor="kuka", rt=rt, cycle_s=cycle_s, **_KUKA_GEOMETRIES[geometry])


_KUKA_GEOMETRIES: dict[str, dict[str, Any]] = {
    "kr16": dict(
        geometry="kr16",
        d1=675.0, a1=260.0, a2=680.0, a3=-35.0, d4=670.0, d6=158.0,
        turn_min=(-185.0, -155.0, -130.0, -350.0, -125.0, -350.0),
        turn_max=(185.0, 20.0, 154.0, 350.0, 125.0, 350.0),
        hw_j2_max=35.0,
        default_speed=(0.1872, 0.1872, 0.1872, 0.396, 0.396, 0.738),
    ),
    "kr3": dict(
        geometry="kr3",
        d1=350.0, a1=100.0, a2=265.0, a3=0.0, d4=270.0, d6=75.0,
        turn_min=(-180.0, -135.0, -135.0, -180.0, -135.0, -350.0),
        turn_max=(180.0, 20.0, 135.0, 180.0, 135.0, 350.0),
        hw_j2_max=45.0,
        default_speed=(0.288, 0.252, 0.288, 0.45, 0.36, 0.45),
    ),
}

ROBOTS: dict[str, RobotModel] = {
    "kr16": _kuka("kr16", "kr16", rt=False, cycle_s=0.012),
    # KUKA RSI real-time variants run a 4 ms interpolation cycle
    "kr16rt": _kuka("kr16rt", "kr16", rt=True, cycle_s=0.004),
    "kr3": _kuka("kr3", "kr3", rt=False, cycle_s=0.012),
    "kr3rt": _kuka("kr3rt", "kr3", rt=True, cycle_s=0.004),
    # Adept Viper s850: V+ trajectory generator runs at 16 ms (ALTER period)
    "ad850": RobotModel(
        name="ad850", geometry="ad850", vendor="adept", rt=False,
        d1=335.0, a1=75.0, a2=365.0, a3=90.0, d4=405.0, d6=80.0,
        turn_min=(-170.0, -190.0, -119.0, -190.0, -120.0, -360.0),
        turn_max=(170.0, 20.0, 169.0, 190.0, 120.0, 360.0),
        hw_j2_max=45.0,
        default_speed=(0.3, 0.3, 0.3, 0.45, 0.45, 0.72),
        cycle_s=0.016,
    ),
    # Kawasaki FS03N: self-consistent a2 = +250 geometry (robots.md explains why);
    # E-controller interpolation runs at 16 ms
    "kaw_fs": RobotModel(
        name="kaw_fs", geometry="kaw_fs", vendor="kawasaki", rt=False,
        d1=250.0, a1=120.0, a2=250.0, a3=0.0, d4=250.0, d6=80.0,
        turn_min=(-160.0, -60.0, -150.0, -360.0, -135.0, -360.0),
        turn_max=(160.0, 20.0, 120.0, 360.0, 135.0, 360.0),
        hw_j2_max=150.0,
        default_speed=(0.432, 0.3, 0.27, 0.648, 0.27, 0.648),
        cycle_s=0.016,
    ),
}

ROBOT_TYPES = tuple(ROBOTS)
#: the robot type rob6 drives when none is given (``--robot``, ``ROB6_ROBOT``)
DEFAULT_ROBOT = "kr16"


def get_robot(name: str) -> RobotModel:
    try:
        return ROBOTS[name]
    except KeyError:
        raise ValueError(
            f"unknown robot type {name!r}; known: {', '.join(ROBOT_TYPES)}"
        ) from None
