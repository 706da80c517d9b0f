"""Machine data of the simulated robots: the controller's own copy, as a KR C4 has its own.

Axis angles A1..A6 in degrees, speeds in degrees per second, lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Machine:
    name: str
    rated: tuple[float, ...]  # rated axis speeds, deg/s
    lower: tuple[float, ...]  # software limit switches (here: the hardware ranges)
    upper: tuple[float, ...]
    # KUKA's standard DH chain (see kinematics.py): d1, a1, a2, a3, d4, d6
    d1: float
    a1: float
    a2: float
    a3: float
    d4: float
    d6: float

    def range_width(self) -> tuple[float, ...]:
        return tuple(hi - lo for lo, hi in zip(self.lower, self.upper, strict=True))


# The KR 16 a KR C4 drives is the KR 16-2: axis ranges and speeds of ros-industrial/kuka_experimental
# kuka_kr16_support/urdf/kr16_2_macro.xacro (A5 +-130: rob6's kr16 stops at +-125, inside them).
_KR16: dict[str, Any] = dict(
    rated=(156.0, 156.0, 156.0, 330.0, 330.0, 615.0),
    lower=(-185.0, -155.0, -130.0, -350.0, -130.0, -350.0),
    upper=(185.0, 35.0, 154.0, 350.0, 130.0, 350.0),
    d1=675.0, a1=260.0, a2=680.0, a3=-35.0, d4=670.0, d6=158.0,
)
# The KR 3 a KR C4 drives is the KR 3 R540 (KR AGILUS): axis ranges and speeds of
# ros-industrial/kuka_experimental kuka_kr3_support/urdf/kr3r540_macro.xacro; its
# geometry (d1 345, a1 20, a2 260, a3 20, d4 260, d6 75) is that of the same robot.
_KR3: dict[str, Any] = dict(
    rated=(530.0, 529.0, 538.0, 600.0, 600.0, 800.0),
    lower=(-170.0, -170.0, -110.0, -175.0, -120.0, -350.0),
    upper=(170.0, 50.0, 155.0, 175.0, 120.0, 350.0),
    d1=345.0, a1=20.0, a2=260.0, a3=-20.0, d4=260.0, d6=75.0,
)

#: rob6's robot names: the cycle is the program's choice (RSI_ON #IPO_FAST or #IPO)
MACHINES: dict[str, Machine] = {
    "kr16": Machine("kr16", **_KR16),
    "kr16rt": Machine("kr16rt", **_KR16),
    "kr3": Machine("kr3", **_KR3),
    "kr3rt": Machine("kr3rt", **_KR3),
}

# where the arm stands at power-on by default: KUKA's usual home (upper arm vertical, forearm
# horizontal), inside every limit of both types
HOME = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
