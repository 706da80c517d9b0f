"""Turning the client's byte stream into command lines.

Real clients send commands terminated by ``\\n``, by ``\\r\\n``, or not at all (one
command per write). The original treated every TCP read as one command, which
breaks as soon as TCP splits or merges writes. rob6 instead:

* answers every ``\\n``-terminated line as a command (one trailing ``\\r`` removed),
  several in one read in order;
* takes an unterminated chunk as a command once no further byte arrives within a
  short pause (``pause_s``, a few milliseconds);
* ends a line at a NUL byte, like the original's C strings;
* bounds a line (``max_line``): a longer one is answered with an error and dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

MAX_LINE = 64 * 1024


@dataclass
class Line:
    text: str  # latin-1 decoded, terminator removed, cut at the first NUL
    too_long: int = 0  # >0: the line was dropped, this many bytes long


class Framer:
    def __init__(self, max_line: int = MAX_LINE):
        self.max_line = max_line
        self._buffer = bytearray()
        self._dropping = 0  # bytes of an over-long line discarded so far

    def feed(self, data: bytes) -> list[Line]:
        """Complete lines in ``data`` (plus what was buffered)."""
        lines: list[Line] = []
        buffer = self._buffer
        buffer += data
        start = 0
        while True:
            end = buffer.find(b"\n", start)
            if end < 0:
                break
            if self._dropping:
                lines.append(Line("", too_long=self._dropping + end - start + 1))
                self._dropping = 0
            elif end - start > self.max_line:
                lines.append(Line("", too_long=end - start + 1))
            else:
                lines.append(Line(_clean(bytes(buffer[start:end]))))
            start = end + 1
        del buffer[:start]
        if len(buffer) > self.max_line:  # no terminator in sight: drop, remember the size
            self._dropping += len(buffer)
            buffer.clear()
        return lines

    def pending(self) -> bool:
        return bool(self._buffer) or bool(self._dropping)

    def flush(self) -> list[Line]:
        """The unterminated rest, after the pause: one command."""
        if self._dropping:
            size, self._dropping = self._dropping + len(self._buffer), 0
            self._buffer.clear()
            return [Line("", too_long=size)]
        if not self._buffer:
            return []
        text = _clean(bytes(self._buffer))
        self._buffer.clear()
        return [Line(text)]


def _clean(raw: bytes) -> str:
    if raw.endswith(b"\r"):
        raw = raw[:-1]
    nul = raw.find(b"\0")
    if nul >= 0:
        raw = raw[:nul]
    return raw.decode("latin-1")
