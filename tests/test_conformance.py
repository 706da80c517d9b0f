"""Replay the original's transcripts (tests/transcripts) against a fresh rob6 per file."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from _pytest.mark import ParameterSet

from harness.system import running
from tests.conformance import CONFORMANCE, SHARED, replay

ROBOTS = ("kr16", "ad850", "kaw_fs", "kr3rt", "kr16rt", "kr3")


def cases() -> Iterator[ParameterSet]:
    """Every transcript of every robot type, each against a freshly started system."""
    for robot in ROBOTS:
        for path in sorted((CONFORMANCE / robot).glob("*.jsonl")):
            yield pytest.param(robot, path, id=f"{robot}-{path.stem}")


def test_every_robot_has_transcripts() -> None:
    """A missing or emptied transcript set is a failure, never a silently shorter suite."""
    counts = {robot: len(list((CONFORMANCE / robot).glob("*.jsonl"))) for robot in ROBOTS}
    assert all(counts.values()) and sum(counts.values()) >= 150, counts  # 150 when copied


def test_transcripts_match_the_ground_truth() -> None:
    """The copy kept with the tests is the ground truth's (when it is beside the project)."""
    truth = SHARED / "conformance"
    if not truth.is_dir():
        pytest.skip(f"no ground truth at {truth} to compare the copy with")
    ours = {p.relative_to(CONFORMANCE): p.read_bytes() for p in CONFORMANCE.rglob("*")
            if p.is_file() and p.name != "ORIGIN.md"}
    theirs = {p.relative_to(truth): p.read_bytes() for p in truth.rglob("*") if p.is_file()}
    assert ours == theirs, "tests/transcripts differs from ../shared/conformance: run `make transcripts`"


@pytest.mark.parametrize("robot, path", list(cases()))
def test_transcript(robot: str, path: Path) -> None:
    with running(robot) as system:
        result = replay(system, robot, path)
    assert result.checked > 0
    assert not result.failures, f"{len(result.failures)} of {result.checked} differ:\n" + "\n".join(result.failures[:20])
