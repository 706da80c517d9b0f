"""A busy robot PC: with four processes spinning at normal priority on the CPUs, a
client mixing reads, kinematics, PTP moves and one-second Alter bursts (250 Hz
MoveRTJoints, DisableAlter) for 20 s on the real-time kr16rt gets no ERROR reply and every
move, Alter target and mode change ``true``, as on a quiet machine. Nothing is timed."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.workload import cpu_hogs, mixed_session
from harness.system import running
from tests.flows.rigs import STARTS

pytestmark = pytest.mark.slow


def test_a_mixed_client_on_a_busy_machine_gets_no_error(tmp_path: Path) -> None:
    with running("kr16rt", dummy=False, log_dir=str(tmp_path)) as system, system.client(timeout=60) as client:
        with cpu_hogs(4):
            result = mixed_session(client, STARTS["kr16rt"], 20.0)
        assert client.ask("GetRobot") == "kr16rt\n"  # still in step
    assert result.errors == []
    assert result.moves >= 4 and result.moves_true == result.moves
    assert result.bursts >= 1
    assert len(result.samples["MoveRTJoints"]) == result.bursts * 250
