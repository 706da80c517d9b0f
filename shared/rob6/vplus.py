"""V+ digital signals: which numbers the SIGNAL instruction may switch, and its argument list.

V+ numbers an Adept controller's digital signals (V+ Language Reference, ``SIGNAL`` and
``SIG``): external outputs 1-512 (a SmartController's XDIO outputs are 1-8), external
inputs 1001-1512, internal software signals 2001-2512. ``SIGNAL 5, -6`` turns output 5 on
and output 6 off: a positive number switches on, a negative one off, in the order given.

rob6 carries exactly this instruction to the Adept (``DirectAdeptCmd signal 5, -6``); every
number is checked here before anything is sent, so a malformed line switches nothing.
"""

from __future__ import annotations

import re

from .errors import RefusedError

OUTPUTS = range(1, 513)
INPUTS = range(1001, 1513)
SOFT_SIGNALS = range(2001, 2513)
#: signals one instruction may switch (each is one exchange with the controller)
MAX_SIGNALS = 32

_KEYWORD = re.compile(r"\s*signal\b", re.IGNORECASE)
_SEPARATOR = re.compile(r"\s*,\s*|\s+")
_NUMBER = re.compile(r"[+-]?\d+")


class SignalError(RefusedError, ValueError):
    """A SIGNAL instruction that cannot be carried out (the text says why)."""


def signal_problem(signal: int) -> str:
    """Why ``signal`` (V+ style: negative switches off) cannot be switched; "" when it can."""
    number = abs(signal)
    if number in OUTPUTS or number in SOFT_SIGNALS:
        return ""
    if number in INPUTS:
        return (f"signal {signal} is an input; only outputs ({OUTPUTS.start}-{OUTPUTS.stop - 1}) and "
                f"software signals ({SOFT_SIGNALS.start}-{SOFT_SIGNALS.stop - 1}) can be switched")
    return (f"signal {signal} is not a V+ output ({OUTPUTS.start}-{OUTPUTS.stop - 1}) or software "
            f"signal ({SOFT_SIGNALS.start}-{SOFT_SIGNALS.stop - 1})")


def check_signals(signals: list[int]) -> str:
    """Why this list cannot be switched as one SIGNAL instruction; "" when it can."""
    if not signals:
        return "SIGNAL needs at least one signal number"
    if len(signals) > MAX_SIGNALS:
        return f"SIGNAL with {len(signals)} signals; at most {MAX_SIGNALS} in one instruction"
    return next((problem for problem in map(signal_problem, signals) if problem), "")


def parse_signal(text: str) -> list[int] | None:
    """The signal numbers of ``SIGNAL n[, m ...]`` (keyword in any case, numbers separated by
    commas and/or blanks), or None when ``text`` is another V+ instruction. SignalError when
    it is a SIGNAL instruction that cannot be carried out."""
    keyword = _KEYWORD.match(text)
    if keyword is None:
        return None
    rest = text[keyword.end():].strip()
    signals: list[int] = []
    for token in _SEPARATOR.split(rest) if rest else []:
        if not token:
            raise SignalError(f"SIGNAL {rest}: an empty place between commas")
        if not _NUMBER.fullmatch(token):
            raise SignalError(f"SIGNAL {rest}: {token!r} is not a signal number")
        signals.append(int(token))
    problem = check_signals(signals)
    if problem:
        raise SignalError(problem)
    return signals
