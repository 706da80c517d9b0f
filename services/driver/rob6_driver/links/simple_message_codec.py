"""ROS-Industrial simple_message: the frames rob6's simple_message link sends and reads.

Written from the protocol's public definition (``simple_message`` in
ros-industrial/industrial_core: ``simple_message.h``, ``joint_traj_pt.h``,
``joint_data.h``, ``robot_status.h``), independently of any controller program or
simulator. A frame is

    int32 length (of what follows)
    int32 message type | int32 comm type | int32 reply code      (the header)
    body

with int32 and float32 fields in one byte order for the whole connection. The byte order
is not part of the protocol (each build of the library chooses it); the Adept V+ server
writes big-endian (``LNGB``/``FLTB``), hence the default.

Bodies rob6 uses:

* JOINT_TRAJ_PT (11): int32 sequence, float32 joints[10] (rad), float32 velocity
  (fraction of the maximum), float32 duration (s) -- 52 bytes. Special sequences:
  -1 start of a trajectory download, -2 start of streaming, -3 end of a trajectory,
  -4 stop.
* JOINT_POSITION (10): int32 sequence, float32 joints[10] (rad) -- 44 bytes.
* STATUS (13): int32 drives_powered, e_stopped, error_code, in_error, in_motion, mode,
  motion_possible -- 28 bytes; tri-states are 1 true, 0 false, -1 unknown; mode 1
  manual, 2 auto, -1 unknown.

A service reply (comm type 3) may carry any body (the Adept program sends one int32,
other programs echo the point): only its header matters.

The connection's opening (``opening``, ``opening_rest``): the Adept V+ program discards
the first four bytes it reads on a new motion connection, and whether those are the
client's first bytes or something V+ itself delivers on connecting cannot be told from
the program (deploy/adept/README.md section 4). The opening reads right either way: from
its first byte it is a stop (-4, answered -4, no motion) followed by the first word of a
second frame, whose remaining 64 bytes (``opening_rest``, another stop) are sent once the
-4 came; from its fifth byte it is a point at the arm's current joints (answered 0, a
MOVE that goes nowhere), after which the framing is right.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass

from rob6.errors import LinkError

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
# special JOINT_TRAJ_PT sequence numbers
START_TRAJECTORY_DOWNLOAD = -1
START_TRAJECTORY_STREAMING = -2
END_TRAJECTORY = -3
STOP_TRAJECTORY = -4
# tri-state values
TS_UNKNOWN = -1
TS_FALSE = 0
TS_TRUE = 1
MODE_MANUAL = 1
MODE_AUTO = 2

MAX_JOINTS = 10
PREFIX_SIZE = 4
HEADER_SIZE = 12
#: the largest frame the link accepts (the protocol's messages are all far smaller)
MAX_FRAME = 1024

MESSAGE_NAMES = {JOINT_POSITION: "JOINT_POSITION", JOINT_TRAJ_PT: "JOINT_TRAJ_PT", STATUS: "STATUS"}
BYTE_ORDERS = ("big", "little")


class SimpleMessageError(LinkError, ValueError):
    """A frame that cannot be read (the connection's framing is lost)."""


@dataclass(frozen=True)
class Header:
    msg_type: int
    comm_type: int
    reply_code: int


@dataclass(frozen=True)
class TrajPoint:
    sequence: int
    joints: tuple[float, ...]  # ten, radians
    velocity: float
    duration: float


@dataclass(frozen=True)
class JointPosition:
    sequence: int
    joints: tuple[float, ...]  # ten, radians


@dataclass(frozen=True)
class RobotStatus:
    drives_powered: int
    e_stopped: int
    error_code: int
    in_error: int
    in_motion: int
    mode: int
    motion_possible: int


@dataclass(frozen=True)
class Message:
    """One received frame: its header and, for the types rob6 reads, the parsed body."""

    header: Header
    body: bytes
    value: TrajPoint | JointPosition | RobotStatus | None = None


class Codec:
    """Packs and unpacks frames in one byte order (``big`` or ``little``)."""

    def __init__(self, byte_order: str = "big") -> None:
        if byte_order not in BYTE_ORDERS:
            raise ValueError(f"byte order {byte_order!r}: expected big or little")
        self.byte_order = byte_order
        e = ">" if byte_order == "big" else "<"
        self._int = struct.Struct(e + "i")
        self._header = struct.Struct(e + "3i")
        self._traj_pt = struct.Struct(e + f"i{MAX_JOINTS}fff")
        self._joint_position = struct.Struct(e + f"i{MAX_JOINTS}f")
        self._status = struct.Struct(e + "7i")
        other = "<" if e == ">" else ">"
        self._int_swapped = struct.Struct(other + "i")

    # ------------------------------------------------------------------ packing
    def frame(self, msg_type: int, comm_type: int, reply_code: int, body: bytes) -> bytes:
        return self._int.pack(HEADER_SIZE + len(body)) + self._header.pack(msg_type, comm_type, reply_code) + body

    def traj_pt(self, sequence: int, joints_rad: Iterable[float], velocity: float = 0.0, duration: float = 0.0,
                comm_type: int = SERVICE_REQUEST) -> bytes:
        """A JOINT_TRAJ_PT (a service request unless told otherwise); joints padded to ten."""
        body = self._traj_pt.pack(sequence, *_ten(joints_rad), velocity, duration)
        return self.frame(JOINT_TRAJ_PT, comm_type, INVALID, body)

    def joint_position(self, joints_rad: Iterable[float], sequence: int = 0) -> bytes:
        body = self._joint_position.pack(sequence, *_ten(joints_rad))
        return self.frame(JOINT_POSITION, TOPIC, INVALID, body)

    def status(self, status: RobotStatus) -> bytes:
        body = self._status.pack(status.drives_powered, status.e_stopped, status.error_code, status.in_error,
                                 status.in_motion, status.mode, status.motion_possible)
        return self.frame(STATUS, TOPIC, INVALID, body)

    def opening(self, joints_rad: Iterable[float]) -> bytes:
        """The 72 bytes a motion connection begins with (see the module's doc): as a
        JOINT_TRAJ_PT from byte 0 a stop, from byte 4 a point at ``joints_rad``."""
        words = [
            self._int.pack(HEADER_SIZE + self._traj_pt.size),  # read from byte 0: the length ...
            self._header.pack(JOINT_TRAJ_PT, SERVICE_REQUEST, SERVICE_REQUEST),  # ... from 4: length, type, comm
            self._int.pack(STOP_TRAJECTORY),  # from 0: the sequence (a stop); from 4: the reply code
            self._int.pack(0),  # from 0: joint 1 (ignored by a stop); from 4: the sequence
            struct.pack(self._int.format[0] + f"{MAX_JOINTS}ff", *_ten(joints_rad), 0.0),  # from 4: joints, velocity
            self._int.pack(HEADER_SIZE + self._traj_pt.size),  # from 4: the duration; from 0: the next length
        ]
        return b"".join(words)

    def opening_rest(self) -> bytes:
        """The rest of the opening when it was read from byte 0: a stop frame without its
        length word (that came with the opening)."""
        return self.traj_pt(STOP_TRAJECTORY, [])[PREFIX_SIZE:]

    def reply(self, msg_type: int, reply_code: int, body: bytes = b"") -> bytes:
        return self.frame(msg_type, SERVICE_REPLY, reply_code, body)

    # ------------------------------------------------------------------ unpacking
    def length(self, prefix: bytes) -> int:
        """The length prefix; SimpleMessageError when it cannot be a frame's (with a hint
        when the other byte order would make sense of it)."""
        n: int
        (n,) = self._int.unpack(prefix)
        if HEADER_SIZE <= n <= MAX_FRAME:
            return n
        (swapped,) = self._int_swapped.unpack(prefix)
        hint = ""
        if HEADER_SIZE <= swapped <= MAX_FRAME:
            other = "little" if self.byte_order == "big" else "big"
            hint = f" (read {other}-endian it would be {swapped}: is the byte order setting right?)"
        raise SimpleMessageError(f"frame length {n} is not possible{hint}")

    def split(self, buffer: bytearray) -> list[bytes]:
        """Take every complete frame's payload (header + body) off the front of ``buffer``."""
        out = []
        while len(buffer) >= PREFIX_SIZE:
            n = self.length(bytes(buffer[:PREFIX_SIZE]))
            if len(buffer) < PREFIX_SIZE + n:
                break
            out.append(bytes(buffer[PREFIX_SIZE:PREFIX_SIZE + n]))
            del buffer[:PREFIX_SIZE + n]
        return out

    def decode(self, payload: bytes) -> Message:
        """A frame's payload (after the length prefix) as a Message."""
        if len(payload) < HEADER_SIZE:
            raise SimpleMessageError(f"frame of {len(payload)} bytes is shorter than a header")
        header = Header(*self._header.unpack_from(payload))
        body = payload[HEADER_SIZE:]
        value = None
        if header.comm_type != SERVICE_REPLY:
            value = self._body(header.msg_type, body)
        return Message(header, body, value)

    def _body(self, msg_type: int, body: bytes) -> TrajPoint | JointPosition | RobotStatus | None:
        layout = {JOINT_TRAJ_PT: self._traj_pt, JOINT_POSITION: self._joint_position,
                  STATUS: self._status}.get(msg_type)
        if layout is None:
            return None
        if len(body) != layout.size:
            raise SimpleMessageError(f"{MESSAGE_NAMES[msg_type]} body of {len(body)} bytes, "
                                     f"expected {layout.size}")
        fields = layout.unpack(body)
        if msg_type == JOINT_TRAJ_PT:
            return TrajPoint(fields[0], tuple(fields[1:1 + MAX_JOINTS]), fields[-2], fields[-1])
        if msg_type == JOINT_POSITION:
            return JointPosition(fields[0], tuple(fields[1:]))
        return RobotStatus(*fields)

    def reply_sequence(self, body: bytes) -> int | None:
        """The first int32 of a reply's body (the Adept program answers the sequence there
        for a stop, 0 otherwise), or None when the body is shorter."""
        return self._int.unpack_from(body)[0] if len(body) >= 4 else None


def _ten(joints: Iterable[float]) -> list[float]:
    values = [float(x) for x in joints]
    if len(values) > MAX_JOINTS:
        raise ValueError(f"at most {MAX_JOINTS} joints, got {len(values)}")
    return values + [0.0] * (MAX_JOINTS - len(values))
