"""summary / export outputs (library and CLI)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from rob6_recorder.cli import main as cli
from rob6_recorder.inspect import command_word, summarize
from rob6_recorder.writer import Recorder
from tests.recording.rec_helpers import SESSION_LINES, Submitted, record_session


@pytest.fixture
def recording(tmp_path: Path, urdf: str) -> tuple[Path, list[Submitted]]:
    with Recorder(tmp_path / "rec", "kr16", "robot1", urdf=urdf) as rec:
        submitted = record_session(rec, session=3)
    (session,) = (tmp_path / "rec").glob("*_session3.mcap")
    return session, submitted


def test_summary(recording: tuple[Path, list[Submitted]]) -> None:
    path, submitted = recording
    s = summarize(path).as_dict()
    assert s["complete"] and s["robot"] == "kr16" and s["robot_id"] == "robot1"
    assert s["kind"] == "session"
    assert s["topics"]["/session/3/client_in"] == len(SESSION_LINES)
    assert s["topics"]["/driver/joint_state"] == 2 * len(SESSION_LINES)
    assert s["topics"]["/tf"] >= 1  # derived from the URDF (rate-limited to 50 Hz)
    assert s["records"] == sum(s["topics"].values())
    (sess,) = s["sessions"]
    assert sess["session"] == "3" and sess["lines"] == len(SESSION_LINES)
    assert sess["commands"]["GetRobot"] == 2 and sess["commands"]["MovePTPJoints"] == 3
    assert sess["commands"]["(empty)"] == 1
    assert sess["errors"] == 2  # "ERROR: Foo", "ERROR: incorrect joints\nfalse"
    assert sess["false"] == 3  # MovePTPJoints 0 20.., ForwardCalc x, MovePTPJoints 1 2 3
    assert sess["no_reply"] == 1  # the empty line
    assert sess["duration_s"] == pytest.approx((submitted[-1][1] - submitted[0][1]) / 1e9)
    assert sess["latency_ms"]["max"] > 0
    assert any(f["sent"] == "Foo\n" and f["reply"] == "ERROR: Foo\n" for f in sess["failures"])
    assert any("close" in e for e in sess["events"])


def test_summary_cli(recording: tuple[Path, list[Submitted]]) -> None:
    path, _ = recording
    runner = CliRunner()
    res = runner.invoke(cli, ["summary", str(path)])
    assert res.exit_code == 0, res.output
    assert "robot:     kr16 (id robot1), session recording" in res.output
    assert "session 3:" in res.output and "2 ERROR, 3 false" in res.output
    assert "GetRobot" in res.output and "/driver/joint_state" in res.output
    res = runner.invoke(cli, ["summary", "--json", str(path)])
    assert json.loads(res.output)["sessions"][0]["lines"] == len(SESSION_LINES)
    res = runner.invoke(cli, ["summary", str(path.parent / "missing.mcap")])
    assert res.exit_code == 2


def test_export_cli(recording: tuple[Path, list[Submitted]], tmp_path: Path) -> None:
    path, submitted = recording
    out = tmp_path / "csv"
    res = CliRunner().invoke(cli, ["export", str(path), "--csv", str(out)])
    assert res.exit_code == 0, res.output
    with open(out / "commands.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    ins = [r for r in rows if r["direction"] == "in"]
    assert [r["text"] + "\n" for r in ins] == SESSION_LINES
    assert all(r["session"] == "3" for r in rows)
    fc = [r for r in rows if r["direction"] == "out" and r["text"].startswith("0.000000 -0.173648")]
    assert fc and fc[0]["text"].endswith("\nnoflip up lefty")  # a two-line reply is one field
    assert rows[0]["time"].endswith("Z") and int(rows[0]["log_time_ns"]) == submitted[1][1]
    with open(out / "joint_states.csv", newline="") as fh:
        js = list(csv.DictReader(fh))
    assert len(js) == 2 * len(SESSION_LINES)
    assert [float(js[0][f"q{i}"]) for i in range(1, 7)] == [5.0, -5.0, 5.0, 5.0, 5.0, 5.0]
    assert js[-1]["cycle"] == str(2 * len(SESSION_LINES))
    with open(out / "log.csv", newline="") as fh:
        assert list(csv.DictReader(fh))[0]["message"] == "unknown command Foo"


def test_command_word() -> None:
    assert command_word("GetRobot\r\n") == "GetRobot"
    assert command_word(" \tForwardCalc 1 2") == "ForwardCalc"
    assert command_word("\n") == "(empty)"
    assert command_word("Get\0Robot\n") == "Get"
