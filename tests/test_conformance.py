"""Replay the original's transcripts (../shared/conformance) against a fresh rob6 per file."""

from __future__ import annotations

import pytest
from conformance import replay
from system import CONFORMANCE, running

ROBOTS = ("kr16", "ad850", "kaw_fs", "kr3rt", "kr16rt", "kr3")

#: transcript files rob6 replays (the rest is covered by the issue that implements it)
FILES = ("framing", "framing_wait", "management", "session", "misc", "adept_grippergohome",
         "adept_grippermove", "adept_grippermove_noarg", "adept_grippermovetopos", "adept_directcmd",
         "adept_directcmd_noarg", "debug_grippergohome")


def cases():
    for robot in ROBOTS:
        for name in FILES:
            path = CONFORMANCE / robot / f"{name}.jsonl"
            if path.exists():
                yield pytest.param(robot, path, id=f"{robot}-{name}")


@pytest.mark.parametrize("robot, path", list(cases()))
def test_transcript(robot, path):
    with running(robot) as system:
        result = replay(system, robot, path)
    assert result.checked > 0
    assert not result.failures, f"{len(result.failures)} of {result.checked} differ:\n" + "\n".join(result.failures[:20])
