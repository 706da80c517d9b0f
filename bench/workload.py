"""A lab client's mixed workload on a running rob6, and CPU hogs to run it on a busy machine.

The mix is what a followme-style client does all day: reads (GetPositionJoints, GetStatus),
kinematics (ForwardCalc, BackwardCalc, IsPossible), PTP moves between two poses and, every
third round, a one-second Alter burst (MoveRTJoints at 250 Hz, each sent when the last was
answered) ended by DisableAlter. Every reply is judged: an ``ERROR:`` line, or a move,
Alter target or mode change not answered ``true``, is an error. Used by the benchmarks
(``bench/busy.py``) and the busy-machine test (tests/flows), outside the product: no service ships it.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field

from harness.client import Client

#: a busy process at normal priority: what a lab's other programs do to a robot PC
HOG = "while True: pass"
#: Alter burst: targets per second and seconds per burst
ALTER_HZ = 250
ALTER_BURST_S = 1.0
#: how long a late remainder of an error reply (its ``false``) may take to arrive
ERROR_TAIL_S = 0.05


@dataclass
class MixResult:
    """What one mixed session measured."""

    seconds: float = 0.0
    #: command word -> round trip of each (s), send to the last line of the reply
    samples: dict[str, list[float]] = field(default_factory=dict)
    #: (line, reply) of every reply that was an error or not the expected ``true``
    errors: list[tuple[str, str]] = field(default_factory=list)
    moves: int = 0  # PTP moves sent
    moves_true: int = 0  # of which answered true
    bursts: int = 0  # Alter bursts, each ended by DisableAlter

    def errors_of(self, word: str) -> int:
        return sum(1 for line, _ in self.errors if line.split()[0] == word)


@contextmanager
def cpu_hogs(count: int) -> Iterator[list[subprocess.Popen[bytes]]]:
    """``count`` processes spinning on the CPU at normal priority; killed on the way out."""
    hogs: list[subprocess.Popen[bytes]] = []
    try:
        for _ in range(count):
            hogs.append(subprocess.Popen([sys.executable, "-c", HOG], stdin=subprocess.DEVNULL))
        yield hogs
    finally:
        for hog in hogs:
            hog.kill()
        for hog in hogs:
            hog.wait()


class _Mix:
    def __init__(self, client: Client, result: MixResult) -> None:
        self.client = client
        self.result = result

    def ask(self, line: str, lines: int = 1, expect: str | None = None) -> list[str]:
        """Send ``line`` and read its ``lines`` lines, timed; an ERROR reply is taken whole
        (with the ``false`` some errors end with) so the next reply stays in step."""
        started = time.perf_counter()
        self.client.send(line + "\n")
        text = self.client.read_lines(lines)
        elapsed = time.perf_counter() - started
        if text.count("\n") < lines:
            raise TimeoutError(f"{line!r}: no complete reply within {self.client.timeout} s (got {text!r})")
        if text.startswith("ERROR") or "\nERROR" in text:
            text += self.client.read_quiet(ERROR_TAIL_S)
        self.result.samples.setdefault(line.split(maxsplit=1)[0], []).append(elapsed)
        reply = text.splitlines()
        if "ERROR" in text or (expect is not None and reply != [expect]):
            self.result.errors.append((line, text))
        return reply

    def alter_burst(self, start: Sequence[float]) -> None:
        self.result.bursts += 1
        self.ask("EnableAlter", expect="true")
        began = time.perf_counter()
        count = int(ALTER_HZ * ALTER_BURST_S)
        for k in range(count):
            q = list(start)
            q[0] += 2.0 * math.sin(2 * math.pi * k / count)
            self.ask("MoveRTJoints " + _fmt(q), expect="true")
            delay = began + (k + 1) / ALTER_HZ - time.perf_counter()  # paced, as an Alter client streams
            if delay > 0:
                time.sleep(delay)
        self.ask("DisableAlter", expect="true")

    def move(self, target: Sequence[float]) -> None:
        self.result.moves += 1
        if self.ask("MovePTPJoints " + _fmt(target), expect="true") == ["true"]:
            self.result.moves_true += 1


def mixed_session(client: Client, start: Sequence[float], seconds: float) -> MixResult:
    """Run the mix for about ``seconds`` (the round under way is finished) from ``start``,
    between ``start`` and ``start`` with A1 +10 deg; the client is already past the handshake."""
    result = MixResult()
    mix = _Mix(client, result)
    other = list(start)
    other[0] += 10.0
    began = time.perf_counter()
    mix.move(start)
    rounds = 0
    while time.perf_counter() - began < seconds:
        for target in (other, start):
            mix.ask("GetPositionJoints")
            mix.ask("GetStatus")
            forward = mix.ask("ForwardCalc " + _fmt(target), 2)
            if len(forward) == 2 and not forward[0].startswith("ERROR"):
                pose, status = forward
                mix.ask(f"BackwardCalc {pose} {status}")
                mix.ask(f"IsPossible {pose} {status}", expect="true")
            mix.move(target)
        rounds += 1
        if rounds % 3 == 0:  # the robot is at start again
            mix.alter_burst(start)
    result.seconds = time.perf_counter() - began
    return result


def _fmt(values: Sequence[float]) -> str:
    return " ".join(f"{x:f}" for x in values)
