"""Argument parsing exactly as the original read its arguments (REFERENCE.md 3, 5).

The original read numbers like C++ ``istream >> double``: whitespace-separated,
parsing stops at the first character that does not belong to the number and the
rest of the token starts the next field (``10abc`` is 10, then a failure;
``2.5`` read as an int is 2 and ``.5`` is the next value). ``nan``, ``inf`` and
overflowing values (``1e400``) fail.

One deliberate difference: where the original waited for the next message when a
component was missing entirely, we fail at once with the same error the original
would eventually give (the client never hangs).
"""

from __future__ import annotations

import math
import re

from rob6.errors import InputError
from rob6.status import parse_status

WHITESPACE = " \t\r\n\v\f"
#: a number after the whitespace before it, in one match (twelve per BackwardCalc)
_NUMBER = re.compile(r"[ \t\r\n\v\f]*([+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?))")
_INTEGER = re.compile(r"[+-]?\d+")



class ParseError(InputError):
    """A malformed argument; ``what`` is the original's word (joints, matrix, status, value)."""

    def __init__(self, what: str):
        super().__init__(f"incorrect {what}")
        self.what = what


class Args:
    """A cursor over the text after the command word."""

    __slots__ = ("text", "pos")

    def __init__(self, text: str):
        self.text = text
        self.pos = 0

    def _skip(self) -> None:
        text, pos = self.text, self.pos
        while pos < len(text) and text[pos] in WHITESPACE:
            pos += 1
        self.pos = pos

    def at_end(self) -> bool:
        self._skip()
        return self.pos >= len(self.text)

    def double(self) -> float | None:
        match = _NUMBER.match(self.text, self.pos)
        if not match:
            self._skip()
            return None
        value = float(match.group(1))
        if math.isinf(value):  # istream fails on overflow
            return None
        self.pos = match.end()
        return value

    def integer(self) -> int | None:
        self._skip()
        match = _INTEGER.match(self.text, self.pos)
        if not match:
            return None
        self.pos = match.end()
        return int(match.group())

    def word(self) -> str | None:
        self._skip()
        start = self.pos
        text = self.text
        while self.pos < len(text) and text[self.pos] not in WHITESPACE:
            self.pos += 1
        return text[start:self.pos] or None

    # ---- components --------------------------------------------------------
    def doubles(self, n: int, what: str) -> list[float]:
        values = []
        for _ in range(n):
            value = self.double()
            if value is None:
                raise ParseError(what)
            values.append(value)
        return values

    def joints(self) -> list[float]:
        return self.doubles(6, "joints")

    def matrix(self) -> list[float]:
        return self.doubles(12, "matrix")

    def value(self) -> float:
        value = self.double()
        if value is None:
            raise ParseError("value")
        return value

    def index(self) -> int:
        value = self.integer()
        if value is None:
            raise ParseError("value")
        return value

    def leading_doubles(self, limit: int) -> list[float]:
        """As many numbers as parse, up to ``limit`` (ForwardCalc never fails on format)."""
        values: list[float] = []
        while len(values) < limit:
            value = self.double()
            if value is None:
                break
            values.append(value)
        return values

    def status(self) -> list[str]:
        """Up to three status words in any order; missing categories are ``toggle…``.

        Unknown or wrong-case words and two words of one category are an error; a
        fourth word is ignored. No word at all is an error too (the original waited
        for the next message).
        """
        words: list[str] = []
        while len(words) < 3 and not self.at_end():
            word = self.word()
            if word is None:
                raise ParseError("status")
            words.append(word)
        try:
            return list(parse_status(words))
        except ValueError:
            raise ParseError("status") from None
