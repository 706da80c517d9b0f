"""Offline replay of the original's kinematics transcripts against rob6_kinematics.

Only the kinematics commands are judged (ForwardCalc, BackwardCalc,
GetJointsRowWise, IsPossible, GetPositionHomRowWise, GetStatus); the commands that
change the state they depend on (MovePTPJoints, Set/Reset of turn limits and max
change) are tracked.  Arguments are parsed simply (C-like leading numbers, status
words); the real protocol parser is the gateway's.  A record with
``no_reply_within_ms`` and the record after it are skipped (conformance/README.md).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Set
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rob6.status import parse_status
from rob6_kinematics.calc import Kinematics

_NUM = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")

JOINT_TOL = 1e-5
J6_TOL = 5e-3
MATRIX_TOL = 2e-6

JUDGED = {
    "ForwardCalc",
    "BackwardCalc",
    "GetJointsRowWise",
    "IsPossible",
    "GetPositionHomRowWise",
    "GetStatus",
}


def leading_numbers(text: str, limit: int) -> tuple[list[float], str, bool]:
    """Parse up to ``limit`` whitespace-separated numbers like ``istream >> double``.

    Returns (numbers, rest_of_text, failed): ``failed`` is True when a token that
    is present does not start with a number (or only partially is one).
    """
    out: list[float] = []
    pos = 0
    while len(out) < limit:
        blanks = re.compile(r"\s*").match(text, pos)
        assert blanks is not None  # \s* matches anywhere
        pos = blanks.end()
        if pos >= len(text):
            return out, "", False
        m = _NUM.match(text, pos)
        if not m:
            return out, text[pos:], True
        v = float(m.group(0))
        if not np.isfinite(v):
            return out, text[pos:], True
        out.append(v)
        pos = m.end()
        if pos < len(text) and not text[pos].isspace():
            return out, text[pos:], True
    return out, text[pos:], False


def fmt(values: Iterable[float]) -> str:
    return " ".join("%f" % v for v in values)


@dataclass
class State:
    kin: Kinematics
    q: np.ndarray = field(default_factory=lambda: np.zeros(6))
    turn_min: np.ndarray | None = None
    turn_max: np.ndarray | None = None
    max_change: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.reset_turn()
        self.reset_change()

    def reset_turn(self) -> None:
        self.turn_min = self.kin.turn_min.copy()
        self.turn_max = self.kin.turn_max.copy()

    def reset_change(self) -> None:
        self.max_change = self.kin.max_change.copy()


def answer(st: State, line: str) -> str | None:
    """rob6's reply text for a judged command (None when not judged)."""
    k = st.kin
    cmd, _, args = line.strip("\r\n").partition(" ")
    cmd = cmd.strip()
    if cmd == "ForwardCalc":
        nums, _, _ = leading_numbers(args, 6)
        r = k.forward_calc(nums, st.turn_min, st.turn_max)
        if r is None:
            return "false\n"
        return fmt(r[0]) + "\n" + r[1] + "\n"
    if cmd in ("BackwardCalc", "GetJointsRowWise", "IsPossible"):
        nums, rest, failed = leading_numbers(args, 12)
        if len(nums) < 12:
            return "ERROR: incorrect matrix\nfalse\n"
        try:
            pattern = parse_status(rest.split())
        except ValueError:
            return "ERROR: incorrect status\nfalse\n"
        q = k.backward_calc(nums, pattern, st.q, st.turn_min, st.turn_max, st.max_change)
        if cmd == "IsPossible":
            return "true\n" if q is not None else "false\n"
        return "false\n" if q is None else fmt(q) + "\n"
    if cmd == "GetPositionHomRowWise":
        return fmt(k.fk(st.q)[0].reshape(12)) + "\n"
    if cmd == "GetStatus":
        return k.status(st.q) + "\n"
    return None


#: the commands with six values that ``track`` follows: the State field each one sets
SIX_VALUE_SETTERS = {
    "MovePTPJoints": "q",
    "SetJointsMaxChange": "max_change",
    "SetJointsMaxTurnMax": "turn_max",
    "SetJointsMaxTurnMin": "turn_min",
}


def track(st: State, line: str, reply: str) -> None:
    """Apply the state changes of a non-judged command that the original accepted."""
    cmd, _, args = line.strip("\r\n").partition(" ")
    ok = reply.strip() == "true"
    if not ok:
        return
    nums, _, _ = leading_numbers(args, 6)
    if cmd in SIX_VALUE_SETTERS and len(nums) == 6:
        setattr(st, SIX_VALUE_SETTERS[cmd], np.array(nums))
    elif cmd == "ResetJointsMaxChange":
        st.reset_change()
    elif cmd == "ResetJointsMaxTurn":
        st.reset_turn()


def same(expected: str, got: str) -> bool:
    """Compare two reply texts: numbers with the tolerances above, words exactly."""
    el, gl = expected.rstrip("\n").split("\n"), got.rstrip("\n").split("\n")
    if len(el) != len(gl):
        return False
    for e, g in zip(el, gl, strict=True):
        et, gt = e.split(), g.split()
        if len(et) != len(gt):
            return False
        try:
            ev = np.array([float(x) for x in et])
            gv = np.array([float(x) for x in gt])
        except ValueError:
            if e != g:
                return False
            continue
        tol: np.ndarray | float
        if len(ev) == 6:
            tol = np.array([JOINT_TOL] * 5 + [J6_TOL])
            d = np.abs(ev - gv)
            d = np.minimum(d, np.abs(360.0 - d))
        else:
            tol = MATRIX_TOL
            d = np.abs(ev - gv)
        if not np.all(d <= tol):
            return False
    return True


@dataclass
class Result:
    path: str
    lineno: int
    send: str
    expected: str
    got: str
    ok: bool

    @property
    def exact(self) -> bool:
        return self.expected == self.got

    def known_mismatch(self, kin: Kinematics) -> str | None:
        """Classify a mismatch the original's float noise explains (else None).

        * ``partial-status``: ForwardCalc with 1..5 numbers, matrix line identical,
          only the status line differs (robots.md: the status line is meaningless).
        * ``stretched-status``: ForwardCalc with 6 numbers whose elbow is exactly
          stretched (d4 sin q3 - a3 cos q3 == 0, i.e. q3 = 0 on kr3/kaw_fs):
          matrix identical, only the elbow word differs.  The original decides
          up/down there by rounding noise that depends on q2 (``ForwardCalc 0
          -134.999 0 0 0 0`` -> up, ``ForwardCalc 0 0 0 0 0 0`` -> down); rob6
          applies the formula (down).
        """
        if self.ok or not self.send.startswith("ForwardCalc"):
            return None
        el, gl = self.expected.split("\n"), self.got.split("\n")
        if len(el) < 2 or len(gl) < 2 or el[0] != gl[0]:
            return None
        nums, _, _ = leading_numbers(self.send[len("ForwardCalc"):], 6)
        if len(nums) < 6:
            return "partial-status"
        ew, gw = el[1].split(), gl[1].split()
        q3 = np.radians(nums[2])
        v = kin.g.d4 * np.sin(q3) - kin.g.a3 * np.cos(q3)
        if abs(v) < 1e-9 and ew[0] == gw[0] and ew[2] == gw[2]:
            return "stretched-status"
        return None


def replay(kin: Kinematics, path: Path, judge: Set[str] = JUDGED) -> list[Result]:
    st = State(kin)
    records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    out: list[Result] = []
    skip_next = False
    for i, rec in enumerate(records):
        if "send" not in rec:
            continue
        if skip_next:
            skip_next = False
            continue
        if "no_reply_within_ms" in rec:
            skip_next = True
            continue
        send, reply = rec["send"], rec["reply"]
        cmd = send.split()[0] if send.split() else ""
        if cmd in judge:
            got = answer(st, send)
            assert got is not None, f"rob6 cannot judge {cmd}"
            out.append(Result(str(path), i + 1, send.strip(), reply, got, same(reply, got)))
        else:
            track(st, send, reply)
    return out
