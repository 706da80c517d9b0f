"""The recording tests' fixtures: a sample URDF, a scripted session, the fake server's
answers from a dict (the fake server itself is ``harness.fake_server``) and a cell with a
table to record and draw."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from ruamel.yaml import YAML

from harness.fake_server import GREETING, Handler
from rob6_recorder.writer import Recorder
from tests.cell.zone_rig import Rig, rig

URDF = """<?xml version="1.0"?>
<robot name="mini6">
  <link name="base_link"/><link name="link1"/><link name="link2"/><link name="flange"/>
  <joint name="a1" type="revolute"><parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.675"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="a2" type="revolute"><parent link="link1"/><child link="link2"/>
    <origin xyz="0.26 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="link2"/><child link="flange"/>
    <origin xyz="0.68 0 0"/></joint>
</robot>
"""

#: command line -> reply of the fake kr16 (what the scripted session recorded)
REPLIES = {
    "Hello Robot\n": "accepted\n",
    "GetRobot\n": "kr16\n",
    "GetVersion\n": "0.1.01\n",
    "ForwardCalc 10 0 0 0 0 0\n": (
        "0.000000 -0.173648 -0.984808 1741.140107 0.000000 -0.984808 0.173648 -307.009978 "
        "-1.000000 -0.000000 -0.000000 640.000000\nnoflip up lefty\n"),
    "SetAllowedStatus flip toggleElbow toggleArm\n": "",
    "MovePTPJoints 5 -5 5 5 5 5\n": "true\n",
    "MovePTPJoints 0 20 0 0 0 0\n": "false\n",
    "GetPositionJoints\n": "5.000000 -5.000000 5.000000 5.000000 5.000000 5.000000\n",
    "Foo\n": "ERROR: Foo\n",
    "ForwardCalc x\n": "false\n",
    "MovePTPJoints 1 2 3\n": "ERROR: incorrect joints\nfalse\n",
    "GetTimestamp\n": "1795321511.114\n",
    "\n": "",
    "Quit\n": "bye!\n",
}

#: the session the tests record: every line with its reply, in order
SESSION_LINES = [
    "Hello Robot\n", "GetRobot\n", "GetVersion\n", "ForwardCalc 10 0 0 0 0 0\n",
    "SetAllowedStatus flip toggleElbow toggleArm\n", "MovePTPJoints 5 -5 5 5 5 5\n",
    "GetPositionJoints\n", "MovePTPJoints 0 20 0 0 0 0\n", "Foo\n", "ForwardCalc x\n",
    "MovePTPJoints 1 2 3\n", "GetTimestamp\n", "\n", "GetRobot\n", "Quit\n",
]


#: one record as submitted to the recorder: topic, log time (ns), payload
Submitted = tuple[str, int, dict[str, Any]]


def record_session(rec: Recorder, session: int = 3, t0: int | None = None, step_ns: int = 20_000_000,
                   joint_states_per_line: int = 2) -> list[Submitted]:
    """Feed ``rec`` (a Recorder) a scripted client session; return what was submitted."""
    t = time.time_ns() if t0 is None else t0
    submitted: list[Submitted] = []

    def put(topic: str, data: dict[str, Any]) -> None:
        nonlocal t
        t += step_ns // 4
        assert rec.submit(topic, t, data)
        submitted.append((topic, t, data))

    put(f"/session/{session}/event", {"session": session, "event": "open", "peer": "127.0.0.1:5555"})
    put(f"/session/{session}/client_out", {"session": session, "cid": "", "text": GREETING,
                                          "kind": "greeting"})
    cycle = 0
    for i, line in enumerate(SESSION_LINES):
        cid = f"c{i:03d}"
        put(f"/session/{session}/client_in", {"session": session, "cid": cid, "text": line})
        word = line.split()[0] if line.split() else ""
        if word.startswith("Move"):
            put("/bus/planner/move/request", {"cid": cid, "service": "planner", "op": "move",
                                              "body": {"kind": "ptp"}})
            put("/bus/planner/move/reply", {"cid": cid, "service": "planner", "op": "move",
                                            "ok": True, "body": {"ok": True}})
        for _ in range(joint_states_per_line):
            cycle += 1
            put("/driver/joint_state", {"t": cycle * 0.012, "cycle": cycle,
                                        "q": [5.0, -5.0, 5.0, 5.0, 5.0, 5.0], "qd": [0.0] * 6,
                                        "moving": False, "mode": "idle"})
        reply = REPLIES[line]
        if reply or line.strip():  # the gateway records a reply record even when empty
            put(f"/session/{session}/client_out", {"session": session, "cid": cid, "text": reply})
        if word == "Foo":
            put("/log", {"level": "WARNING", "name": "rob6.gateway", "service": "gateway",
                         "message": "unknown command Foo", "t": t / 1e9})
    put(f"/session/{session}/event", {"session": session, "event": "close", "reason": "quit"})
    return submitted


def dict_handler(replies: dict[str, str], overrides: dict[str, str] | None = None) -> Handler:
    table = dict(replies)
    table.update(overrides or {})

    def handle(_conn: int, msg: bytes) -> tuple[bytes, bool]:
        line = msg.decode("latin-1")
        if line == "GetTimestamp\n":
            return f"{time.time():.3f}\n".encode(), False
        reply = table.get(line)
        if reply is None:
            reply = f"ERROR: {line.rstrip(chr(10))}\n"
        return reply.encode("latin-1"), line == "Quit\n"

    return handle


def table_cell(directory: Path, robot: str = "kr16") -> tuple[Rig, Path]:
    """A cell file with the floor, a table 200 mm below the tool tip at the rig's hover pose
    (``zone_rig``), the tool, and no self-collision: what is recorded and drawn, without the
    cost of checking the arm against itself on every path (not what these tests are about)."""
    hover = rig(robot)
    table = Rig(robot, hover.tool_mm, hover.tip_radius_mm, hover.table_z - 100.0)
    cell = YAML(typ="safe").load(table.cell_yaml())
    cell["zones"].insert(0, {"name": "floor", "keep": "out", "ignore": ["link_1"],
                             "half_space": {"point": [0, 0, 0], "normal": [0, 0, 1]}})
    cell["arm"] = {"self_collision": False}
    path = directory / f"{robot}-table.yaml"
    path.write_text(json.dumps(cell, indent=1))  # JSON is YAML
    return table, path
