"""Replay against a tiny fake TCP server: 0 differences when it answers like the
recording, a readable report and exit code 1 when it does not."""

from __future__ import annotations

import asyncio
import json
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from harness.fake_server import FakeServer, Handler
from rob6_recorder.cli import main as cli
from rob6_recorder.playback import replay_joints
from rob6_recorder.reader import read_records
from rob6_recorder.session_replay import (
    Script,
    compare_reply,
    load_script,
    load_transcript,
    replay,
)
from rob6_recorder.writer import Recorder
from tests.conformance import CONFORMANCE
from tests.recording.rec_helpers import REPLIES, SESSION_LINES, dict_handler, record_session


@pytest.fixture
def session_file(tmp_path: Path) -> Path:
    with Recorder(tmp_path / "rec", "kr16", "robot1", system=False) as rec:
        record_session(rec, session=3, step_ns=4_000_000)  # 1 ms between records
    (path,) = (tmp_path / "rec").glob("*_session3.mcap")
    return path


def test_load_recording(session_file: Path) -> None:
    (script,) = load_script(session_file)
    assert script.robot == "kr16" and script.greeting == "welcome to rob6server 0.1.01 !\n"
    assert [ex.send.decode() for ex in script.exchanges] == SESSION_LINES
    assert [ex.expected for ex in script.exchanges] == [REPLIES[line] for line in SESSION_LINES]
    assert script.handshake_recorded
    assert all(b.t > a.t for a, b in pairwise(script.exchanges))


def test_replay_identical_server_zero_differences(session_file: Path) -> None:
    with FakeServer(dict_handler(REPLIES)) as server:
        res = CliRunner().invoke(cli, ["replay", str(session_file), "--to",
                                       f"127.0.0.1:{server.port}", "--as-fast-as-possible"])
        assert res.exit_code == 0, res.output
        assert "0 difference(s)" in res.output
        assert f"{len(SESSION_LINES)} lines replayed" in res.output
        # the raw bytes, in order (the empty line included)
        assert [m.decode() for m in server.received] == SESSION_LINES


def test_replay_with_recorded_pacing(session_file: Path) -> None:
    with FakeServer(dict_handler(REPLIES)) as server:
        res = CliRunner().invoke(cli, ["replay", str(session_file), "--to",
                                       f"127.0.0.1:{server.port}", "--speed", "4"])
        assert res.exit_code == 0, res.output


def test_replay_reports_differences(session_file: Path) -> None:
    overrides = {
        # a number beyond the tolerance
        "ForwardCalc 10 0 0 0 0 0\n": REPLIES["ForwardCalc 10 0 0 0 0 0\n"].replace(
            "1741.140107", "1741.150107"),
        "GetRobot\n": "kr16rt\n",  # a word
        "SetAllowedStatus flip toggleElbow toggleArm\n": "true\n",  # a reply where none was
        "MovePTPJoints 1 2 3\n": "false\n",  # a line missing
        # within 1e-5: no difference
        "GetPositionJoints\n": "5.000001 -5.000000 5.000000 5.000000 5.000000 5.000000\n",
    }
    with FakeServer(dict_handler(REPLIES, overrides)) as server:
        res = CliRunner().invoke(cli, ["replay", str(session_file), "--to",
                                       f"127.0.0.1:{server.port}", "--as-fast-as-possible",
                                       "--no-progress"])
    assert res.exit_code == 1, res.output
    out = res.output
    assert "5 difference(s)" in out  # GetRobot twice
    assert "field 4: expected 1741.140107, got 1741.150107" in out
    assert "expected 'kr16', got 'kr16rt'" in out
    assert "expected 0 line(s), got 1" in out
    assert "expected 2 line(s), got 1" in out
    assert "> 'ForwardCalc 10 0 0 0 0 0'" in out and "cid=c003" in out


def test_replay_unreachable_server(session_file: Path) -> None:
    res = CliRunner().invoke(cli, ["replay", str(session_file), "--to", "127.0.0.1:1",
                                   "--no-progress"])
    assert res.exit_code == 2 and "cannot connect" in res.output


def test_replay_sends_handshake_when_not_recorded(tmp_path: Path) -> None:
    with Recorder(tmp_path, "kr16", "robot1", system=False) as rec:
        rec.submit("/session/1/client_in", 1_000, {"session": 1, "cid": "a", "text": "GetRobot\n"})
        rec.submit("/session/1/client_out", 2_000, {"session": 1, "cid": "a", "text": "kr16\n"})
    (path,) = tmp_path.glob("*.mcap")
    with FakeServer(dict_handler(REPLIES)) as server:
        res = CliRunner().invoke(cli, ["replay", str(path), "--to", f"127.0.0.1:{server.port}",
                                       "--as-fast-as-possible", "--robot", "kr16"])
        assert res.exit_code == 0, res.output
        assert [m.decode() for m in server.received] == ["Hello Robot\n", "GetRobot\n"]


def test_compare_reply_rules() -> None:
    assert compare_reply("GetRobot", "kr16\n", "kr16\n") is None
    assert compare_reply("X", "1.000000 2\n", "1.000004 2\n") is None
    assert compare_reply("X", "1.000000 2\n", "1.000004 2\n", tolerance=1e-6) is not None
    assert compare_reply("X", "-0.000000\n", "0.000000\n") is None
    assert compare_reply("GetTimestamp", "1795321511.114\n", "1.5\n") is None  # shape only
    assert compare_reply("PingRobot", "-1\n", "0.42\n") is None
    assert compare_reply("GetTimestamp", "1795321511.114\n", "x\n") is not None
    difference = compare_reply("X", "a b\n", "a  b\n")
    assert difference is not None and "whitespace" in difference
    assert compare_reply("X", "true\n", "") == "expected 1 line(s), got 0 (no reply)"


def _transcript_handler(path: Path) -> tuple[list[Script], Handler]:
    """Answer each connection from the transcript, one received chunk per record."""
    scripts = load_transcript(path)
    raw = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    per_conn: list[list[dict[str, Any]]] = []
    current: list[dict[str, Any]] | None = None
    for rec in raw:
        if rec.get("connect"):
            current = []
            per_conn.append(current)
        elif "send" in rec and current is not None:
            current.append(rec)
    cursor = [0] * len(per_conn)

    def handle(conn: int, msg: bytes) -> tuple[bytes, bool]:
        recs = per_conn[conn]
        rec = recs[cursor[conn]]
        cursor[conn] += 1
        assert msg.decode("latin-1") == rec["send"]
        return rec.get("reply", "").encode("latin-1"), bool(rec.get("then_closed"))

    return scripts, handle


def test_replay_conformance_transcript(tmp_path: Path) -> None:
    path = CONFORMANCE / "kr16" / "session.jsonl"
    if not path.exists():
        pytest.skip("conformance transcripts not available")
    scripts, handle = _transcript_handler(path)
    assert len(scripts) >= 3 and scripts[0].greeting == "welcome to rob6server 0.1.01 !\n"
    skipped = [ex for s in scripts for ex in s.exchanges if ex.expected is None]
    assert any(ex.send.startswith(b"SetAllowedStatus") for ex in skipped)
    with FakeServer(handle, per_line=False) as server:
        result = asyncio.run(replay(scripts, "127.0.0.1", server.port, speed=None, quiet=0.05))
    assert result.differences == [] and not result.aborted
    assert result.exchanges == sum(len(s.exchanges) for s in scripts)


def test_replay_joints_pacing(session_file: Path) -> None:
    got: list[dict[str, Any]] = []
    sleeps: list[float] = []
    now = [0.0]

    def sleep(dt: float) -> None:
        sleeps.append(dt)
        now[0] += dt

    n = replay_joints(session_file, got.append, speed=2.0, sleep=sleep, clock=lambda: now[0])
    assert n == 2 * len(SESSION_LINES) and got[0]["q"] == [5.0, -5.0, 5.0, 5.0, 5.0, 5.0]
    assert [g["cycle"] for g in got] == list(range(1, n + 1))
    # replayed at 2x: the (fake) clock ends at half the recorded span
    times = [r.log_time for r in read_records(session_file, ["/driver/joint_state"])]
    assert now[0] == pytest.approx((times[-1] - times[0]) / 1e9 / 2)
    assert len(sleeps) == n - 1
    fast: list[dict[str, Any]] = []
    assert replay_joints(session_file, fast.append, speed=None) == n


def test_replay_joints_cli(session_file: Path) -> None:
    res = CliRunner().invoke(cli, ["replay-joints", str(session_file), "--speed", "0"])
    assert res.exit_code == 0
    lines = [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]
    assert len(lines) == 2 * len(SESSION_LINES)
