"""The command table, argument encoding and generated methods of rob6_client (no network)."""

from __future__ import annotations

import ast
import inspect
import math

import pytest

from rob6_client import (
    COMMANDS,
    ROB6_ONLY,
    AsyncRobot,
    Pose,
    Rob6Error,
    Rob6ProtocolError,
    Robot,
    Status,
    normalize_status,
    parse_reply,
)
from rob6_client._stubgen import STUB, stub
from rob6_client.protocol import StatusLike
from rob6_gateway.args import Args
from rob6_gateway.commands import COMMANDS as GATEWAY_COMMANDS


def test_every_protocol_command_has_a_method() -> None:
    """The original's 78 commands and rob6's own GetCell: the gateway's table, one method each."""
    assert set(COMMANDS) == set(GATEWAY_COMMANDS) and len(COMMANDS) == 79 and ROB6_ONLY == {"GetCell"}
    for command in COMMANDS.values():
        assert inspect.isfunction(getattr(Robot, command.method))
        assert inspect.iscoroutinefunction(getattr(AsyncRobot, command.method))
    names = {c.name: c.method for c in COMMANDS.values()}
    assert [names[n] for n in ("MovePTPJoints", "IsKR16", "CM_PING", "SetRTSpeedControl",
                               "GetPositionHomRowWise", "MoveRTHomRowWiseStatus")] == [
        "move_ptp_joints", "is_kr16", "cm_ping", "set_rt_speed_control",
        "get_position_hom_row_wise", "move_rt_hom_row_wise_status"]
    assert len(set(names.values())) == 79 and names["GetCell"] == "get_cell"
    assert inspect.signature(Robot.get_cell).return_annotation == "dict[str, Any]"


def test_generated_signatures_and_docs() -> None:
    signature = inspect.signature(Robot.backward_calc)
    assert list(signature.parameters) == ["self", "pose", "status", "timeout"]
    assert signature.parameters["timeout"].kind is inspect.Parameter.KEYWORD_ONLY
    assert signature.return_annotation == "Joints | None"
    assert inspect.signature(AsyncRobot.ping_robot).parameters["n"].default == 10
    doc = Robot.enable_alter.__doc__
    assert doc is not None and "Original rob6server" in doc and "kr16" in doc


def test_type_stub_is_current() -> None:
    assert STUB.read_text() == stub(), "run: .venv/bin/python -m rob6_client._stubgen"
    stubbed = ast.parse(STUB.read_text())
    methods = {c.name: [f.name for f in c.body if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))]
               for c in stubbed.body if isinstance(c, ast.ClassDef)}
    assert methods["RobotCommands"] == methods["AsyncRobotCommands"] == [c.method for c in COMMANDS.values()]


def encoded(name: str, *values: object) -> Args:
    """What the gateway's argument parser (the original's rules) reads from our line."""
    line = COMMANDS[name].encode(values)
    word, _, rest = line.partition(" ")
    assert word == name and "\n" not in line
    return Args(rest)


@pytest.mark.parametrize("q", [[10, 0, 0, 0, 0, 0], [1e-5, -0.0, 123.456789012345, -1e-12, 1e6, 359.99999999]])
def test_numbers_reach_the_server_exactly(q: list[float] | list[int]) -> None:
    assert encoded("MovePTPJoints", q).joints() == [float(v) for v in q]


def test_poses_flat_rows_or_homogeneous() -> None:
    flat = [0, 0, -1, 1768, 0, -1, 0, 0, -1, 0, 0, 640]
    rows = [flat[0:4], flat[4:8], flat[8:12]]
    for pose in (flat, rows, rows + [[0, 0, 0, 1]], tuple(map(tuple, rows)), Pose(*flat)):
        assert encoded("MovePTPHomRowWise", pose).matrix() == flat
    with pytest.raises(ValueError, match="3 rows of 4"):
        COMMANDS["MovePTPHomRowWise"].encode([rows + [[0, 0, 1, 1]]])
    with pytest.raises(ValueError, match="3 rows of 4"):
        COMMANDS["MovePTPHomRowWise"].encode([[row[:3] for row in rows]])


@pytest.mark.parametrize("words, expected", [
    ("noflip up lefty", ("noflip", "up", "lefty")),
    ("lefty up noflip", ("noflip", "up", "lefty")),
    (["righty", "flip"], ("flip", "toggleElbow", "righty")),
    ("noToggleElbow", ("toggleHand", "noToggleElbow", "toggleArm")),
    (Status("flip", "down", "noToggleArm"), ("flip", "down", "noToggleArm")),
])
def test_status_words_are_sent_normalised(words: StatusLike, expected: tuple[str, ...]) -> None:
    assert normalize_status(words) == expected
    args = encoded("BackwardCalc", [0] * 12, words)
    args.matrix()
    assert args.status() == list(expected)


@pytest.mark.parametrize("words", ["", "NOFLIP", "flip up lefty righty", "up down", "flip extra"])
def test_bad_status_words(words: str) -> None:
    with pytest.raises(ValueError):
        normalize_status(words)


def test_reply_values() -> None:
    pose, status = parse_reply("ForwardCalc", "0.000000 -0.173648 -0.984808 1741.140107 0.000000 -0.984808 "
                                              "0.173648 -307.009978 -1.000000 -0.000000 -0.000000 640.000000\n"
                                              "noflip up lefty\n")
    assert pose.x == 1741.140107 and pose.rows[2] == (-1.0, -0.0, -0.0, 640.0)
    assert str(status) == "noflip up lefty" and status.arm == "lefty"
    assert math.copysign(1, pose.r32) == -1  # -0.000000 stays negative zero
    assert parse_reply("ForwardCalc", "false\n") is None
    assert parse_reply("BackwardCalc", "false\n") is None
    assert parse_reply("PingRobot", "-1\n") is None
    assert parse_reply("PingRobot", "0.001378 0.1680000000 1795422310.4704022408 -0.24351772 0\n").mean_rtt == 0.001378
    assert parse_reply("GetRTSpeedControl", "1\n") == 1
    assert parse_reply("GetTimestamp", "1795317178.341\n") == 1795317178.341
    assert parse_reply("Shutdown", "bye!\nshutting down ...\n") is None
    assert parse_reply("GetCell", '{"margin_mm":5.0,"zones":[{"name":"t\\u00e4ble"}]}\n') == {
        "margin_mm": 5.0, "zones": [{"name": "t\u00e4ble"}]}


@pytest.mark.parametrize(("reply", "error"), [
    ("[1, 2]\n", Rob6ProtocolError), ("{not json\n", Rob6ProtocolError), ("true\n", Rob6ProtocolError),
    ("ERROR: driver unavailable\n", Rob6Error), ("ERROR: GetCell\n", Rob6Error),  # rob6 without a driver; the original
])
def test_get_cell_takes_a_json_object_only(reply: str, error: type[Exception]) -> None:
    with pytest.raises(error):
        parse_reply("GetCell", reply)
