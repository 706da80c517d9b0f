"""SIGKILL a process that is recording: the files stay readable up to the last closed
chunk, at most ~1 s is lost, and ``recover`` rebuilds indexed files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from rob6_recorder.cli import main as cli
from rob6_recorder.reader import RecordingReader, is_complete
from rob6_recorder.recover import recover, recover_unfinished
from tests.recording.rec_helpers import URDF

CHILD = textwrap.dedent("""
    import sys, time
    from rob6_recorder.writer import Recorder
    rec = Recorder(sys.argv[1], "kr16", "robot1", urdf=sys.argv[2])   # default settings
    rec.start()
    print("READY", flush=True)
    i = 0
    while True:
        now = time.time()
        rec.submit("/driver/joint_state", time.time_ns(),
                   {"seq": i, "wall": now, "q": [i * 0.001] * 6, "qd": [0.0] * 6})
        if i % 10 == 0:
            rec.submit("/session/7/client_in", time.time_ns(),
                       {"session": 7, "cid": f"c{i}", "text": "GetRobot\\n", "seq": i, "wall": now})
            rec.submit("/session/7/client_out", time.time_ns(),
                       {"session": 7, "cid": f"c{i}", "text": "kr16\\n", "seq": i, "wall": now})
        i += 1
        time.sleep(0.0005)
""")


def _kill_while_writing(directory: Path, after: float) -> float:
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(directory), URDF],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stderr is not None  # both are pipes
    try:
        assert proc.stdout.readline().strip() == "READY", proc.stderr.read()
        time.sleep(after)
        killed_at = time.time()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()
    return killed_at


@pytest.mark.parametrize("after", [0.15, 1.6])
def test_sigkill_mid_write_then_recover(tmp_path: Path, after: float) -> None:
    rec_dir = tmp_path / "rec"
    killed_at = _kill_while_writing(rec_dir, after)
    files = sorted(rec_dir.glob("*.mcap"))
    system = [p for p in files if "_system_" in p.name]
    assert len(system) == 1
    for path in files:
        assert not is_complete(path)  # the writer never finished it
        reader = RecordingReader(path)
        recs = list(reader.records())  # readable as is, up to the last closed chunk
        assert reader.report.error and not reader.report.complete
        assert reader.metadata["rob6"]["robot"] == "kr16"
        seqs = [r.data["seq"] for r in recs if r.topic == "/driver/joint_state"]
        first = 0 if path in system else (seqs[0] if seqs else 0)  # a session starts later
        assert seqs == list(range(first, first + len(seqs)))  # nothing missing in between
        walls = [r.data["wall"] for r in recs if isinstance(r.data, dict) and "wall" in r.data]
        if after > 1.0:
            assert walls, "a recording of 1.6 s must hold closed chunks"
            assert killed_at - max(walls) <= 1.0  # at most ~1 s lost
        # recover -> an indexed file the stock reader accepts
        out = tmp_path / (path.stem + ".recovered.mcap")
        result = recover(path, out)
        assert result.messages == len(recs)
        assert is_complete(out)
        with open(out, "rb") as fh:
            mreader = make_reader(fh, validate_crcs=True)
            summary = mreader.get_summary()
            assert summary is not None and summary.statistics is not None
            assert summary.statistics.message_count == len(recs)
            got = [(c.topic, m.log_time) for _, c, m in mreader.iter_messages(log_time_order=False)]
        assert got == [(r.topic, r.log_time) for r in recs]
        with open(out, "rb") as fh:
            mreader = make_reader(fh)
            assert [a.name for a in mreader.iter_attachments()] == ["robot.urdf"]
            assert {m.name for m in mreader.iter_metadata()} >= {"rob6", "rob6.recovered"}


def test_recover_cli_doctor_and_directory_sweep(tmp_path: Path) -> None:
    rec_dir = tmp_path / "rec"
    _kill_while_writing(rec_dir, 1.2)
    (system,) = rec_dir.glob("*_system_*.mcap")
    runner = CliRunner()
    res = runner.invoke(cli, ["doctor", str(system)])
    assert res.exit_code == 1 and "unfinished" in res.output or "truncated" in res.output
    res = runner.invoke(cli, ["recover", str(system)])
    assert res.exit_code == 0, res.output
    out = system.with_name(system.stem + ".recovered.mcap")
    assert "recovered:" in res.output and is_complete(out)
    res = runner.invoke(cli, ["doctor", str(out)])
    assert res.exit_code == 0 and "complete" in res.output
    out.unlink()

    results = recover_unfinished(rec_dir, min_age_s=0)
    assert len(results) == len(list(rec_dir.glob("*.mcap")))
    for path in rec_dir.glob("*.mcap"):
        assert is_complete(path)
        assert path.with_name(path.name + ".unfinished").exists()
    assert recover_unfinished(rec_dir, min_age_s=0) == []  # nothing left to do


def test_damaged_chunk_is_skipped(tmp_path: Path) -> None:
    from rob6_recorder.writer import Recorder

    with Recorder(tmp_path, "kr16", "robot1", chunk_interval=0.05, fsync=False) as rec:
        t = time.time_ns()
        for i in range(30):
            rec.submit("/driver/joint_state", t + i, {"seq": i, "q": [0] * 6})
            time.sleep(0.02)
    (path,) = tmp_path.glob("*.mcap")
    data = bytearray(path.read_bytes())
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[3]
    # flip bytes at the end of the 4th chunk's compressed data: its CRC check fails
    mid = chunk.chunk_start_offset + chunk.chunk_length - 6
    data[mid:mid + 4] = bytes(b ^ 0xFF for b in data[mid:mid + 4])
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    result = recover(broken, tmp_path / "fixed.mcap")
    assert result.scan.bad_chunks == 1 and result.scan.complete
    assert 0 < result.messages < 30
    seqs = [r.data["seq"] for r in RecordingReader(tmp_path / "fixed.mcap").records()
            if r.topic == "/driver/joint_state"]
    assert seqs == sorted(seqs) and seqs[-1] == 29  # the chunks after the damaged one are kept
    with open(tmp_path / "fixed.mcap", "rb") as fh:
        fixed = make_reader(fh, validate_crcs=True).get_summary()
    assert fixed is not None and fixed.statistics is not None
    assert fixed.statistics.message_count == result.messages
