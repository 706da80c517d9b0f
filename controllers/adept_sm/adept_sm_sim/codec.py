"""simple_message as the Adept V+ server writes and reads it.

A frame is a 4-byte length (of what follows), a header of three int32 (message type,
comm type, reply code) and a body; integers are int32, reals float32. The byte order
is a setting: the V+ program uses the big-endian LNGB/FLTB primitives as they are
(the ROS side links the ``_bswap`` simple_message library for it).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

# message types
JOINT_POSITION = 10
JOINT_TRAJ_PT = 11
STATUS = 13

# comm types
TOPIC = 1
SERVICE_REQUEST = 2
SERVICE_REPLY = 3

# reply codes
INVALID = 0
SUCCESS = 1
FAILURE = 2

# special sequence numbers of JOINT_TRAJ_PT
START_TRAJECTORY_DOWNLOAD = -1
START_TRAJECTORY_STREAMING = -2
END_TRAJECTORY = -3
STOP_TRAJECTORY = -4

MAX_JOINTS = 10
HEADER_LEN = 12
#: what the motion task reads per point, whatever the length word says (adept_ros.v2 lines
#: 558-573): length, type, comm type, reply code, sequence, ten joints, velocity, duration
RECORD_LEN = 4 + HEADER_LEN + 4 + 4 * MAX_JOINTS + 4 + 4

BYTE_ORDERS = {"big": ">", "little": "<"}


@dataclass(frozen=True)
class Record:
    """What the motion task takes of one record: it looks at the comm type, the sequence
    and the first six joints only."""

    comm_type: int
    sequence: int
    joints_rad: tuple[float, ...]  # all ten


class Codec:
    def __init__(self, byte_order: str = "big") -> None:
        if byte_order not in BYTE_ORDERS:
            raise ValueError(f"byte order must be one of {sorted(BYTE_ORDERS)}, not {byte_order!r}")
        e = BYTE_ORDERS[byte_order]
        self.byte_order = byte_order
        self._int = struct.Struct(e + "i")
        self._header = struct.Struct(e + "3i")
        self._record = struct.Struct(e + f"5i{MAX_JOINTS}fff")
        self._joints = struct.Struct(e + f"i{MAX_JOINTS}f")
        self._status = struct.Struct(e + "7i")

    def record(self, data: bytes) -> Record:
        """One ``RECORD_LEN``-byte record as the motion task reads it (LNGB, FLTB)."""
        _length, _msg_type, comm, _reply, seq, *rest = self._record.unpack(data)
        return Record(comm, seq, tuple(rest[:MAX_JOINTS]))

    def _frame(self, msg_type: int, comm_type: int, reply_code: int, body: bytes) -> bytes:
        return (
            self._int.pack(HEADER_LEN + len(body))
            + self._header.pack(msg_type, comm_type, reply_code)
            + body
        )

    def traj_reply(self, reply_code: int, sequence: int) -> bytes:
        """The V+ program's acknowledgement: header and one int32 (0, or -4 for a stop)."""
        return self._frame(JOINT_TRAJ_PT, SERVICE_REPLY, reply_code, self._int.pack(sequence))

    def joint_position(self, joints_rad: Sequence[float]) -> bytes:
        padded = tuple(joints_rad) + (0.0,) * (MAX_JOINTS - len(joints_rad))
        # the V+ program always sends sequence 0
        return self._frame(JOINT_POSITION, TOPIC, INVALID, self._joints.pack(0, *padded))

    def status(self, drives_powered: int, e_stopped: int, error_code: int, in_error: int, in_motion: int,
               mode: int, motion_possible: int) -> bytes:
        body = self._status.pack(drives_powered, e_stopped, error_code, in_error, in_motion,
                                 mode, motion_possible)
        return self._frame(STATUS, TOPIC, INVALID, body)
