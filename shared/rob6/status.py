"""The robot's configuration words ("status"): parsing, pattern matching and the flags' formulas.

The robot's configuration ("status"): its words, how a pattern of them is read and
matched, and the flags' formulas (robots.md "Status flags"). The one home of these rules:
the gateway parses with it, the planner and the kinematics match and compute with it.

A *status* is three words, hand/elbow/arm: ``flip|noflip``, ``up|down``, ``lefty|righty``.
A *pattern* is three words too, one per category: an explicit word, ``toggle…`` (any) or
``noToggle…`` (the current one's). Pure Python (no numpy): the formulas take ``sin``/``cos``,
so the kinematics and the planner evaluate the same expressions on numpy arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Protocol

Status = tuple[str, str, str]

#: Status words per category (hand, elbow, arm): the two explicit words, then the
#: word for "may change" and the word for "keep the current one".
STATUS_WORDS = (
    ("flip", "noflip", "toggleHand", "noToggleHand"),
    ("up", "down", "toggleElbow", "noToggleElbow"),
    ("lefty", "righty", "toggleArm", "noToggleArm"),
)
TOGGLE_ALL = ("toggleHand", "toggleElbow", "toggleArm")
NO_TOGGLE_ALL = ("noToggleHand", "noToggleElbow", "noToggleArm")
#: MovePTPHomRowWise takes no status: it chooses among these (the transcripts show it
#: never picks righty)
PTP_HOM_PATTERN = ("toggleHand", "toggleElbow", "lefty")

_SLOT = {word: slot for slot, words in enumerate(STATUS_WORDS) for word in words}


def parse_status(words: Iterable[str]) -> Status:
    """1..3 status words in any order -> the (hand, elbow, arm) pattern; a category not
    given is ``toggle…``. A fourth word and beyond are ignored (as the original).

    ``ValueError`` for no word, an unknown or wrong-case word, or two words of one
    category (the protocol's ``ERROR: incorrect status``).
    """
    chosen: list[str | None] = [None, None, None]
    count = 0
    for word in words:
        if count == 3:
            break
        slot = _SLOT.get(word)
        if slot is None:
            raise ValueError(f"unknown status word {word!r}")
        if chosen[slot] is not None:
            raise ValueError(f"two {('hand', 'elbow', 'arm')[slot]} words")
        chosen[slot] = word
        count += 1
    if count == 0:
        raise ValueError("no status words")
    hand, elbow, arm = (word or TOGGLE_ALL[slot] for slot, word in enumerate(chosen))
    return hand, elbow, arm


def status_matches(pattern: Sequence[str], status: Sequence[str], current: Sequence[str]) -> bool:
    """Does ``status`` satisfy ``pattern``? Explicit words must match, ``toggle…`` admits
    anything, ``noToggle…`` requires the word of ``current`` (REFERENCE.md 6.4)."""
    for i in range(3):
        word = pattern[i]
        if word.startswith("toggle"):
            continue
        want = current[i] if word.startswith("noToggle") else word
        if status[i] != want:
            return False
    return True


# ---------------------------------------------------------------- flags
# The formulas work on floats (math) and, with numpy's sin/cos, on arrays: q2, q3 in
# radians, q5 in degrees.
Trig = Callable[[Any], Any]


class DhLengths(Protocol):
    """The DH lengths (mm) the flags depend on: a ``RobotModel`` or a kinematics geometry."""

    @property
    def a1(self) -> float: ...

    @property
    def a2(self) -> float: ...

    @property
    def a3(self) -> float: ...

    @property
    def d4(self) -> float: ...


def elbow_term(g: DhLengths, q3: Any, *, sin: Trig = math.sin, cos: Trig = math.cos) -> Any:
    """Positive: elbow ``up``; zero: the arm is stretched (elbow singularity)."""
    return g.d4 * sin(q3) - g.a3 * cos(q3)


def reach_term(g: DhLengths, q2: Any, q3: Any, *, sin: Trig = math.sin, cos: Trig = math.cos) -> Any:
    """The wrist centre's distance from the J1 axis, signed: positive ``lefty``; zero: the
    shoulder singularity."""
    return g.a1 + g.a2 * cos(q2) + g.d4 * cos(q2 + q3) + g.a3 * sin(q2 + q3)


def status_flags(g: DhLengths, q2: Any, q3: Any, q5: Any, *,
                 sin: Trig = math.sin, cos: Trig = math.cos) -> tuple[Any, Any, Any]:
    """(flip, up, lefty): true where the status is ``flip``, ``up``, ``lefty``."""
    return q5 < 0, elbow_term(g, q3, sin=sin, cos=cos) > 0, reach_term(g, q2, q3, sin=sin, cos=cos) > 0


def status_words(flip: bool, up: bool, lefty: bool) -> Status:
    """The words of the flags."""
    return "flip" if flip else "noflip", "up" if up else "down", "lefty" if lefty else "righty"
