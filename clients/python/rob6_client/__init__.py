"""Python client of rob6 and the original rob6server (TCP port 5005, line-based text protocol).

    from rob6_client import Robot

    with Robot("127.0.0.1", 5005) as robot:
        pose, status = robot.forward_calc([10, 0, 0, 0, 0, 0])
        robot.move_ptp_joints([10, -60, 80, 20, 40, 30])

Standard library only. ``AsyncRobot`` is the asyncio twin with the same methods.
"""

from .aio import AsyncRobot
from .client import DEFAULT_PORT, Robot
from .errors import Rob6ConnectionError, Rob6Error, Rob6ProtocolError, Rob6Timeout
from .protocol import (
    ANY_STATUS,
    COMMANDS,
    ROB6_ONLY,
    Joints,
    PingResult,
    Pose,
    Status,
    normalize_status,
    parse_reply,
)

__all__ = [
    "ANY_STATUS", "AsyncRobot", "COMMANDS", "DEFAULT_PORT", "Joints", "PingResult", "Pose", "ROB6_ONLY", "Robot",
    "Rob6ConnectionError", "Rob6Error", "Rob6ProtocolError", "Rob6Timeout", "Status",
    "normalize_status", "parse_reply",
]
__version__ = "0.1.0"
