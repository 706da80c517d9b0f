"""Recorder and its native writer: content, order, schemas, rotation, drop accounting, errors."""

from __future__ import annotations

import gc
import json
import logging
import math
import re
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.summary import Summary
from pytest import LogCaptureFixture

from rob6_recorder.reader import RecordingReader, is_complete, read_records
from rob6_recorder.schemas import schema_for, to_foxglove_log
from rob6_recorder.transforms import TfDeriver, pose_from_fk
from rob6_recorder.writer import Recorder
from tests.motion.link_session import wait_until
from tests.recording.rec_helpers import record_session

if TYPE_CHECKING:
    import numpy.typing as npt

NAME = re.compile(r"^\d{8}T\d{6}Z_kr16_robot1_(session3|system_\d{3})(-\d+)?\.mcap$")


def _files(d: Path, kind: str) -> list[Path]:
    return sorted(p for p in d.iterdir() if p.suffix == ".mcap" and f"_{kind}" in p.name)


def _checked_summary(path: Path) -> tuple[Summary, list[tuple[Schema | None, Channel, Message]]]:
    """The stock mcap reader accepts the file, with CRCs validated."""
    with open(path, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        messages = list(reader.iter_messages(log_time_order=False))
        assert len(messages) == summary.statistics.message_count
        return summary, messages


def test_scripted_session_every_record_in_order_with_cid(tmp_path: Path, urdf: str) -> None:
    def fk(q: list[float]) -> list[float]:
        return [1, 0, 0, 1000.0, 0, 1, 0, 0, 0, 0, 1, 500.0]

    with Recorder(tmp_path, "kr16", "robot1", urdf=urdf, fk=fk, tf_max_rate=0) as rec:
        submitted = record_session(rec, session=3)
    session_files, system_files = _files(tmp_path, "session"), _files(tmp_path, "system")
    assert len(session_files) == 1 and len(system_files) == 1
    for p in session_files + system_files:
        assert NAME.match(p.name), p.name
        assert is_complete(p)

    for path in (session_files[0], system_files[0]):
        got = [(r.topic, r.log_time, r.data) for r in read_records(path)
               if r.topic not in ("/tf", "/flange", "/robot_description")]
        expected = []
        for topic, t, data in submitted:
            expected.append((topic, t, to_foxglove_log(data, t) if topic == "/log" else data))
        assert got == expected  # every record, in submission order, with its cid

        # the cid chain: each client line -> its bus traffic -> its reply
        cids = [d.get("cid") for topic, _, d in got if topic.startswith(("/session/3/client", "/bus/"))]
        assert [c for c in cids if c] == [d.get("cid") for topic, _, d in submitted
                                           if topic.startswith(("/session/3/client", "/bus/")) and d.get("cid")]

        summary, messages = _checked_summary(path)
        schemas = {summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
        assert all(ch.schema_id != 0 and ch.message_encoding == "json"
                   for ch in summary.channels.values())
        assert {"rob6.ClientLine", "rob6.ClientReply", "rob6.JointState", "foxglove.Log",
                "foxglove.FrameTransforms", "foxglove.PosesInFrame", "std_msgs/String",
                "rob6.BusRequest", "rob6.BusReply", "rob6.SessionEvent"} <= schemas
        assert all(s.encoding == "jsonschema" for s in summary.schemas.values())
        with open(path, "rb") as fh:
            mcap_reader = make_reader(fh)
            assert [a.name for a in mcap_reader.iter_attachments()] == ["robot.urdf"]
            meta = {m.name: m.metadata for m in mcap_reader.iter_metadata()}
        assert meta["rob6"]["robot"] == "kr16" and meta["rob6"]["robot_id"] == "robot1"
        assert "rob6.end" in meta

    reader = RecordingReader(session_files[0])
    recs = list(reader.records())
    assert reader.metadata["rob6"]["kind"] == "session" and reader.metadata["rob6"]["session"] == "3"
    # one /tf and one /flange per joint state, derived from the URDF / fk
    n_js = sum(1 for r in recs if r.topic == "/driver/joint_state")
    assert sum(1 for r in recs if r.topic == "/tf") == n_js
    flange = [r for r in recs if r.topic == "/flange"]
    assert len(flange) == n_js
    assert flange[0].data["poses"][0]["position"] == {"x": 1.0, "y": 0.0, "z": 0.5}
    assert flange[0].data["frame_id"] == "base_link"
    tf = [r for r in recs if r.topic == "/tf"][0].data["transforms"]
    assert [t["child_frame_id"] for t in tf] == ["link1", "link2", "flange", "fk_flange"]
    assert tf[-1]["parent_frame_id"] == "base_link"
    assert tf[-1]["translation"] == {"x": 1.0, "y": 0.0, "z": 0.5}
    desc = [r for r in recs if r.topic == "/robot_description"]
    assert len(desc) == 1 and desc[0].data == {"data": urdf}
    log = [r for r in recs if r.topic == "/log"][0]
    assert log.data["level"] == 3 and log.data["name"] == "gateway/rob6.gateway"


def test_records_outside_sessions_go_to_system_only(tmp_path: Path) -> None:
    with Recorder(tmp_path, "kr16", "robot1") as rec:
        t = time.time_ns()
        rec.submit("/driver/joint_state", t, {"q": [0] * 6})
        rec.submit("/session/1/client_in", t + 1, {"session": 1, "cid": "a", "text": "GetRobot\n"})
        rec.submit("/driver/joint_state", t + 2, {"q": [1] * 6})
        rec.submit("/session/1/event", t + 3, {"session": 1, "event": "close"})
        rec.flush()
        time.sleep(1.2)  # linger (0.5 s) passes: the session file is finished
        rec.submit("/driver/joint_state", t + 4, {"q": [2] * 6})
        rec.submit("/session/1/client_out", t + 5, {"session": 1, "cid": "a", "text": "late\n"})
    (session,), (system,) = _files(tmp_path, "session"), _files(tmp_path, "system")
    assert is_complete(session)
    assert [r.log_time - t for r in read_records(session)] == [1, 2, 3]
    assert [r.log_time - t for r in read_records(system)] == [0, 1, 2, 3, 4, 5]


def test_a_trace_arriving_before_its_sessions_open_event_lands_in_the_session(tmp_path: Path) -> None:
    """Two services' trace batches reach the recorder in either order: the kinematics trace of
    a session's first command may come before the gateway's open event (seen in a full test
    run on a busy machine). It belongs to the session by its time, not by its arrival."""
    with Recorder(tmp_path, "kr16", "robot1") as rec:
        t = time.time_ns()
        rec.submit("/driver/joint_state", t, {"q": [0] * 6})  # before the session: not in it
        rec.submit("/bus/kinematics/forward_calc/request", t + 2, {"cid": "a"})  # arrives first
        rec.submit("/session/1/event", t + 1, {"session": 1, "event": "open"})
        rec.submit("/session/1/client_in", t + 3, {"session": 1, "cid": "a", "text": "ForwardCalc\n"})
        rec.submit("/session/1/event", t + 4, {"session": 1, "event": "close"})
    (session,), (system,) = _files(tmp_path, "session"), _files(tmp_path, "system")
    assert sorted(r.log_time - t for r in read_records(session)) == [1, 2, 3, 4]
    assert sorted(r.log_time - t for r in read_records(system)) == [0, 1, 2, 3, 4]


def test_rotation_by_size_and_time(tmp_path: Path) -> None:
    with Recorder(tmp_path / "size", "kr16", "robot1", rotate_bytes=20_000, rotate_seconds=0,
                  chunk_interval=0.05, fsync=False) as rec:
        t = time.time_ns()
        for i in range(3000):
            rec.submit("/driver/joint_state", t + i, {"cycle": i, "q": [i * 1.1] * 6, "qd": [0.5] * 6})
            if i % 300 == 0:
                time.sleep(0.06)
    files = _files(tmp_path / "size", "system")
    assert len(files) >= 2
    cycles = [r.data["cycle"] for p in files for r in read_records(p)]
    assert cycles == list(range(3000))
    assert all(is_complete(p) for p in files)

    with Recorder(tmp_path / "time", "kr16", "robot1", rotate_seconds=0.3, chunk_interval=0.05,
                  fsync=False) as rec:
        t = time.time_ns()
        for i in range(8):
            rec.submit("/log", t + i, {"level": "INFO", "name": "x", "message": str(i)})
            time.sleep(0.1)
    files = _files(tmp_path / "time", "system")
    assert len(files) >= 2
    assert [r.data["message"] for p in files for r in read_records(p)] == [str(i) for i in range(8)]


def test_a_latched_record_starts_every_file_opened_after_it(tmp_path: Path, urdf: str) -> None:
    """The cell is what the robot is made of: recorded once, like any record, and again at the
    start of every file opened after it (rotated system files, a session's), right after the
    URDF; a newer one replaces it from then on. A file opened before it has none at its start."""
    first = {"source": "cell-a.yaml", "margin_mm": 5.0, "zones": [{"name": "floor", "keep": "out"}]}
    second = {"source": "cell-b.yaml", "margin_mm": 8.0}
    with Recorder(tmp_path, "kr16", "robot1", urdf=urdf, rotate_seconds=0.2, rotate_bytes=0, chunk_interval=0.02,
                  fsync=False) as rec:
        t = time.time_ns()
        tick = iter(range(1, 1 << 30))

        def rotated_past(opened: int) -> bool:  # keeps the recording going until the writer rotated
            rec.submit("/driver/joint_state", t + next(tick), {"cycle": 0})
            return len(_files(tmp_path, "system")) >= opened

        rec.submit("/driver/joint_state", t, {"cycle": 0})  # the first file opens before any cell
        for cell in (first, second):
            assert rec.submit("/cell", t + next(tick), cell, latched=True)
            assert rec.flush()
            opened = len(_files(tmp_path, "system")) + 2
            wait_until(partial(rotated_past, opened), 20.0, "two rotations")
        rec.submit("/session/7/client_in", time.time_ns(), {"session": 7, "cid": "a", "text": "GetCell\n"})
    systems = _files(tmp_path, "system")
    current: dict[str, Any] | None = None
    started_with = []
    recorded = []
    for path in systems:
        records = list(read_records(path))
        assert records[0].topic == "/robot_description"
        if current is not None:  # right after the URDF, at the file's start: the latest cell
            assert (records[1].topic, records[1].data, records[1].log_time) == ("/cell", current, records[0].log_time)
            assert records[1].schema == "rob6.Cell"
            started_with.append(current)
        cells = [r.data for r in records[2 if current is not None else 1:] if r.topic == "/cell"]
        recorded += cells
        current = cells[-1] if cells else current
    assert recorded == [first, second]  # each recorded once where it came
    assert started_with.count(first) >= 2 and started_with.count(second) >= 2, started_with
    assert not any(r.topic == "/cell" for r in read_records(systems[0]) if r.log_time < t + 1)
    (session,) = _files(tmp_path, "session")
    assert [(r.topic, r.data) for r in read_records(session)][:2] == [("/robot_description", {"data": urdf}),
                                                                    ("/cell", second)]
    assert sum(r.topic == "/cell" for r in read_records(session)) == 1


def test_backlog_bound_drops_are_counted_logged_and_recorded(tmp_path: Path, caplog: LogCaptureFixture) -> None:
    rec = Recorder(tmp_path, "kr16", "robot1", max_backlog=100, warn_backlog=50)
    t = time.time_ns()
    with caplog.at_level(logging.WARNING, logger="rob6.recorder"):
        accepted = [rec.submit("/driver/joint_state", t + i, {"cycle": i}) for i in range(150)]
        assert accepted == [True] * 100 + [False] * 50  # never blocks, refuses past the bound
        stats = rec.stats()
        assert stats.dropped == 50 and stats.dropped_by_topic == {"/driver/joint_state": 50}
        assert stats.backlog == 100
        rec.start()
        rec.close()
    assert any("falling behind" in r.message for r in caplog.records)
    assert any("dropping" in r.message for r in caplog.records)
    (system,) = _files(tmp_path, "system")
    recs = list(read_records(system))
    assert [r.data["cycle"] for r in recs if r.topic == "/driver/joint_state"] == list(range(100))
    (status,) = [r.data for r in recs if r.topic == "/recorder/status"]
    assert status["dropped"] == 50 and status["dropped_since_last"] == {"/driver/joint_state": 50}
    assert status["first_drop_ns"] == t + 100 and status["last_drop_ns"] == t + 149
    assert rec.stats().written == 100


def test_records_keep_their_order_around_the_writers_controls(tmp_path: Path) -> None:
    """Sessions opened without waiting are done by the writer's thread in order with the
    records around them: each session's file holds what was submitted after it opened, and the
    system file everything, in the order submitted."""
    with Recorder(tmp_path, "kr16", "robot1") as rec:
        t = time.time_ns()
        for i in range(400):
            rec.submit("/driver/joint_state", t + i, {"cycle": i})
            if i % 100 == 50:
                rec.open_session(i)
    assert rec.stats().written == 400 and rec.stats().dropped == 0
    (system,) = _files(tmp_path, "system")
    assert [r.data["cycle"] for r in read_records(system) if r.topic == "/driver/joint_state"] == list(range(400))
    for n in (50, 150, 250, 350):
        (session,) = [p for p in _files(tmp_path, "session") if p.stem.endswith(f"session{n}")]
        cycles = [r.data["cycle"] for r in read_records(session) if r.topic == "/driver/joint_state"]
        assert cycles == list(range(n + 1, 400)), n


def test_missed_batches_are_logged_and_recorded_on_the_status_channel(tmp_path: Path, caplog: LogCaptureFixture) -> None:
    """What the bus reports as lost on the way (sample-miss detection) is in the file."""
    with caplog.at_level(logging.WARNING, logger="rob6.recorder"), Recorder(tmp_path, "kr16", "robot1") as rec:
        rec.report_missed("rob6/robot1/trace/gateway gw-1", 3)
        rec.report_missed("rob6/robot1/trace/gateway gw-1", 2)
        assert rec.stats().missed == 5
    assert any("missed 3 trace batches from rob6/robot1/trace/gateway gw-1" in r.message for r in caplog.records)
    (system,) = _files(tmp_path, "system")
    status = [r.data for r in read_records(system) if r.topic == "/recorder/status"]
    assert status == [{"missed": 3, "missed_source": "rob6/robot1/trace/gateway gw-1", "missed_total": 3},
                      {"missed": 2, "missed_source": "rob6/robot1/trace/gateway gw-1", "missed_total": 5}]


def test_submit_after_close_is_refused_and_counted(tmp_path: Path) -> None:
    rec = Recorder(tmp_path, "kr16", "robot1").start()
    rec.close()
    assert rec.submit("/log", 1, {"message": "late"}) is False
    assert rec.stats().dropped == 1


def test_bytes_and_structs_and_unserialisable(tmp_path: Path) -> None:
    import msgspec

    class JS(msgspec.Struct):
        q: list[float]
        cycle: int

    with Recorder(tmp_path, "kr16", "robot1") as rec:
        rec.submit("/driver/joint_state", 1, JS(q=[1.0] * 6, cycle=7))
        rec.submit("/bus/x/y/reply", 2, b'{"cid":"k","ok":true}')
        rec.submit("/other/topic", 3, {"obj": object()})  # falls back to repr, not lost
    (system,) = _files(tmp_path, "system")
    recs = list(read_records(system))
    assert recs[0].data == {"q": [1.0] * 6, "cycle": 7}
    assert recs[1].data == {"cid": "k", "ok": True}
    assert recs[2].schema == "rob6.Record" and recs[2].data["obj"].startswith("<object")


def test_fk_without_urdf_gives_tf_and_flange(tmp_path: Path) -> None:
    def fk(q: list[float]) -> list[float] | None:
        return None if q[0] > 100 else [1, 0, 0, q[0], 0, 1, 0, 0, 0, 0, 1, 0]

    with Recorder(tmp_path, "kr16", "robot1", fk=fk, tf_max_rate=0) as rec:
        rec.submit("/driver/joint_state", 1, {"q": [500.0] + [0] * 5})  # unreachable: nothing
        rec.submit("/driver/joint_state", 2, {"q": [250.0] + [0] * 5})
        rec.submit("/driver/joint_state", 3, {"q": [50.0] + [0] * 5})
    (system,) = _files(tmp_path, "system")
    recs = [(r.topic, r.log_time) for r in read_records(system)]
    assert recs == [("/driver/joint_state", 1), ("/driver/joint_state", 2),
                    ("/driver/joint_state", 3), ("/tf", 3), ("/flange", 3)]
    tf = [r.data for r in read_records(system, ["/tf"])][0]["transforms"]
    assert tf[0]["parent_frame_id"] == "base" and tf[0]["translation"]["x"] == 0.05


def test_schema_mapping() -> None:
    assert schema_for("/session/12/client_in").name == "rob6.ClientLine"
    assert schema_for("/bus/kinematics/fk/request").name == "rob6.BusRequest"
    assert schema_for("/bus/kinematics/fk/reply").name == "rob6.BusReply"
    assert schema_for("/tf").name == "foxglove.FrameTransforms"
    assert schema_for("/whatever").name == "rob6.Record"


def test_log_mapping_levels() -> None:
    assert to_foxglove_log({"level": "ERROR", "name": "n", "message": "m", "service": "driver",
                            "time": 12.5}, 0) == {
        "timestamp": {"sec": 12, "nsec": 500_000_000}, "level": 4, "message": "m",
        "name": "driver/n", "file": "", "line": 0, "service": "driver"}
    assert to_foxglove_log({"level": 20, "message": "x"}, 5)["level"] == 2
    assert to_foxglove_log({"level": "DEBUG", "message": "x"}, 7)["timestamp"] == {"sec": 0, "nsec": 7}


def test_tf_from_urdf(urdf: str) -> None:
    tf = TfDeriver(urdf)
    msg = tf.transforms([90.0, 0.0, 0, 0, 0, 0], 1_500_000_000)
    frames = [(t["parent_frame_id"], t["child_frame_id"]) for t in msg["transforms"]]
    assert frames == [("base_link", "link1"), ("link1", "link2"), ("link2", "flange")]
    first = msg["transforms"][0]
    assert first["timestamp"] == {"sec": 1, "nsec": 500_000_000}
    assert first["translation"] == {"x": 0.0, "y": 0.0, "z": 0.675}
    r = first["rotation"]
    assert math.isclose(r["z"], math.sqrt(0.5)) and math.isclose(r["w"], math.sqrt(0.5))
    # joint_map: sign/offset per axis
    flipped = TfDeriver(urdf, joint_map=[(-1, 0), (1, 90)]).transforms([90.0, 0.0], 0)
    assert math.isclose(flipped["transforms"][0]["rotation"]["z"], -math.sqrt(0.5))
    assert math.isclose(flipped["transforms"][1]["rotation"]["y"], math.sqrt(0.5))


def test_pose_from_fk_forms() -> None:
    pose = pose_from_fk([0, -0.173648, -0.984808, 1741.140107, 0, -0.984808, 0.173648,
                         -307.009978, -1, 0, 0, 640])
    assert pose is not None
    (p, q) = pose
    assert p == pytest.approx((1.741140107, -0.307009978, 0.64))
    assert sum(c * c for c in q) == pytest.approx(1.0)
    assert pose_from_fk(None) is None
    pose = pose_from_fk([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1000], [0, 0, 0, 1]])
    assert pose is not None and pose[0] == (0, 0, 1.0)


def _batch(tmp_path: Path, pairs: list[tuple[str, bytes]], received_ns: int) -> list[tuple[str, int, int, bytes, str]]:
    """What one trace batch of ``pairs`` (suffix, record JSON) becomes in the system file:
    ``(topic, log_time, publish_time, JSON as written, schema)`` of each record it gave."""
    payload = b"[" + b",".join(b'["%s",%s]' % (suffix.encode(), record) for suffix, record in pairs) + b"]"
    with Recorder(tmp_path, "kr16", "robot1", sessions=False) as rec:
        assert rec.submit_batch(payload, received_ns) == []
    (system,) = _files(tmp_path, "system")
    reader = RecordingReader(system)
    return [(r.topic, r.log_time, r.publish_time, r.data, r.schema) for r in reader.records(decode=False)
            if r.topic.startswith(("/bus/", "/session/", "/trace/"))]


def test_a_bus_trace_gives_its_request_and_reply_records(tmp_path: Path) -> None:
    trace = (b'{"t":1700000000.5,"dt":0.002,"instance":"k-1","request":{"v":1,"cid":"abc",'
             b'"body":{"joints":[[0,0,0,0,0,0]]}},"reply":{"v":1,"cid":"abc","ok":false,'
             b'"error":{"code":"invalid","message":"x"}}}')
    (req, rep) = _batch(tmp_path, [("trace/kinematics/fk", trace)], received_ns=5)
    assert req[:3] == ("/bus/kinematics/fk/request", 1_700_000_000_500_000_000, 1_700_000_000_500_000_000)
    assert json.loads(req[3]) == {"cid": "abc", "service": "kinematics", "op": "fk", "instance": "k-1",
                                  "body": {"joints": [[0, 0, 0, 0, 0, 0]]}}
    assert rep[:3] == ("/bus/kinematics/fk/reply", 1_700_000_000_502_000_000, 5)
    assert json.loads(rep[3]) == {"cid": "abc", "service": "kinematics", "op": "fk", "instance": "k-1",
                                  "ok": False, "body": None, "dt": 0.002,
                                  "error": {"code": "invalid", "message": "x"}}
    assert (req[4], rep[4]) == ("rob6.BusRequest", "rob6.BusReply")


def test_a_bus_trace_passes_the_bodies_through_as_sent(tmp_path: Path) -> None:
    """The bodies are not decoded and printed again: numbers keep the service's digits."""
    trace = (b'{"t":2.0,"dt":0.5,"instance":"k-1","request":{"v":1,"cid":"c1","body":{"q":[1.50,-0.0]}},'
             b'"reply":{"v":1,"cid":"c1","ok":true,"instance":"k-1","body":{"q":[1.000001]}}}')
    (req, rep) = _batch(tmp_path, [("trace/kinematics/fk", trace)], received_ns=7)
    assert req[:4] == ("/bus/kinematics/fk/request", 2_000_000_000, 2_000_000_000,
                       b'{"cid":"c1","service":"kinematics","op":"fk","instance":"k-1","body":{"q":[1.50,-0.0]}}')
    assert rep[:4] == ("/bus/kinematics/fk/reply", 2_500_000_000, 7,
                       b'{"cid":"c1","service":"kinematics","op":"fk","instance":"k-1","ok":true,'
                       b'"body":{"q":[1.000001]},"dt":0.5}')


def test_a_bus_trace_of_unexpected_shape_is_kept(tmp_path: Path) -> None:
    """A trace whose fields are not what a service writes still gives both records (what is
    there kept as the body), at the time it was received; so does one that is not an object."""
    records = _batch(tmp_path, [("trace/driver/ping", b'{"t":"x","dt":true,"request":null,"reply":[1,2]}'),
                                ("trace/driver/ping", b"[3,4]")], received_ns=7)
    assert [r[:3] for r in records] == [("/bus/driver/ping/request", 7, 7), ("/bus/driver/ping/reply", 7, 7)] * 2
    assert json.loads(records[0][3])["body"] is None
    assert json.loads(records[1][3]) == {"cid": "", "service": "driver", "op": "ping", "instance": "", "ok": False,
                                         "body": [1, 2], "dt": 0.0}
    assert json.loads(records[2][3])["body"] == [3, 4] and json.loads(records[3][3])["body"] is None


def test_a_client_exchange_and_session_events_give_their_session_records(tmp_path: Path) -> None:
    opened = b'{"session":3,"event":"open","peer":"10.0.0.2:4711","t":10.5,"greeting":"welcome\\n"}'
    line = (b'{"session":3,"peer":"10.0.0.2:4711","cid":"c7","t_in":11.25,"t_out":11.5,'
            b'"line":"GetRobot \\u00e9","reply":"kr16\\n","seq":1}')
    quiet = b'{"session":3,"peer":"10.0.0.2:4711","cid":"c8","t_in":12.0,"t_out":12.0,"line":"","reply":null,"seq":2}'
    closed = b'{"session":3,"event":"close","peer":"10.0.0.2:4711","t":13.0,"reason":"timeout"}'
    records = _batch(tmp_path, [("trace/gateway/event", opened), ("trace/gateway/session", line),
                                ("trace/gateway/session", quiet), ("trace/gateway/event", closed)], received_ns=1)
    assert [(topic, t, json.loads(data), schema) for topic, t, _, data, schema in records] == [
        ("/session/3/event", 10_500_000_000, {"session": 3, "event": "open", "peer": "10.0.0.2:4711"},
         "rob6.SessionEvent"),
        ("/session/3/client_out", 10_500_000_000, {"session": 3, "cid": "", "text": "welcome\n", "kind": "greeting"},
         "rob6.ClientReply"),
        ("/session/3/client_in", 11_250_000_000,
         {"session": 3, "cid": "c7", "text": "GetRobot \u00e9\n", "peer": "10.0.0.2:4711", "seq": 1}, "rob6.ClientLine"),
        ("/session/3/client_out", 11_500_000_000,
         {"session": 3, "cid": "c7", "text": "kr16\n", "dt": 0.25, "seq": 1}, "rob6.ClientReply"),
        ("/session/3/client_in", 12_000_000_000,
         {"session": 3, "cid": "c8", "text": "\n", "peer": "10.0.0.2:4711", "seq": 2}, "rob6.ClientLine"),
        ("/session/3/client_out", 12_000_000_000, {"session": 3, "cid": "c8", "text": "", "dt": 0.0, "seq": 2},
         "rob6.ClientReply"),
        ("/session/3/event", 13_000_000_000,
         {"session": 3, "event": "close", "peer": "10.0.0.2:4711", "reason": "timeout"}, "rob6.SessionEvent"),
    ]


def test_a_session_record_that_cannot_be_read_is_kept_as_it_came(tmp_path: Path, caplog: LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="rob6.recorder"):
        records = _batch(tmp_path, [("trace/gateway/session", b'{"session":"three"}')], received_ns=9)
    assert records == [("/trace/gateway/session", 9, 9, b'{"session":"three"}', "rob6.Record")]
    assert "trace/gateway/session: a record that could not be read" in caplog.text


def test_the_other_records_of_a_batch_go_back_to_python_and_a_malformed_batch_is_refused(tmp_path: Path) -> None:
    with Recorder(tmp_path, "kr16", "robot1") as rec:
        others = rec.submit_batch(b'[["driver/state",{"q":[1,2,3,4,5,6]}],["log/driver",{"message":"m"}]]', 1)
        assert others == [("driver/state", b'{"q":[1,2,3,4,5,6]}'), ("log/driver", b'{"message":"m"}')]
        for bad in (b"{}", b"[1]", b'[["a"]]', b"not json"):
            with pytest.raises(ValueError, match="not a trace batch"):
                rec.submit_batch(bad, 1)


def test_tf_chain_of_the_project_urdf_matches_the_kinematics_fk() -> None:
    """Composing /tf from the shipped URDF gives the protocol's flange pose."""
    import pathlib

    np = pytest.importorskip("numpy")
    opw = pytest.importorskip("rob6_kinematics.opw")
    import rob6
    from rob6.robots import get_robot

    path = pathlib.Path(rob6.__file__).parent / "urdf" / "kr16.urdf"
    if not path.exists():
        pytest.skip("no shipped URDF")
    tf = TfDeriver(path.read_text())

    def matrix(t: dict[str, Any]) -> npt.NDArray[Any]:
        x, y, z, w = (t["rotation"][k] for k in "xyzw")
        m: npt.NDArray[Any] = np.eye(4)
        m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
        m[:3, 3] = [t["translation"][k] for k in "xyz"]
        return m

    for q in ([0, 0, 0, 0, 0, 0], [10, -60, 80, 20, 40, 30], [-84, -75, -41, -60, 27, 38]):
        T = np.eye(4)
        for t in tf.transforms(q, 0)["transforms"]:
            T = T @ matrix(t)
            if t["child_frame_id"] == "flange":
                break
        P = opw.fk(opw.Geometry.of(get_robot("kr16")), q)[0]
        assert np.allclose(T[:3, 3] * 1000, P[:, 3], atol=1e-6)
        assert np.allclose(T[:3, :3], P[:, :3], atol=1e-9)


def test_schemas_of_bus_messages_are_generated_from_their_structs() -> None:
    """The joint state, link event, gripper state, clearance and cell are recorded as the bus
    carries them: their schemas come from the Structs and name every field (the hand-written
    one had lost ``missed``)."""
    import msgspec

    from rob6.messages import Cell, Clearance, GripperState, JointState, LinkEvent

    for topic, struct in (("/driver/joint_state", JointState), ("/driver/link", LinkEvent),
                          ("/gripper/state", GripperState), ("/driver/clearance", Clearance), ("/cell", Cell)):
        spec = schema_for(topic)
        assert spec.name == f"rob6.{struct.__name__}"
        assert set(spec.schema["properties"]) == set(struct.__struct_fields__)
        assert spec.schema["type"] == "object" and "$ref" not in spec.schema
        msgspec.json.decode(spec.data)  # stored as JSON
    assert "missed" in schema_for("/driver/joint_state").schema["properties"]


def test_a_recorder_dropped_without_close_finishes_its_files(tmp_path: Path) -> None:
    """A forgotten recorder must not leave a file without its summary: the native writer's
    thread is told to finish when the recorder goes."""
    rec = Recorder(tmp_path, "kr16", "robot1").start()
    rec.submit("/driver/joint_state", time.time_ns(), {"cycle": 1})
    del rec
    gc.collect()
    # polled: the writer's thread finishes on its own after the recorder is gone, nothing to join
    system = wait_until(lambda: next(iter(_files(tmp_path, "system")), None), 10.0, "the system file")
    wait_until(lambda: is_complete(system), 10.0, "the file finished")
    assert [r.data for r in read_records(system, ["/driver/joint_state"])] == [{"cycle": 1}]


def test_a_file_that_cannot_be_opened_is_counted_logged_and_the_recording_goes_on(
        tmp_path: Path, caplog: LogCaptureFixture) -> None:
    directory = tmp_path / "rec"
    with caplog.at_level(logging.ERROR, logger="rob6.recorder"), Recorder(directory, "kr16", "robot1") as rec:
        directory.rmdir()  # before the first record: its system file cannot be created
        assert rec.submit("/driver/joint_state", time.time_ns(), {"cycle": 1})
        assert rec.flush()
        assert rec.stats().errors >= 1
        directory.mkdir()
        assert rec.submit("/driver/joint_state", time.time_ns(), {"cycle": 2})
    assert any("opening" in r.message and "failed" in r.message for r in caplog.records)
    (system,) = _files(directory, "system")
    assert [r.data for r in read_records(system, ["/driver/joint_state"])] == [{"cycle": 2}]
