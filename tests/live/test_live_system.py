"""The live view with the real system: ``rob6 run`` prints its address, a Foxglove
WebSocket client sees the URDF, every link's transform, the joint state and the command
log, and the arm move when a client drives it through the gateway; it sees the cell's zones
and tool, and the table turn amber as the tool comes down to it."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from harness.foxglove_client import FoxgloveClient
from harness.system import running
from rob6.cell import load_cell
from rob6.robots import get_robot
from rob6_recorder.cell_scene import AMBER, FLANGE_FRAME, GREEN, GREY, colour
from tests.cell.zone_rig import HOVER_S
from tests.recording.rec_helpers import table_cell

TARGET = [10.0, -60.0, 80.0, 20.0, 40.0, 30.0]
SCHEMAS = {"/robot_description": "std_msgs/String", "/tf": "foxglove.FrameTransforms",
           "/driver/joint_state": "rob6.JointState", "/commands": "foxglove.Log", "/log": "foxglove.Log",
           "/gripper/state": "rob6.GripperState"}


def _links(robot: str) -> tuple[str, set[str]]:
    """The URDF's root link and every other link (a 3D panel needs a transform to each)."""
    root = ET.fromstring(get_robot(robot).urdf)
    links = {link.attrib["name"] for link in root.iter("link")}
    children = {child.attrib["link"] for child in root.iterfind(".//joint/child")}
    (base,) = links - children
    return base, links - {base}


def test_live_view_follows_the_arm(tmp_path: Path, live_port: int) -> None:
    with running("kr16", log_dir=str(tmp_path), extra_env={"ROB6_LIVE_PORT": str(live_port)}) as system:
        url = f"ws://127.0.0.1:{live_port}"
        assert any(f"live view: {url}" in line for line in system.output), system.output
        with FoxgloveClient(url) as fox, system.client() as client:
            assert fox.wait(lambda: fox.server_info)
            client.ask("GetRobot")  # something on /commands and the session channels
            topics = fox.wait_topics(SCHEMAS)
            assert {t: topics[t]["schemaName"] for t in SCHEMAS if t in topics} == SCHEMAS
            assert all(topics[t]["encoding"] == "json" for t in SCHEMAS)
            fox.subscribe("/robot_description", "/tf", "/driver/joint_state", "/commands", "/gripper/state")

            # the URDF: latched on its topic (sent on subscribe) and as an asset
            (_, description), *_ = fox.wait_messages("/robot_description")
            assert description["data"].lstrip().startswith("<?xml") and "<robot" in description["data"]
            fetched = fox.fetch_asset("package://rob6/robot.urdf")
            assert fetched is not None, "no answer to fetchAsset"
            status, asset = fetched
            assert status == 0 and asset.decode() == description["data"]

            # a transform for every link the 3D panel has to place
            root, links = _links("kr16")
            tf = fox.wait_messages("/tf", 3)
            assert tf, "no /tf"
            children = {t["child_frame_id"] for t in tf[-1][1]["transforms"]}
            parents = {t["parent_frame_id"] for t in tf[-1][1]["transforms"]}
            assert links <= children and root in parents

            assert fox.wait_messages("/gripper/state")
            before = fox.wait_messages("/driver/joint_state")[-1][1]
            assert "mode" in before and "moving" in before

            assert client.ask("MovePTPJoints " + " ".join(f"{q:g}" for q in TARGET)) == "true\n"
            assert client.ask("GetPositionJoints").split() == [f"{q:.6f}" for q in TARGET]

            def at_target(state: dict[str, Any]) -> bool:
                return all(abs(a - b) < 1e-6 for a, b in zip(state["q"], TARGET, strict=True))

            assert fox.wait(lambda: any(at_target(s) for _, s in fox.received("/driver/joint_state")))
            assert not at_target(before)
            # the transforms moved with it
            first = {t["child_frame_id"]: t["rotation"] for t in tf[0][1]["transforms"]}

            def moved() -> bool:
                last = {t["child_frame_id"]: t["rotation"] for t in fox.received("/tf")[-1][1]["transforms"]}
                return any(last[k] != first[k] for k in first)

            assert fox.wait(moved)

            # the command log: the client's lines and the server's replies
            def logged(text: str) -> bool:
                return any(m["message"] == text for _, m in fox.received("/commands"))

            assert fox.wait(lambda: logged("> MovePTPJoints 10 -60 80 20 40 30") and logged("< true"))
            entry = next(m for _, m in fox.received("/commands") if m["message"] == "< true")
            assert entry["name"].startswith("session ") and entry["level"] == 2 and entry["cid"]
            assert {"timestamp", "level", "message", "name", "file", "line"} <= set(entry)
    _stopped_cleanly(system.output)


def _stopped_cleanly(output: list[str]) -> None:
    """Every service ended with 0: a viewer's subscriptions leave nothing the recorder's stop trips on."""
    assert not [line for line in output if "stopped with exit code" in line or "Traceback" in line], output[-40:]


def _joints(q: list[float]) -> str:
    return " ".join(f"{v:g}" for v in q)


def test_live_view_draws_the_cell_and_colours_the_nearest_zone(tmp_path: Path, live_port: int) -> None:
    """The cell the driver guards on /cell/scene: the table where the cell file puts it, the
    tool on the flange; the table green with the tool 200 mm above it, amber when the tool
    came down to 30 mm, and the scene's colour the one of the last clearance the driver published."""
    table, cell_file = table_cell(tmp_path)
    box = next(z.box for z in load_cell(cell_file).zones if z.name == "table")
    assert box is not None
    env = {"ROB6_LIVE_PORT": str(live_port), "ROB6_CELL": str(cell_file)}
    with running("kr16", dummy=False, log_dir=str(tmp_path / "rec"), extra_env=env) as system, \
            FoxgloveClient(f"ws://127.0.0.1:{live_port}") as fox, system.client() as client:
        assert fox.wait_topics(["/cell/scene"])["/cell/scene"]["schemaName"] == "foxglove.SceneUpdate"
        fox.subscribe("/cell/scene", "/driver/clearance", "/tf")

        def entities() -> dict[str, Any]:
            scenes = fox.received("/cell/scene")
            return {e["id"]: e for e in scenes[-1][1]["entities"]} if scenes else {}

        assert fox.wait(lambda: {"zone:floor", "zone:table", "tool"} <= set(entities()))
        (cube,) = entities()["zone:table"]["cubes"]
        assert cube["pose"]["position"] == pytest.approx(
            {k: (lo + hi) / 2000 for k, lo, hi in zip("xyz", box.min, box.max, strict=True)})
        assert cube["size"] == pytest.approx({k: (hi - lo) / 1000 for k, lo, hi in zip("xyz", box.min, box.max,
                                                                                        strict=True)})
        tool = entities()["tool"]
        assert tool["frame_id"] == FLANGE_FRAME and tool["frame_locked"] and len(tool["spheres"]) == 3
        assert fox.wait(lambda: any(FLANGE_FRAME in {t["child_frame_id"] for t in m["transforms"]}
                                    for _, m in fox.received("/tf")))  # the frame the tool rides on

        def table_colour() -> tuple[float, ...]:
            (shape,) = entities()["zone:table"]["cubes"]
            return tuple(shape["color"][c] for c in "rgba")

        # the driver's clearance every 0.1 s of its clock while the arm moves: several as the
        # tool comes over the table, and as it comes down from 200 mm to 30 mm above it
        assert client.ask(f"MovePTPJoints {_joints(table.q(HOVER_S))}") == "true\n"
        assert fox.wait(lambda: table_colour() == GREEN), fox.received("/driver/clearance")[-5:]
        assert client.ask(f"MovePTPJoints {_joints(table.q(table.s_at(30.0)))}") == "true\n"
        assert fox.wait(lambda: table_colour() == AMBER), fox.received("/driver/clearance")[-5:]
        last = fox.received("/driver/clearance")[-1][1]
        assert last["other"] == "table" and last["zone"] and 25.0 <= last["distance_mm"] < 100.0, last
        assert table_colour() == colour(last["distance_mm"], 5.0)
        metadata = {m["key"]: m["value"] for m in entities()["zone:table"]["metadata"]}
        assert metadata["distance_mm"] == f"{last['distance_mm']:.1f}" and metadata["nearest_part"] == last["part"]
        (slab,) = entities()["zone:floor"]["cubes"]
        assert tuple(slab["color"][c] for c in "rgba") == GREY  # not the nearest
    _stopped_cleanly(system.output)
