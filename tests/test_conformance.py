"""Replay the original's transcripts (../shared/conformance) against a fresh rob6 per file."""

from __future__ import annotations

import pytest
from conformance import replay
from system import CONFORMANCE, running

ROBOTS = ("kr16", "ad850", "kaw_fs", "kr3rt", "kr16rt", "kr3")



def cases():
    """Every transcript of every robot type, each against a freshly started system."""
    for robot in ROBOTS:
        for path in sorted((CONFORMANCE / robot).glob("*.jsonl")):
            yield pytest.param(robot, path, id=f"{robot}-{path.stem}")


@pytest.mark.parametrize("robot, path", list(cases()))
def test_transcript(robot, path):
    with running(robot) as system:
        result = replay(system, robot, path)
    assert result.checked > 0
    assert not result.failures, f"{len(result.failures)} of {result.checked} differ:\n" + "\n".join(result.failures[:20])
