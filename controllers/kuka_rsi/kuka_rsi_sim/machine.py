"""Machine data of the simulated robots: the controller's own copy, as a KR C4 has its own.

Axis angles A1..A6 in degrees, speeds in degrees per second, lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Machine:
    name: str
    ipo_ms: int  # RSI cycle: 4 ms with RSI_ON(#ABSOLUTE, #IPO_FAST), 12 ms with #IPO
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


_KR16: dict[str, Any] = dict(
    rated=(156.0, 156.0, 156.0, 330.0, 330.0, 615.0),
    lower=(-185.0, -155.0, -130.0, -350.0, -125.0, -350.0),
    upper=(185.0, 35.0, 154.0, 350.0, 125.0, 350.0),
    d1=675.0, a1=260.0, a2=680.0, a3=-35.0, d4=670.0, d6=158.0,
)
_KR3: dict[str, Any] = dict(
    rated=(240.0, 210.0, 240.0, 375.0, 300.0, 375.0),
    lower=(-180.0, -135.0, -135.0, -180.0, -135.0, -350.0),
    upper=(180.0, 45.0, 135.0, 180.0, 135.0, 350.0),
    d1=350.0, a1=100.0, a2=265.0, a3=0.0, d4=270.0, d6=75.0,
)

MACHINES: dict[str, Machine] = {
    "kr16": Machine("kr16", 12, **_KR16),
    "kr16rt": Machine("kr16rt", 4, **_KR16),
    "kr3": Machine("kr3", 12, **_KR3),
    "kr3rt": Machine("kr3rt", 4, **_KR3),
}

# KUKA's usual home (upper arm vertical, forearm horizontal): inside every limit of both types
HOME = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
