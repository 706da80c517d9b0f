"""The live view with the real system: ``rob6 run`` prints its address, a Foxglove
WebSocket client sees the URDF, every link's transform, the joint state and the command
log, and the arm move when a client drives it through the gateway."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from harness.foxglove_client import FoxgloveClient
from harness.system import running
from rob6.robots import get_robot
from rob6_recorder.service import URDF_DIR

TARGET = [10.0, -60.0, 80.0, 20.0, 40.0, 30.0]
SCHEMAS = {"/robot_description": "std_msgs/String", "/tf": "foxglove.FrameTransforms",
           "/driver/joint_state": "rob6.JointState", "/commands": "foxglove.Log", "/log": "foxglove.Log",
           "/gripper/state": "rob6.GripperState"}


def _links(robot: str) -> tuple[str, set[str]]:
    """The URDF's root link and every other link (a 3D panel needs a transform to each)."""
    root = ET.fromstring((URDF_DIR / f"{get_robot(robot).geometry}.urdf").read_text())
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
