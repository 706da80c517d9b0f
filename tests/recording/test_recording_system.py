"""Recording with the real system: a scripted session lands in MCAP with its correlation
ids, replays against the same system without differences and against another robot
type with differences, and survives a SIGKILL of the recorder; the cell the driver guards
and a motion it refused are in the files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import msgspec
from mcap.reader import make_reader

from harness.system import System, running
from rob6.cell import load_cell
from rob6.messages import Cell, Clearance
from rob6_recorder.reader import read_records
from tests.cell.zone_rig import HOVER_S
from tests.recording.rec_helpers import table_cell

SCRIPT = ["GetRobot", "ForwardCalc 10 -60 80 20 40 30", "MovePTPJoints 10 -60 80 20 40 30",
          "GetPositionJoints", "GetStatus", "BackwardCalc 1 0 0 1000 0 1 0 0 0 0 1 500 noflip up lefty",
          "SetJointsMaxSpeed 0.1 0.1 0.1 0.1 0.1 0.1", "GetJointsMaxSpeed", "SetVerbosity 3", "Foo"]
REPLY_LINES = {"ForwardCalc": 2}


def _session(system: System) -> None:
    with system.client() as client:
        for line in SCRIPT:
            client.ask(line, REPLY_LINES.get(line.split()[0], 1))
        assert client.ask("Quit") == "bye!\n"


def _session_file(directory: Path) -> Path:
    deadline = time.monotonic() + 10
    while True:
        files = sorted(directory.glob("*_session*.mcap"))
        if files or time.monotonic() > deadline:
            assert files, f"no session file in {directory}"
            return files[0]
        time.sleep(0.1)


def _replay(path: Path, port: int) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rob6_recorder.cli", "replay", str(path), "--to",
                           f"127.0.0.1:{port}", "--as-fast-as-possible"], capture_output=True, check=False, text=True,
                          timeout=120)


def test_session_recorded_replayed_and_compared(tmp_path: Path) -> None:
    with running("kr16", log_dir=str(tmp_path)) as system:
        _session(system)
        time.sleep(1.5)  # the session file is finished shortly after the client left
        path = _session_file(tmp_path)
        with open(path, "rb") as stream:  # a complete, indexed MCAP file
            summary = make_reader(stream).get_summary()
            assert summary is not None and summary.statistics is not None and summary.statistics.message_count > 0
        records = list(read_records(path))
        lines_in = [r for r in records if r.topic.endswith("/client_in")]
        assert [r.data["text"].rstrip("\n") for r in lines_in] == ["Hello Robot", *SCRIPT, "Quit"]
        cids = {r.data["cid"] for r in lines_in}
        forward = [r for r in records if r.topic == "/bus/kinematics/forward_calc/request"]
        assert forward and forward[0].data["cid"] in cids  # inner request tied to its client line
        moves = [r for r in records if r.topic == "/bus/driver/execute/request"]
        assert moves and moves[0].data["cid"] in cids  # gateway -> planner -> driver, one cid
        # log records travel with the traces (kept for a recorder that starts later)
        logs = [r.data for p in tmp_path.glob("*_system_*.mcap") for r in read_records(p, ["/log"])]
        assert any(r["service"] == "gateway" and r["message"].startswith("gateway listening on") for r in logs)
        # what is published live (rob6.bus.LIVE_TOPICS), not traced: the planner's settings
        # after SetJointsMaxSpeed, the gateway's verbosity after SetVerbosity
        assert [r.data["speed"] for r in read_records(path, ["/planner/config"])][-1:] == [[0.1] * 6]
        assert {"level": 3} in [r.data for r in read_records(path, ["/control/verbosity"])]
        same = _replay(path, system.port)
        assert same.returncode == 0, same.stdout + same.stderr
    with running("ad850", log_dir=str(tmp_path / "other")) as other:
        changed = _replay(path, other.port)
        assert changed.returncode == 1, changed.stdout + changed.stderr
        assert "kr16" in changed.stdout and "ad850" in changed.stdout


def test_recorder_killed_mid_session_leaves_a_readable_file(tmp_path: Path) -> None:
    with running("kr16", log_dir=str(tmp_path)) as system, system.client() as client:
        for _ in range(30):
            assert client.ask("GetRobot") == "kr16\n"
        time.sleep(1.5)  # over a second of records, chunks closed every 0.5 s
        killed_at = time.time()
        os.kill(system.pids()["recorder"], signal.SIGKILL)
        assert client.ask("CM_PING") == "PONG\n"  # the gateway does not depend on it
    for path in tmp_path.glob("*.mcap"):
        records = list(read_records(path))  # reads up to the last complete chunk
        assert records, f"{path.name} has no readable records"
        last = max(r.log_time for r in records) / 1e9
        assert killed_at - last < 1.0, f"{path.name}: {killed_at - last:.2f} s lost"


def test_the_cell_and_a_refused_motion_are_in_the_recording(tmp_path: Path) -> None:
    """The recorder asks the driver for its cell when it appears and records it on ``/cell``
    (schema ``rob6.Cell``) in the system file and in the session's; a PTP into the table is
    refused before anything moves, and the client's reply and the planner's say why."""
    table, cell_file = table_cell(tmp_path)
    into_table = " ".join(f"{q:g}" for q in table.q(table.s_at(-20.0)))
    with running("kr16", log_dir=str(tmp_path / "rec"), extra_env={"ROB6_CELL": str(cell_file)}) as system, \
            system.client() as client:
        assert client.ask("MovePTPJoints " + " ".join(f"{q:g}" for q in table.q(HOVER_S))) == "true\n"
        refused = client.ask(f"MovePTPJoints {into_table}", 2)
        assert refused.startswith("ERROR: path enters keep-out 'table' at ") and refused.endswith("\nfalse\n")
        assert client.ask("Quit") == "bye!\n"
    # read once the system stopped: the recorder stops last, every file finished
    expected = load_cell(cell_file)
    (session,) = (tmp_path / "rec").glob("*_session*.mcap")
    for path in [session, *(tmp_path / "rec").glob("*_system_*.mcap")]:
        records = list(read_records(path))
        cells = [r for r in records if r.topic == "/cell"]
        assert len(cells) == 1 and cells[0].schema == "rob6.Cell", path.name
        assert msgspec.convert(cells[0].data, Cell) == expected
        replies = [r.data["text"] for r in records if r.topic.endswith("/client_out")]
        assert refused in replies, path.name
        moves = [r.data["body"] for r in records if r.topic == "/bus/planner/move/reply"]
        assert refused.split("\n")[0] == f"ERROR: {moves[-1]['zone']}" and moves[-1]["ok"] is False
        clearances = [r for r in records if r.topic == "/driver/clearance"]  # while the arm moved to the table
        assert clearances and {r.schema for r in clearances} == {"rob6.Clearance"}
        assert all(msgspec.convert(r.data, Clearance).distance_mm > 0 for r in clearances)
