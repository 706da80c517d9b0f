"""MotionSettings against the original's limits/limits_bounds/misc transcripts (offline).

A tiny argument splitter stands in for the gateway's parser: numbers are read like C++
``istream >> int`` / ``>> double`` (``2.5`` as an index is 2 and ``.5`` is the next
value). Lines it cannot read are answered by the gateway with ``ERROR: incorrect …``;
here they only have to leave the state unchanged. A command the original left waiting
for its arguments is merged with the argument line that followed (as the original
did), so later ``Get…`` replies still compare.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pytest import CaptureFixture

from rob6.status import parse_status
from rob6_planner.config import MotionSettings
from tests.conformance import CONFORMANCE

ROBOTS = ("kr16", "kr16rt", "kr3rt", "ad850", "kaw_fs")
SCRIPTS = ("limits", "limits_bounds", "misc")

_DOUBLE = re.compile(r"[ \t]*([+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?))")
_INT = re.compile(r"[ \t]*([+-]?\d+)")

GETTERS = {
    "GetJointsMaxSpeed": "speed",
    "GetJointsMaxAcceleration": "accel",
    "GetJointsMaxChange": "max_change",
    "GetJointsMaxTurnMax": "turn_max",
    "GetJointsMaxTurnMin": "turn_min",
    "GetMinChangeWeights": "weights",
}
SIX = ("SetJointsMaxSpeed", "SetJointsMaxAcceleration", "SetJointsMaxChange",
       "SetJointsMaxTurnMax", "SetJointsMaxTurnMin", "SetMinChangeWeights")
SINGLE = ("SetSingleJointMaxSpeed", "SetSingleJointMaxAcceleration", "SetSingleJointMaxChange",
          "SetSingleJointMaxTurnMax", "SetSingleJointMaxTurnMin")
RESETS = ("ResetJointsMaxSpeed", "ResetJointsMaxAcceleration", "ResetJointsMaxChange",
          "ResetJointsMaxTurn", "ResetMinChangeWeights", "ResetAllowedStatus")
KNOWN = set(GETTERS) | set(SIX) | set(SINGLE) | set(RESETS) | {
    "GetAllowedStatus", "SetAllowedStatus", "GetRTSpeedControl", "SetRTSpeedControl",
    "SetKukaRTSpeed", "GetRobot", "Quit", "Hello"}


class Cursor:
    def __init__(self, text: str):
        self.text, self.pos = text, 0

    def _read(self, pattern: re.Pattern[str]) -> str | None:
        m = pattern.match(self.text, self.pos)
        if not m:
            return None
        self.pos = m.end()
        return m.group(1)

    def double(self) -> float | None:
        s = self._read(_DOUBLE)
        if s is None or math.isinf(float(s)):
            return None
        return float(s)

    def integer(self) -> int | None:
        s = self._read(_INT)
        return None if s is None else int(s)


def parse(cmd: str, rest: str) -> tuple[list[Any], list[str]] | None:
    """-> (args, words) or None when the gateway would answer ``ERROR: incorrect …``."""
    c = Cursor(rest)
    if cmd in SIX or cmd == "SetKukaRTSpeed":
        values = [c.double() for _ in range(6)]
        return None if None in values else (values, [])
    if cmd in SINGLE:
        j = c.integer()
        v = c.double() if j is not None else None
        return None if v is None else ([j, v], [])
    if cmd == "SetRTSpeedControl":
        n = c.integer()
        return None if n is None else ([n], [])
    if cmd == "SetAllowedStatus":
        words = rest.split()
        try:
            parse_status(words)
        except ValueError:
            return None
        return [], words
    return [], []


def fmt(values: Iterable[float]) -> str:
    return " ".join(f"{v:f}" for v in values) + "\n"


def records(path: Path) -> Iterator[tuple[str, str]]:
    """(command line, reply) pairs with waiting commands merged with their argument line."""
    recs = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    recs = [r for r in recs if "send" in r]
    i = 0
    while i < len(recs):
        r = recs[i]
        line = r["send"].strip()
        if "no_reply_within_ms" in r and i + 1 < len(recs):
            nxt = recs[i + 1]["send"].strip()
            first = nxt.split()[0] if nxt.split() else ""
            if first not in KNOWN and not line.startswith("SetAllowedStatus "):
                yield line + " " + nxt, recs[i + 1]["reply"]
                i += 2
                continue
        yield line, r.get("reply", "")
        i += 1


def replay(robot: str, script: str) -> tuple[dict[str, int], list[tuple[str, str, str]]]:
    config = MotionSettings(robot)
    stats = {"get_match": 0, "get_mismatch": 0, "set_match": 0, "set_mismatch": 0,
             "parse_error": 0, "skipped": 0}
    mismatches: list[tuple[str, str, str]] = []
    for line, reply in records(CONFORMANCE / robot / f"{script}.jsonl"):
        parts = line.split(None, 1)
        if not parts:
            continue
        cmd, rest = parts[0], (parts[1] if len(parts) > 1 else "")
        if cmd in GETTERS or cmd in ("GetAllowedStatus", "GetRTSpeedControl"):
            if cmd == "GetAllowedStatus":
                ours = " ".join(config.allowed) + "\n"
            elif cmd == "GetRTSpeedControl":
                ours = f"{config.rt_speed_control}\n"
            else:
                ours = fmt(getattr(config, GETTERS[cmd]))
            key = "get_match" if ours == reply else "get_mismatch"
            if ours != reply:
                mismatches.append((line, reply, ours))
            stats[key] += 1
            continue
        if not (cmd in SIX or cmd in SINGLE or cmd in RESETS
                or cmd in ("SetAllowedStatus", "SetRTSpeedControl", "SetKukaRTSpeed")):
            stats["skipped"] += 1
            continue
        if cmd == "SetKukaRTSpeed" and not config.robot.rt:
            ours = "true\n" if config.apply(cmd) else "false\n"  # arguments never read
        else:
            if not rest.strip() and cmd not in RESETS:
                stats["skipped"] += 1  # bare command: the original waited (rob6 answers at once)
                continue
            parsed = parse(cmd, rest)
            if parsed is None:
                before = config.to_dict()
                stats["parse_error"] += 1
                if reply == "":  # the original waited for the missing value (rob6: error at once)
                    continue
                assert reply.startswith("ERROR: incorrect"), (line, reply)
                assert config.to_dict() == before
                continue
            ok = config.apply(cmd, *parsed)
            if cmd == "SetAllowedStatus":
                ours = "" if ok else "ERROR: incorrect status\n"
            else:
                ours = "true\n" if ok else "false\n"
        key = "set_match" if ours == reply else "set_mismatch"
        if ours != reply:
            mismatches.append((line, reply, ours))
        stats[key] += 1
    return stats, mismatches


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("robot", ROBOTS)
def test_transcript(robot: str, script: str) -> None:
    stats, mismatches = replay(robot, script)
    assert not mismatches, mismatches[:5]
    assert stats["get_match"] + stats["set_match"] > 10
    print(robot, script, stats)


def test_totals(capsys: CaptureFixture[str]) -> None:
    total: dict[str, int] = {}
    for robot in ROBOTS:
        for script in SCRIPTS:
            stats, _ = replay(robot, script)
            for k, v in stats.items():
                total[k] = total.get(k, 0) + v
    with capsys.disabled():
        print("\nMotionConfig transcript replay:", total)
    assert total["get_mismatch"] == 0 and total["set_mismatch"] == 0
