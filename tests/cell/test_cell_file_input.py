"""A cell file as a careless or hostile hand writes it: every malformed file is one line naming
its file and line (never a traceback), every value is bounded; a zone's own margin; the file's
SHA-256; the conventions of a box's ``rpy_deg`` and of the tool (-z out of the flange),
pinned through the model the guard measures with."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import msgspec
import numpy as np
import pinocchio as pin
import pytest

from rob6.cell import CellError, CellModel, default_cell, load_cell
from rob6.cell.file import (
    DEFAULT_FILE,
    MAX_FILE_BYTES,
    MAX_TOOL_SHAPES,
    MAX_ZONES,
    parse_cell,
)
from rob6.messages import Box, Cell, ToolShape, Zone
from rob6.ownership import EXIT_REFUSED
from rob6.robots import ROBOTS, get_robot

BOX = "keep: out, box: {min: [0, 0, 0], max: [1, 1, 1]}"
BILLION_LAUGHS = "\n".join(["margin_mm: 5", "zones:", "  - name: t", "    keep: out",
                            "    box: {min: [0, 0, 0], max: [1, 1, 1]}", "    ignore: &a [link_1, link_1]"]
                           + [f"    x{i}: &a{i} [*{'a' if i == 0 else f'a{i - 1}'}, *{'a' if i == 0 else f'a{i - 1}'}]"
                              for i in range(3)]) + "\n"


def zones(count: int) -> str:
    return "zones:\n" + "".join(f"  - {{name: z{i}, {BOX}}}\n" for i in range(count))


def tool(count: int) -> str:
    return "tool:\n" + "".join(f"  - {{name: t{i}, sphere: {{center: [0, 0, -10], radius: 5}}}}\n" for i in range(count))


# (text, the error; today's answer in the comment)
BROKEN = {
    # OverflowError: int too large to convert to float
    "a 400-digit number": ("margin_mm: " + "9" * 400 + "\n", "line 1: a value of 400 characters (at most 256)"),
    "a 200-digit margin": ("margin_mm: " + "9" * 200 + "\n",
                           "line 1: margin_mm must be at most 1000 mm, not 999999999999... (a number of 200 digits)"),
    "a 200-digit coordinate": (f"zones:\n  - name: t\n    keep: out\n    half_space: {{point: [0, 0, 1{'0' * 199}], "
                               "normal: [0, 0, 1]}\n", "line 4: point must lie within 100000 mm of the base, not [0, 0, "),
    # accepted
    "a box 1000 km long": ("zones:\n  - name: t\n    keep: out\n    box: {min: [0, 0, 0], max: [1e9, 1, 1]}\n",
                           "line 4: max must lie within 100000 mm of the base, not [1000000000.0, 1, 1]"),
    "a plane 1 km away": ("zones:\n  - name: t\n    keep: out\n    half_space: {point: [0, 0, -1000000], "
                          "normal: [0, 0, 1]}\n", "line 4: point must lie within 100000 mm of the base"),
    "a tool 10 m long": ("tool:\n  - {name: tip, capsule: {from: [0, 0, 0], to: [0, 0, -10000], radius: 5}}\n",
                         "line 2: to must lie within 5000 mm of the flange"),
    "a tool sphere 2 m wide": ("tool:\n  - {name: tip, sphere: {center: [0, 0, 0], radius: 2000}}\n",
                               "radius must be at most 1000 mm, not 2000"),
    "a margin of 5 m": ("margin_mm: 5000\n", "line 1: margin_mm must be at most 1000 mm, not 5000"),
    "a padding of 1 km": ("arm:\n  padding_mm: 1000000\n", "line 2: padding_mm must be at most 1000 mm, not 1000000"),
    "a box turned 720 degrees": ("zones:\n  - name: t\n    keep: out\n    box: {min: [0, 0, 0], max: [1, 1, 1], "
                                 "rpy_deg: [0, 0, 720]}\n", "line 4: rpy_deg must lie within ±360 degrees"),
    "a zone's margin of 5 m": (f"zones:\n  - {{name: t, {BOX}, margin_mm: 5000}}\n",
                               "line 2: margin_mm must be at most 1000 mm, not 5000"),
    "too many zones": (zones(MAX_ZONES + 1), f"line {MAX_ZONES + 2}: {MAX_ZONES + 1} zones, at most {MAX_ZONES}"),
    "too many tool shapes": (tool(MAX_TOOL_SHAPES + 1),
                             f"line {MAX_TOOL_SHAPES + 2}: {MAX_TOOL_SHAPES + 1} tool shapes, at most {MAX_TOOL_SHAPES}"),
    "an alias": ("tool:\n  - {name: a, sphere: {center: &c [0, 0, -10], radius: 5}}\n"
                 "  - {name: b, sphere: {center: *c, radius: 5}}\n", "line 3: an alias (*c): a cell file has no anchors"),
    "a billion laughs": (BILLION_LAUGHS, "line 7: an alias (*a)"),
    "a tool shape and a zone of one name": (f"tool:\n  - {{name: gripper, sphere: {{center: [0, 0, -10], radius: 5}}}}\n"
                                            f"zones:\n  - {{name: gripper, {BOX}}}\n",
                                            "line 4: zone name 'gripper' is taken by a tool shape: names must differ"),
    "a zone named after a link": (f"zones:\n  - {{name: link_3, {BOX}}}\n",
                                  "line 2: zone name 'link_3' is taken by a part of the arm"),
    "a name on two lines": (f"zones:\n  - {{name: \"table\\nfalse\", {BOX}}}\n",
                            "line 2: every zone needs a name of at most 64 printable characters on one line"),
    "a name of 100 characters": (f"zones:\n  - {{name: {'t' * 100}, {BOX}}}\n",
                                 "line 2: every zone needs a name of at most 64 printable characters"),
    "a zone asking for less room": (f"margin_mm: 10\nzones:\n  - {{name: t, {BOX}, margin_mm: 4}}\n",
                                    "line 3: zone 't': margin_mm 4 is less than the cell's margin_mm 10: a zone may "
                                    "ask for more room, not less"),
    # RecursionError: maximum recursion depth exceeded
    "nested 5000 deep": ("zones: " + "[" * 5000 + "]" * 5000 + "\n", "line 1: nested more than 10 deep"),
    # ReaderError: unacceptable character #x0000
    "a NUL character": ("margin_mm: 5\nzones: []\x00\n", "line 2: not YAML: character '\\x00' is not allowed"),
    # refused already today: pinned
    "a duplicate key": ("margin_mm: 5\nzones: []\nmargin_mm: 6\n", "line 3: not YAML: found duplicate key \"margin_mm\""),
    "a duplicate key in a box": ("zones:\n  - name: t\n    keep: out\n    box: {min: [0, 0, 0], max: [1, 1, 1], "
                                 "min: [0, 0, 0]}\n", "line 4: not YAML: found duplicate key \"min\""),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_file_is_one_line_naming_the_file_and_line(case: str) -> None:
    text, error = BROKEN[case]
    with pytest.raises(CellError) as refused:
        parse_cell(text, "lab.yaml")
    message = str(refused.value)
    assert message.startswith("cell file lab.yaml line ") and "\n" not in message and len(message) < 250, message
    assert error in message, message


def test_a_file_not_in_utf8_names_its_line_and_byte(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"  # today: UnicodeDecodeError, a traceback
    path.write_bytes("margin_mm: 5\nzones:\n  - name: Tisch (Gerät)\n".encode("latin-1"))
    with pytest.raises(CellError, match=r"^cell file .*latin1\.yaml line 3: not UTF-8 text \(byte 0xe4 at column 21\): "
                                        r"save the file as UTF-8$"):
        load_cell(path)


def test_a_huge_file_is_refused_without_reading_it_all(tmp_path: Path) -> None:
    path = tmp_path / "huge.yaml"  # today: read whole and accepted (comments)
    path.write_bytes(b"margin_mm: 5\n" + b"# ...\n" * (MAX_FILE_BYTES // 6 + 1))
    with pytest.raises(CellError, match=r"^cell file .*huge\.yaml line \d+: the file goes on beyond 256 KiB"):
        load_cell(path)
    with pytest.raises(CellError, match=r"^cell file lab.yaml line \d+: the file goes on beyond 256 KiB"):
        parse_cell(path.read_text(), "lab.yaml")


def test_the_bounds_themselves_are_accepted() -> None:
    cell = parse_cell(zones(MAX_ZONES) + tool(MAX_TOOL_SHAPES) + "margin_mm: 1000\narm: {padding_mm: 1000}\n", "lab.yaml")
    assert len(cell.zones) == MAX_ZONES and len(cell.tool) == MAX_TOOL_SHAPES and cell.margin_mm == 1000.0
    far = parse_cell("zones:\n  - name: t\n    keep: in\n    box: {min: [-100000, -100000, -100000], "
                     "max: [100000, 100000, 100000], rpy_deg: [-360, 0, 360]}\n", "lab.yaml")
    assert far.zones[0].box == Box(min=[-1e5] * 3, max=[1e5] * 3, rpy_deg=[-360.0, 0.0, 360.0])


# ---------------------------------------------------------------------- through the driver
@pytest.mark.parametrize("case", ["not UTF-8", "a 400-digit number", "nested 5000 deep", "a box 1000 km long",
                                  "a tool shape and a zone of one name", "too many zones"])
def test_the_driver_refuses_a_broken_cell_in_one_line(case: str, tmp_path: Path) -> None:
    """``rob6-driver --cell`` (its real entry point, as ``make run`` starts it) exits refused
    with the one line; today the first three end in a traceback (exit 1)."""
    path = tmp_path / "lab-cell.yaml"
    if case == "not UTF-8":
        path.write_bytes(b"zones:\n  - name: caf\xe9\n")
        error = "line 2: not UTF-8 text (byte 0xe9 at column 14)"
    else:
        text, error = BROKEN[case]
        path.write_text(text, encoding="utf-8")
    result = subprocess.run([sys.executable, "-m", "rob6_driver", "--robot", "kr16", "--cell", str(path)],
                            capture_output=True, check=False, text=True, timeout=60)
    assert result.returncode == EXIT_REFUSED and result.stdout == "", result.stdout + result.stderr
    (line,) = result.stderr.splitlines()
    assert line.startswith(f"rob6-driver: cell file {path} line ") and error in line, result.stderr


# ---------------------------------------------------------------------- a zone's own margin
def test_a_zone_may_ask_for_more_room_than_the_cell() -> None:
    cell = parse_cell(f"margin_mm: 5\nzones:\n  - {{name: press, {BOX}, margin_mm: 120}}\n  - {{name: table, {BOX}}}\n"
                      "  - name: wall\n    keep: out\n    half_space: {point: [0, 0, 0], normal: [1, 0, 0]}\n"
                      "    margin_mm: 5\n", "lab.yaml")
    press, table, wall = cell.zones
    assert (press.margin_mm, table.margin_mm, wall.margin_mm) == (120.0, None, 5.0)
    with pytest.raises(CellError, match=r"line 2: margin_mm must be a number, not 'far'"):
        parse_cell(f"zones:\n  - {{name: press, {BOX}, margin_mm: far}}\n", "lab.yaml")
    with pytest.raises(CellError, match=r"line 3: margin_mm must be at least 0, not -1"):
        parse_cell(f"margin_mm: 0\nzones:\n  - {{name: press, {BOX}, margin_mm: -1}}\n", "lab.yaml")


# ---------------------------------------------------------------------- the file's hash
def test_the_cell_carries_the_sha256_of_its_files_bytes(tmp_path: Path) -> None:
    path = tmp_path / "lab.yaml"
    path.write_bytes(f"margin_mm: 5\nzones:\n  - {{name: table, {BOX}}}\n".encode())
    first = load_cell(path)
    assert first.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    path.write_bytes(path.read_bytes() + b"# moved the table\n")  # the same cell, another file
    assert load_cell(path).sha256 == hashlib.sha256(path.read_bytes()).hexdigest() != first.sha256
    assert parse_cell("margin_mm: 5\n", "x").sha256 == hashlib.sha256(b"margin_mm: 5\n").hexdigest()
    for robot in sorted(ROBOTS):
        assert default_cell(ROBOTS[robot]).sha256 == hashlib.sha256(DEFAULT_FILE.read_bytes()).hexdigest()


def test_a_recorded_cell_without_the_new_fields_still_reads() -> None:
    """A recording made before ``sha256`` and a zone's ``margin_mm``: both at their defaults."""
    old = (b'{"source":"lab.yaml","margin_mm":5.0,"zones":[{"name":"t","keep":"out",'
           b'"box":{"min":[0,0,0],"max":[1,1,1]}}],"tool":[],"from_file":true}')
    cell = msgspec.json.decode(old, type=Cell)
    assert cell.sha256 == "" and cell.zones[0].margin_mm is None
    new = parse_cell(f"zones:\n  - {{name: t, {BOX}, margin_mm: 20}}\n", "lab.yaml")
    assert msgspec.json.decode(msgspec.json.encode(new), type=Cell) == new


def test_the_recorders_cell_schema_has_the_new_fields() -> None:
    from rob6_recorder.schemas import CELL

    assert "sha256" in CELL["properties"], CELL
    assert "margin_mm" in CELL["$defs"]["Zone"]["properties"], CELL


# ---------------------------------------------------------------------- conventions, measured
def _flange(robot: str, q: list[float]) -> pin.SE3:
    model = pin.buildModelFromXML(get_robot(robot).urdf)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.radians(q))
    return data.oMf[model.getFrameId("flange")]


def _probe_distances(robot: str, boxes: dict[str, Box], q: list[float]) -> dict[str, float]:
    """How far a 10 mm sphere at the flange's origin is from each box (mm), measured by ``CellModel``."""
    cell = Cell(source="test", margin_mm=0.0, self_collision=False,
                tool=[ToolShape(name="probe", radius=10.0, a=[0.0, 0.0, 0.0])],
                zones=[Zone(name=name, keep="out", box=box) for name, box in boxes.items()])
    model = CellModel(get_robot(robot), cell)
    distances = model.distances(np.array(q))
    return {pair.other: float(d) for pair, d in zip(model.pairs, distances, strict=True) if pair.part == "probe"}


@pytest.mark.parametrize("robot", ["kr16", "ad850"])
def test_rpy_deg_turns_a_box_about_its_centre_about_fixed_x_then_y_then_z(robot: str) -> None:
    """Half-extents (200, 100, 50) along the box's own x, y, z; the box's centre 300 mm from the
    probe along the base's x (``along_x``), y or z. What the probe measures is 300 - 10 less the
    box's half-extent along that base axis. ``[0, 0, 90]`` swaps x and y; ``[90, 0, 90]`` (fixed
    axes: roll about x first, then yaw about z) puts the box's z along base x, its x along base
    y, its y along base z; moving axes (x, then the new z) would give 100 along base x."""
    q = [0.0, -90.0, 90.0, 0.0, 30.0, 0.0]
    p = _flange(robot, q).translation * 1000.0
    half = np.array([200.0, 100.0, 50.0])

    def boxes(rpy: list[float]) -> dict[str, Box]:
        out: dict[str, Box] = {}
        for axis, name in enumerate(("along_x", "along_y", "along_z")):
            centre = p + 300.0 * np.eye(3)[axis]
            out[name] = Box(min=list(centre - half), max=list(centre + half), rpy_deg=rpy)
        return out

    def extents(rpy: list[float]) -> list[float]:
        measured = _probe_distances(robot, boxes(rpy), q)
        return [300.0 - 10.0 - measured[name] for name in ("along_x", "along_y", "along_z")]

    assert extents([0, 0, 0]) == pytest.approx([200.0, 100.0, 50.0], abs=1e-3)
    assert extents([0, 0, 90]) == pytest.approx([100.0, 200.0, 50.0], abs=1e-3)
    assert extents([90, 0, 0]) == pytest.approx([200.0, 50.0, 100.0], abs=1e-3)
    assert extents([0, 90, 0]) == pytest.approx([50.0, 100.0, 200.0], abs=1e-3)
    assert extents([90, 0, 90]) == pytest.approx([50.0, 200.0, 100.0], abs=1e-3)


@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_a_tool_along_minus_z_sticks_out_of_the_flange(robot: str) -> None:
    """The flange frame's z points into the wrist: a point 100 mm along -z is 100 mm farther
    from the wrist's centre (joint 5) than the flange, one along +z lies back inside the wrist."""
    q = [10.0, -80.0, 70.0, 20.0, 40.0, 30.0]
    flange = _flange(robot, q)
    model = pin.buildModelFromXML(get_robot(robot).urdf)
    data = model.createData()
    pin.forwardKinematics(model, data, np.radians(q))
    wrist = data.oMi[5].translation
    out, back = (float(np.linalg.norm(flange.act(np.array([0.0, 0.0, z])) - wrist)) for z in (-0.1, 0.1))
    reach = float(np.linalg.norm(flange.translation - wrist))
    assert out == pytest.approx(reach + 0.1, abs=1e-9) and back < reach
