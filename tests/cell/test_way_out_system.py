"""Through the whole system: a robot that starts within a zone's margin is led out by PTP, LIN or Alter, and never further in.

On the simulation, a lab adds a table to its cell file 2 mm below the arm (the simulated
KR 16 starts at all joints 0, where the wrist is singular for LIN) and restarts rob6. On RSI,
the stand-in KR C4 holds the arm with the tool 2 mm above the table when rob6 starts, and
again after each restart of its program (the operator jogged it back). Before, every motion
was refused "at 0.00 s", even one straight away from the table.
"""

from __future__ import annotations

import socket
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from harness.client import Client
from harness.ports import free_port
from harness.system import System, running
from rob6.cell import CellModel
from rob6.cell.file import parse_cell
from rob6.robots import get_robot
from tests.cell.zone_rig import HOVER_S, rig
from tests.controllers.rsi_controller import SYSTEM_TIMEOUT, RsiController
from tests.motion.link_session import joints, wait_until
from tests.motion.test_rsi_realtime import POSITION_TOL, connected

pytestmark = pytest.mark.slow

ROBOT = "kr16"
WITHIN_MM = 2.0  # how far the arm starts above the table (the margin is 5 mm)
FAR_Z = -5000.0


def _table(z: float) -> str:
    return f"""\
margin_mm: 5
zones:
  - name: floor
    keep: out
    half_space: {{point: [0, 0, 0], normal: [0, 0, 1]}}
    ignore: [link_1]
  - name: table
    keep: out
    half_space: {{point: [0, 0, {z:.3f}], normal: [0, 0, 1]}}
    ignore: [link_1]
"""


def _model(text: str) -> CellModel:
    return CellModel(get_robot(ROBOT), parse_cell(text, "probe"))


def _cell_text() -> str:
    """A table top 2 mm below the arm's lowest part at all joints 0 but its column (measured
    with the top far below)."""
    model = _model(_table(FAR_Z))
    lowest = min(d for d, pair in zip(model.distances(np.zeros(6)), model.pairs, strict=True) if pair.other == "table")
    return _table(FAR_Z + lowest - WITHIN_MM)


def _a2(sign: float) -> list[float]:
    """A2 turned 6 deg: down onto the table (``sign`` < 0) or up from it (> 0; 2: 12 deg)."""
    model = _model(_cell_text())
    down = min((-1.0, 1.0), key=lambda s: model.nearest(np.eye(6)[1] * s * 6.0))
    return [float(v) for v in np.eye(6)[1] * 6.0 * down * -sign]


@pytest.fixture()
def started_near_the_wall(tmp_path: Path) -> Iterator[System]:
    cell = tmp_path / "cell.yaml"
    cell.write_text(_cell_text())
    with running(ROBOT, dummy=False, log_dir=str(tmp_path / "logs"), extra_env={"ROB6_CELL": str(cell)}) as system:
        yield system


def _joints(client: Client) -> list[float]:
    return [float(v) for v in client.ask("GetPositionJoints").split()]


def _answer(client: Client, line: str) -> str:
    first = client.ask(line, timeout=60)
    return first + client.read_lines(1) if first.startswith("ERROR") else first


def _fmt(values: list[float]) -> str:
    return " ".join(f"{v:.6f}" for v in values)


def _hold_target(client: Client, target: list[float], tol: float) -> None:
    """The way out is slow (250 mm/s at most): the arm gets there well after the stream's last
    target, so the client goes on sending it (as a streaming client does; the Alter watchdog
    stops an arm whose client fell silent) until the arm is there."""
    def there() -> bool:
        assert client.ask("MoveRTJoints " + _fmt(target)) == "true\n"
        return bool(np.allclose(_joints(client), target, atol=tol))
    wait_until(there, timeout=60.0, what="the arm to be out")


def _refused_deeper(client: Client) -> None:
    answer = _answer(client, "MovePTPJoints " + _fmt(_a2(-1.0)))
    assert answer.startswith("ERROR: ") and answer.endswith("\nfalse\n"), answer
    assert "'table'" in answer and "it may only move away from it" in answer
    assert _joints(client) == [0.0] * 6


@pytest.mark.parametrize("way", ["PTP", "Alter"])
def test_the_simulated_arm_is_led_out_and_never_further_in(started_near_the_wall: System, way: str) -> None:
    system = started_near_the_wall
    assert any("the robot is at a pose where" in line and "keep-out 'table', within the 5 mm margin" in line
               and "it may only move away from it" in line for line in system.output), system.output[-20:]
    with system.client() as client:
        _refused_deeper(client)
        up = _a2(1.0)
        if way == "PTP":
            assert _answer(client, "MovePTPJoints " + _fmt(up)) == "true\n"
            assert _joints(client) == pytest.approx(up, abs=1e-6)
        else:  # targets leading the arm up over 1 s, every 4 ms, then one down onto the table
            assert client.ask("EnableAlter") == "true\n"
            answer = _answer(client, "MoveRTJoints " + _fmt(_a2(-1.0)))
            assert answer.startswith("ERROR: target refused: ") and "to get out, move" in answer, answer
            for k in range(1, 251):
                assert client.ask(f"MoveRTJoints {_fmt([v * k / 250 for v in up])}") == "true\n"
            _hold_target(client, up, 1e-6)
            assert client.ask("DisableAlter", timeout=60) == "true\n"
            assert _joints(client) == pytest.approx(up, abs=1e-6)
        # out of the margin now: the normal rule again
        assert _answer(client, "MovePTPJoints " + _fmt([30.0, *_a2(2.0)[1:]])) == "true\n"


def test_an_rsi_linked_arm_standing_in_the_margin_is_led_out_by_ptp_lin_and_alter(tmp_path: Path) -> None:
    r = rig("kr16rt")
    inside, deeper, up = r.q(r.s_at(WITHIN_MM)), r.q(r.s_at(0.5)), r.q(HOVER_S)
    port = free_port(socket.SOCK_DGRAM)
    with running("kr16rt", dummy=False, log_dir=str(tmp_path / "logs"),
                 extra_env={"ROB6_LINK": "rsi", "ROB6_RSI_LISTEN": f"127.0.0.1:{port}",
                            "ROB6_CELL": str(r.write(tmp_path))}) as system, \
            RsiController("--start-pose", ",".join(f"{v:g}" for v in inside), rob6=("127.0.0.1", port),
                          robot="kr16rt", timeout=SYSTEM_TIMEOUT) as kuka, system.client() as client:
        for way in ("PTP", "LIN", "Alter"):
            if way != "PTP":
                kuka.restart(start=inside)  # the operator jogs it back into the margin
            assert np.allclose(connected(client, kuka, system), inside, atol=POSITION_TOL)
            wait_until(lambda: sum("back at a pose where tool tip" in line for line in system.output) >= 1,
                       timeout=10.0, what="the driver to say where the arm is")
            answer = _answer(client, "MovePTPJoints " + _fmt(deeper))
            assert answer.startswith("ERROR: ") and "it may only move away from it" in answer, answer
            if way == "PTP":
                assert _answer(client, "MovePTPJoints " + _fmt(up)) == "true\n"
            elif way == "LIN":
                pose = [float(x) for x in client.ask("GetPositionHomRowWise").split()]
                pose[11] += 50.0
                assert client.ask("EnableLin") == "true\n"
                assert _answer(client, "MoveLINHomRowWise " + _fmt(pose)) == "true\n"
                assert client.ask("DisableLin") == "true\n"
            else:
                assert client.ask("EnableAlter") == "true\n"
                answer = _answer(client, "MoveRTJoints " + _fmt(deeper))
                assert answer.startswith("ERROR: target refused: ") and "to get out, move tool tip" in answer, answer
                for k in range(1, 251):
                    target = [a + (b - a) * k / 250 for a, b in zip(inside, up, strict=True)]
                    assert client.ask("MoveRTJoints " + _fmt(target)) == "true\n"
                _hold_target(client, up, POSITION_TOL)
                assert client.ask("DisableAlter", timeout=60) == "true\n"
            here = joints(client)
            assert r.tip_clearance(np.array(here))[0] > 10.0, f"{way}: the tip is not out"
            assert np.allclose(here, kuka.status()["aipos"], atol=POSITION_TOL)
        assert not kuka.status()["trips"]
