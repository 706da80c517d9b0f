"""The wire format of rob6's AS program for Kawasaki controllers, and the FS03N's joint convention.

The format is deploy/kawasaki/PROTOCOL.md, as the driver writes and reads it; the joints
are converted between rob6's convention and the controller's.

One message is one line of printable ASCII ended by LF (a CR before it is ignored), at
most ``MAX_LINE`` characters, fields separated by one or more spaces (AS pads numbers),
the first field a one-letter type. The driver sends ``P`` (a point) and ``C`` (cancel the queue); the
controller sends ``H`` (hello, once per connection) and ``A`` (the answer to every P and
C) on the program's port, and ``S`` (its state, at least every 100 ms) on the state port,
the next one up: a socket of its own, so a receive waiting on the first never holds it up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from rob6.errors import LinkError

from .wire_numbers import finite_float

PROTOCOL = "rob6-kas"
VERSION = 3
#: one message, LF included; AS strings hold 255 characters, the program keeps below that
MAX_LINE = 120
MAX_SEQUENCE = 999_999

#: the answer codes of ``A`` (0: taken)
ACK_CODES = {
    0: "accepted",
    1: "malformed message",
    2: "a joint outside the controller's range",
    3: "faster than an axis can move",
    4: "not ready (motor power off, teach mode or an error)",
    5: "queue full",
    6: "sequence number not above the last one",
}

# ---------------------------------------------------------------------- the FS03N's joints
#: controller joint (deg) = sign * rob6 joint (deg) + offset. The controller's JT2 = 0 has the
#: upper arm vertical (rob6: horizontal forward, hence +90), JT3 turns the other way round
#: (its 0 is the forearm in line with the upper arm, as rob6's), JT4..JT6 turn the other way
#: round; JT1 turns as rob6's q1 (clockwise seen from above). Derived from Kawasaki's own
#: arm descriptions and tested against an independent chain with the FS03N's lengths
#: (tests/kawasaki/test_kawasaki_convention.py, deploy/kawasaki/README.md).
TO_CONTROLLER_SIGN = np.array([1.0, 1.0, -1.0, -1.0, -1.0, -1.0])
TO_CONTROLLER_OFFSET_DEG = np.array([0.0, 90.0, 0.0, 0.0, 0.0, 0.0])
#: the FS03N's motion range, controller's convention (Kawasaki's data sheet), deg
CONTROLLER_MIN_DEG = np.array([-160.0, -60.0, -150.0, -360.0, -135.0, -360.0])
CONTROLLER_MAX_DEG = np.array([160.0, 150.0, 120.0, 360.0, 135.0, 360.0])
#: the FS03N's rated axis speeds, deg/s (rob6's robots.md): what the program refuses to exceed
RATED_SPEED_DEG_S = np.array([360.0, 250.0, 225.0, 540.0, 225.0, 540.0])
#: decimals of the joint values on the wire (deg)
WIRE_DECIMALS = 3


def to_controller_deg(q_rob6_deg: npt.ArrayLike) -> np.ndarray:
    q: np.ndarray = TO_CONTROLLER_SIGN * np.asarray(q_rob6_deg, float) + TO_CONTROLLER_OFFSET_DEG
    return q


def from_controller_deg(q_ctrl_deg: npt.ArrayLike) -> np.ndarray:
    q = (np.asarray(q_ctrl_deg, float) - TO_CONTROLLER_OFFSET_DEG) * TO_CONTROLLER_SIGN
    rounded: np.ndarray = np.round(q, WIRE_DECIMALS) + 0.0
    return rounded  # + 0.0: no -0.0


def outside_controller_range(q_rob6_deg: npt.ArrayLike) -> str:
    """"" when every joint is inside the controller's range, else which is not."""
    ctrl = to_controller_deg(q_rob6_deg)
    for j in range(6):
        if not CONTROLLER_MIN_DEG[j] <= ctrl[j] <= CONTROLLER_MAX_DEG[j]:
            return (f"joint {j + 1} at {float(np.asarray(q_rob6_deg)[j]):.3f} is JT{j + 1} {ctrl[j]:.3f} on the "
                    f"controller, outside its range {CONTROLLER_MIN_DEG[j]:g} .. {CONTROLLER_MAX_DEG[j]:g}")
    return ""


class KasError(LinkError, ValueError):
    """A line that is not a message of the protocol (the text says why)."""


@dataclass(frozen=True)
class Hello:
    capacity: int  # points the controller's queue holds


@dataclass(frozen=True)
class Ack:
    sequence: int
    code: int
    queued: int


@dataclass(frozen=True)
class State:
    count: int
    joints: tuple[float, ...]  # controller's convention, deg
    motor: bool  # motor power on (an E-stop switches it off: AS has no E-stop switch to report)
    teach: bool
    moving: bool
    queued: int
    done: int  # the sequence number of the last point the arm finished
    error: int  # controller error code, 0 none
    underruns: int  # times the queue ran dry before a final point
    running: bool = True  # the robot program (rob6_motion) runs: TASK(1) is 1 (not held, stopped, never started)


def point(sequence: int, q_rob6_deg: npt.ArrayLike, duration_s: float, final: bool) -> bytes:
    """A ``P`` line: the controller's joints (deg, 3 decimals), the time to reach them (ms)."""
    ctrl = to_controller_deg(q_rob6_deg)
    ms = max(1, min(99_999, round(duration_s * 1000)))
    joints = " ".join(_num(x) for x in ctrl)
    line = f"P {sequence} {joints} {ms} {1 if final else 0}\n"
    assert len(line) <= MAX_LINE, line
    return line.encode("ascii")


def cancel(sequence: int) -> bytes:
    return f"C {sequence}\n".encode("ascii")


def _num(x: float) -> str:
    text = f"{x:.{WIRE_DECIMALS}f}"
    return "0.000" if text == "-0.000" else text


def parse(line: bytes) -> Hello | Ack | State:
    """One line from the controller (without its LF) -> a message, or KasError."""
    if len(line) + 1 > MAX_LINE:
        raise KasError(f"a line of {len(line) + 1} characters (at most {MAX_LINE})")
    try:
        text = line.decode("ascii").rstrip("\r")
    except UnicodeDecodeError:
        raise KasError("a line that is not ASCII") from None
    fields = text.split()
    if not fields:
        raise KasError("an empty line")
    kind, args = fields[0], fields[1:]
    if kind == "H":
        if len(args) != 3 or args[0] != PROTOCOL:
            raise KasError(f"a hello that is not {PROTOCOL}: {text!r}")
        if _int(args[1], "version") != VERSION:
            raise KasError(f"protocol version {args[1]} (rob6 speaks {VERSION}): update the AS program")
        return Hello(_int(args[2], "capacity"))
    if kind == "A":
        if len(args) != 3:
            raise KasError(f"an answer with {len(args)} fields (3 expected): {text!r}")
        return Ack(_int(args[0], "sequence"), _int(args[1], "code"), _int(args[2], "queued"))
    if kind == "S":
        if len(args) != 15:
            raise KasError(f"a state with {len(args)} fields (15 expected): {text!r}")
        joints = tuple(_float(x) for x in args[1:7])
        motor, teach, moving = (_flag(x) for x in args[7:10])
        return State(_int(args[0], "count"), joints, motor=motor, teach=teach, moving=moving,
                     queued=_int(args[10], "queued"),
                     done=_int(args[11], "done"), error=_int(args[12], "error"),
                     underruns=_int(args[13], "underruns"), running=_flag(args[14]))
    raise KasError(f"an unknown message type {kind!r}")


def _int(text: str, what: str) -> int:
    if not text.lstrip("-").isdigit():
        raise KasError(f"{what} {text!r} is not an integer")
    return int(text)


def _float(text: str) -> float:
    try:
        return finite_float(text)
    except ValueError as why:
        raise KasError(f"joint {text!r} {why}") from None


def _flag(text: str) -> bool:
    if text not in ("0", "1"):
        raise KasError(f"flag {text!r} is not 0 or 1")
    return text == "1"
