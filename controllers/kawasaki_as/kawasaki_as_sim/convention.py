"""rob6's kaw_fs joints versus the FS03N controller's, as the simulator's status reports them.

The controller (AS, degrees): JT1 = q1, JT2 = q2 + 90 (its 0 is the upper arm vertical),
JT3 = -q3, JT4 = -q4, JT5 = -q5, JT6 = -q6 (deploy/kawasaki/README.md). Only for the
control channel's ``position_rob6_deg`` and ``--start-pose``; the wire carries the
controller's own angles.
"""

from __future__ import annotations

SIGN = (1.0, 1.0, -1.0, -1.0, -1.0, -1.0)
OFFSET = (0.0, 90.0, 0.0, 0.0, 0.0, 0.0)


def to_controller(q_rob6: tuple[float, ...] | list[float]) -> tuple[float, ...]:
    return tuple(s * q + o for s, q, o in zip(SIGN, q_rob6, OFFSET, strict=True))


def to_rob6(q_ctrl: tuple[float, ...] | list[float]) -> tuple[float, ...]:
    return tuple((q - o) * s + 0.0 for s, q, o in zip(SIGN, q_ctrl, OFFSET, strict=True))
