"""Safety zones through the whole system, for every robot type, as an old client sees them.

Each robot runs in real time with a cell of its own (``zone_rig``: a table under the tool,
self-collision on). A PTP through the table is refused before anything moves, one that
only ends near it moves, an Alter stream aimed 50 mm into it stops with the tool outside
at every recorded state, a self-colliding target is refused, IsPossible says why a pose is
not possible. The heights come from the closed-form kinematics, the states from the MCAP
recording.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest

from harness.client import Client
from harness.system import System, running
from tests.cell.zone_rig import HOVER_S, Rig, rig
from tests.motion.test_realtime_system import joint_states

pytestmark = pytest.mark.slow

ROBOTS = ("kr16", "kr16rt", "kr3", "kr3rt", "ad850", "kaw_fs")
#: a pose in which the arm runs into itself, per geometry (J1 turned away from the table)
SELF_COLLIDING = {"kr16": [150, 10, 145, 0, 0, 0], "kr3": [150, -130, -130, 0, -100, 0],
                  "ad850": [150, -5, 166, 0, -100, 0], "kaw_fs": [150, -55, -145, 0, -70, 0]}
PATH_ENTERS = re.compile(r"^ERROR: path enters keep-out 'table' at (\d+\.\d\d) s \(tool tip (\d+) mm inside\)\nfalse\n$")


@pytest.fixture(scope="module", params=ROBOTS)
def lab(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[System, Rig, Path]]:
    robot: str = request.param
    directory = tmp_path_factory.mktemp(robot)
    r = rig(robot)
    with running(robot, dummy=False, log_dir=str(directory / "logs"),
                 extra_env={"ROB6_CELL": str(r.write(directory))}) as system:
        yield system, r, directory / "logs"


def _joints(client: Client) -> list[float]:
    return [float(v) for v in client.ask("GetPositionJoints").split()]


def _move(client: Client, joints: list[float]) -> str:
    """A move's whole answer: ``true``/``false``, or an ``ERROR:`` line and ``false``."""
    first = client.ask("MovePTPJoints " + " ".join(f"{v:.6f}" for v in joints), timeout=60)
    return first + client.read_lines(1) if first.startswith("ERROR") else first


def _fmt(values: list[float]) -> str:
    return " ".join(f"{v:.6f}" for v in values)


def test_a_ptp_through_the_table_is_refused_and_nothing_moves(lab: tuple[System, Rig, Path]) -> None:
    system, r, _ = lab
    with system.client() as client:
        assert _move(client, r.q(HOVER_S)) == "true\n"
        before = _joints(client)
        answer = _move(client, r.q(r.s_at(-50.0)))
        assert PATH_ENTERS.match(answer), answer
        assert int(PATH_ENTERS.match(answer).group(2)) == pytest.approx(50, abs=3)  # type: ignore[union-attr]
        assert _joints(client) == before


def test_a_ptp_that_only_ends_near_the_table_moves(lab: tuple[System, Rig, Path]) -> None:
    system, r, _ = lab
    with system.client() as client:
        assert _move(client, r.q(HOVER_S)) == "true\n"
        target = r.q(r.s_at(20.0))
        assert _move(client, target) == "true\n"
        assert _joints(client) == pytest.approx(target, abs=1e-3)
        assert r.tip_clearance(np.array(_joints(client)))[0] == pytest.approx(20.0, abs=0.5)
        assert _move(client, r.q(HOVER_S)) == "true\n"


def test_is_possible_says_why_a_pose_in_the_table_is_not(lab: tuple[System, Rig, Path]) -> None:
    system, r, _ = lab
    with system.client() as client:
        inside = client.ask("ForwardCalc " + _fmt(r.q(r.s_at(-30.0))), lines=2).splitlines()
        near = client.ask("ForwardCalc " + _fmt(r.q(r.s_at(40.0))), lines=2).splitlines()
        assert client.ask(f"IsPossible {near[0]} {near[1]}") == "true\n"
        answer = client.ask(f"IsPossible {inside[0]} {inside[1]}", lines=2)
        assert re.match(r"^ERROR: pose in the cell's way: tool tip (2[89]|3[01]) mm inside keep-out 'table'\nfalse\n$",
                        answer), answer


def test_a_self_colliding_target_is_refused(lab: tuple[System, Rig, Path]) -> None:
    system, r, _ = lab
    target = [float(v) for v in SELF_COLLIDING[system.robot.removesuffix("rt")]]
    with system.client() as client:
        assert _move(client, [target[0], *r.q(HOVER_S)[1:]]) == "true\n"
        before = _joints(client)
        answer = _move(client, target)
        assert re.match(r"^ERROR: path collides \S+( tip)? with (base|link_\d) at \d+\.\d\d s \(\d+ mm deep\)\nfalse\n$",
                        answer), answer
        assert _joints(client) == before
        assert _move(client, r.q(HOVER_S)) == "true\n"


def _recorded_through(logs: Path, rest: Sequence[float], last: Sequence[float], timeout: float = 30.0) -> np.ndarray:
    """The recorded joint states, once the recording holds the arm at ``rest`` and ends at
    ``last`` (the recorder writes in batches, a little after the replies)."""
    deadline = time.monotonic() + timeout
    while True:
        _, states = joint_states(logs)
        if len(states) and np.abs(states - rest).max(axis=1).min() < 1e-4 and np.abs(states[-1] - last).max() < 1e-4:
            return states
        assert time.monotonic() < deadline, f"the recording lacks the rest at {rest} or the end at {last} after {timeout} s"
        time.sleep(0.2)


def test_an_alter_stream_aimed_50_mm_into_the_table_stops_outside_it(lab: tuple[System, Rig, Path]) -> None:
    """Targets every 4 ms from above the table to 50 mm inside it, over 2 s, as a client's
    real-time loop sends them: the ones within the margin are refused with the reason, the
    arm comes to rest outside, and no recorded state has the tool in the table."""
    system, r, logs = lab
    start, end = np.array(r.q(HOVER_S)), np.array(r.q(r.s_at(-50.0)))
    with system.client() as client:
        assert _move(client, r.q(HOVER_S)) == "true\n"
        assert client.ask("EnableAlter") == "true\n"
        t0 = time.monotonic()
        answers = []
        for k in range(1, 501):
            client.send(f"MoveRTJoints {_fmt((start + (end - start) * k / 500).tolist())}\n")
            first = client.read_lines(1)
            answers.append(first + (client.read_lines(1) if first.startswith("ERROR") else ""))
            time.sleep(max(0.0, t0 + 0.004 * k - time.monotonic()))  # the client's 4 ms loop
        assert client.ask("DisableAlter") == "true\n"  # answers once the arm is at rest
        rest = _joints(client)
        assert _move(client, r.q(HOVER_S)) == "true\n"
    refused = [a for a in answers if a != "true\n"]
    assert refused and answers[0] == "true\n"
    # the guard's stop (told with the next target), then the targets within the margin
    assert all(re.match(r"^ERROR: (target refused: |stopped before )tool tip \d+ mm (from|inside) keep-out 'table'.*\nfalse\n$", a)
               for a in refused), refused[:3]
    assert 0.0 < r.tip_clearance(np.array(rest))[0] < 20.0  # it came close, and stayed out
    states = _recorded_through(logs, rest, r.q(HOVER_S))
    assert len(states) > 250
    clearance = r.tip_clearance(states)
    print(f"{system.robot}: {len(states)} recorded states, the tool tip at least {clearance.min():.1f} mm "
          f"above the table ({len(refused)} of {len(answers)} targets refused)")
    assert clearance.min() > 0.0
