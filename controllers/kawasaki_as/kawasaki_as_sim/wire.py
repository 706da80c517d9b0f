"""The rob6-kas protocol as the AS PC program reads and writes it: its own parser (no rob6 code).

Lines of printable ASCII ended by LF (CR before it ignored), at most 120 characters,
fields separated by one or more spaces (AS's number formats pad with spaces). In: ``P seq j1..j6 ms final`` and ``C seq``. Out: ``H``
(hello), ``A seq code queued`` (an answer to each P and C), ``S ...`` (the state).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MAX_LINE = 120
MAX_SEQUENCE = 999_999
MAX_MS = 99_999
HELLO = "H rob6-kas 1"

OK = 0
MALFORMED = 1
RANGE = 2
TOO_FAST = 3
NOT_READY = 4
QUEUE_FULL = 5
SEQUENCE = 6


class Malformed(ValueError):
    """A line the PC program cannot read (the text says why)."""


@dataclass(frozen=True)
class PointMsg:
    sequence: int
    joints: tuple[float, ...]  # controller's convention, deg
    ms: int
    final: bool


@dataclass(frozen=True)
class CancelMsg:
    sequence: int


def sequence_of(text: str) -> int:
    """The sequence number of a line, or 0 when it has none readable (for the answer)."""
    fields = text.split()
    if len(fields) >= 2 and fields[1].isdigit() and len(fields[1]) <= 6:
        return int(fields[1])
    return 0


def read(text: str) -> PointMsg | CancelMsg:
    """One line (no LF) -> a message, or Malformed."""
    fields = text.split()
    if not fields:
        raise Malformed("an empty line")
    kind = fields[0]
    if kind == "P":
        if len(fields) != 10:
            raise Malformed(f"a point has 10 fields, this has {len(fields)}")
        seq = _seq(fields[1])
        joints = tuple(_deg(x) for x in fields[2:8])
        if not fields[8].isdigit() or not 1 <= int(fields[8]) <= MAX_MS:
            raise Malformed(f"duration {fields[8]!r} is not 1..{MAX_MS} ms")
        if fields[9] not in ("0", "1"):
            raise Malformed(f"final flag {fields[9]!r} is not 0 or 1")
        return PointMsg(seq, joints, int(fields[8]), fields[9] == "1")
    if kind == "C":
        if len(fields) != 2:
            raise Malformed(f"a cancel has 2 fields, this has {len(fields)}")
        return CancelMsg(_seq(fields[1]))
    raise Malformed(f"unknown message type {kind!r}")


def _seq(text: str) -> int:
    if not text.isdigit() or not 1 <= int(text) <= MAX_SEQUENCE:
        raise Malformed(f"sequence {text!r} is not 1..{MAX_SEQUENCE}")
    return int(text)


def _deg(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise Malformed(f"joint {text!r} is not a number") from None
    if not math.isfinite(value) or "e" in text.lower():
        raise Malformed(f"joint {text!r} is not a plain decimal number")
    return value


def answer(sequence: int, code: int, queued: int) -> bytes:
    return f"A {sequence} {code} {queued}\n".encode("ascii")


def hello(capacity: int) -> bytes:
    return f"{HELLO} {capacity}\n".encode("ascii")


def state(count: int, joints: list[float], motor: bool, estop: bool, teach: bool, moving: bool,
          queued: int, done: int, error: int, underruns: int) -> bytes:
    js = " ".join(_fmt(x) for x in joints)
    flags = " ".join("1" if f else "0" for f in (motor, estop, teach, moving))
    line = f"S {count % 1_000_000} {js} {flags} {queued} {done} {error} {underruns}\n"
    return line.encode("ascii")


def _fmt(x: float) -> str:
    text = f"{x:.3f}"
    return "0.000" if text == "-0.000" else text
