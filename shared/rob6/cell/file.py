"""Reading a cell file (YAML): every value checked, every error naming its line.

The format (all lengths in mm; docs/SAFETY_ZONES.md)::

    margin_mm: 5                     # kept clear of every zone and between parts of the arm
    zones:                           # in the robot's base frame (x forward at q1 = 0, z up)
      - name: table
        keep: out                    # out: no part may enter it; in: no part may leave it
        half_space: {point: [0, 0, 120], normal: [0, 0, 1]}   # normal: towards the arm's side
      - name: fixture
        keep: out
        box: {min: [500, -100, 120], max: [700, 100, 300], rpy_deg: [0, 0, 30]}
        ignore: [tool tip]           # parts never checked against this zone
        margin_mm: 40                # this zone wants more room than the cell's margin
    tool:                            # in the flange frame: the tool sticks out along -z
      - {name: gripper, capsule: {from: [0, 0, 0], to: [0, 0, -120], radius: 40}}
      - {name: tool tip, sphere: {center: [0, 0, -150], radius: 10}}
    arm:
      self_collision: true
      padding_mm: 0                  # added around every shape of the arm, or per part:
                                     # {link_3: 20, link_6: 30, default: 0}
      allowed_pairs: [[link_2, gripper]]   # may touch, beyond the adjacent parts

A keep-in zone is a box. Parts are the arm's links ``link_1`` ... ``link_6`` (and
``base``) and the tool's shapes by name; a zone's name is neither.

**The tool** rides on the URDF's ``flange`` frame, whose z axis points *into* the flange
(towards the wrist): a tool sticks out along **-z**, so a gripper 120 mm long is
``from: [0, 0, 0], to: [0, 0, -120]``. A shape along +z lies inside the wrist.

**A box's rpy_deg** ``[r, p, y]`` (degrees) turns the box about its own centre, the middle of
``min`` and ``max``: first by ``r`` about the base frame's x axis, then by ``p`` about the
base frame's y axis, then by ``y`` about the base frame's z axis (fixed axes, URDF's and
ROS's roll-pitch-yaw; the same turn as yaw about z, then pitch about the new y, then roll
about the newest x). Its rotation matrix is ``Rz(y) @ Ry(p) @ Rx(r)``, and a corner ``c`` of
the box before the turn lies at ``centre + R @ (c - centre)``. ``min`` and ``max`` are the
corners before the turn: ``rpy_deg: [0, 0, 90]`` swaps a box's extents along x and y.

**Bounds.** A file is refused, in one line naming the file and the line, when it is not
UTF-8 text, larger than ``MAX_FILE_BYTES``, nested deeper than ``MAX_DEPTH``, uses YAML
anchors and aliases (``&a`` / ``*a``: the way a "billion laughs" file grows), repeats a key,
has a value longer than ``MAX_SCALAR_CHARS`` characters, more than ``MAX_ZONES`` zones or
``MAX_TOOL_SHAPES`` tool shapes, a coordinate beyond ``MAX_COORDINATE_MM`` of the base
(``MAX_TOOL_MM`` of the flange for the tool), an angle beyond ``MAX_ANGLE_DEG``, or a
radius, margin or padding beyond ``MAX_LENGTH_MM``.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

from ruamel.yaml import YAML
from ruamel.yaml.error import MarkedYAMLError, YAMLError
from ruamel.yaml.events import (
    AliasEvent,
    CollectionEndEvent,
    CollectionStartEvent,
    ScalarEvent,
)
from ruamel.yaml.reader import ReaderError

from ..errors import InputError
from ..messages import Box, Cell, HalfSpace, ToolShape, Zone
from ..robots import RobotModel

#: the cell of every robot type when ROB6_CELL is not set: the floor at the base, self-collision on
DEFAULT_FILE = Path(__file__).with_name("default.yaml")
#: kept clear of every zone when the file does not say (mm)
DEFAULT_MARGIN_MM = 5.0
#: the arm's parts, as the URDF names its links (rob6/urdf): what ``ignore`` and ``allowed_pairs`` may name
ARM_PARTS = ("base", "link_1", "link_2", "link_3", "link_4", "link_5", "link_6")

# The bounds of a cell file. Each refusal names the bound and the line that crosses it.
#: a lab's cell is a few kilobytes (a zone is 4-5 lines); more is the wrong file or a generated bomb
MAX_FILE_BYTES = 256 * 1024
#: the format nests 5 deep (the file, zones, a zone, its box, a corner); more is not a cell
MAX_DEPTH = 10
#: the longest value (a name, a number): a 400-digit number is a typo, not a length
MAX_SCALAR_CHARS = 256
#: the longest name of a zone or a tool shape: it goes into one-line errors and the live view
MAX_NAME_CHARS = 64
#: zones, and shapes of the tool: every setpoint check measures every part against every zone
#: within the 4 ms RSI cycle (100 boxes took 4.45 ms, issue 56); a lab names a handful
MAX_ZONES = 32
MAX_TOOL_SHAPES = 16
#: a zone's coordinates lie within 100 m of the robot's base (mm): farther is a unit mistake (m as mm)
MAX_COORDINATE_MM = 100_000.0
#: a tool shape's coordinates lie within 5 m of the flange (mm)
MAX_TOOL_MM = 5_000.0
#: a box's roll, pitch and yaw (degrees)
MAX_ANGLE_DEG = 360.0
#: the largest radius of a tool shape, margin (the cell's, a zone's) and padding (mm): a metre
#: of room all round is already more than any stopping distance of the arms rob6 drives
MAX_LENGTH_MM = 1_000.0
#: the keys whose number is a length bounded by MAX_LENGTH_MM, wherever they appear
_LENGTH_KEYS = ("margin_mm", "padding_mm", "radius", "default", *ARM_PARTS)


class CellError(InputError):
    """A cell file that cannot be used: the message names the file, the line and the fix."""


def load_cell(path: str | Path) -> Cell:
    """The cell described in ``path``; raises ``CellError`` naming the line of the first problem.
    Its ``sha256`` is the file's bytes': a changed file shows in the driver's log, ``GetCell``
    and every recording."""
    path = Path(path)
    try:
        with path.open("rb") as file:
            data = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise CellError(f"cell file {path}: cannot be read: {exc.strerror or exc}") from None
    if len(data) > MAX_FILE_BYTES:
        line = data.count(b"\n", 0, MAX_FILE_BYTES) + 1
        raise CellError(f"cell file {path} line {line}: the file goes on beyond {MAX_FILE_BYTES // 1024} KiB "
                        f"(a cell file is a few kilobytes): is it the right file?")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise CellError(f"cell file {path} line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x} at column "
                        f"{column}): save the file as UTF-8") from None
    return parse_cell(text, str(path), sha256=hashlib.sha256(data).hexdigest())


def default_cell(robot: RobotModel) -> Cell:
    """The cell of ``robot`` when ROB6_CELL is not set (``default.yaml``)."""
    cell = load_cell(DEFAULT_FILE)
    cell.source, cell.from_file = f"default {robot.name}", False
    return cell


def parse_cell(text: str, source: str, sha256: str | None = None) -> Cell:
    """The cell described by ``text`` (read from ``source``); ``sha256``: of the file's bytes
    (default: of ``text`` in UTF-8)."""
    reader = _Reader(source)
    if len(text) > MAX_FILE_BYTES:
        raise reader.error(text.count("\n", 0, MAX_FILE_BYTES),
                           f"the file goes on beyond {MAX_FILE_BYTES // 1024} KiB (a cell file is a few kilobytes)")
    doc = _load(text, reader)
    if doc is None:
        doc = {}
    top = reader.mapping(doc, None, "the file", ("margin_mm", "zones", "tool", "arm"))
    margin = reader.number(top, "margin_mm", DEFAULT_MARGIN_MM, minimum=0.0)
    tool_items = reader.items(top, "tool", most=MAX_TOOL_SHAPES, what="tool shapes")
    tool = [reader.tool_shape(item, line) for item, line in tool_items]
    arm = reader.mapping(top.get("arm", {}), reader.line_of(top, "arm"), "arm",
                         ("self_collision", "padding_mm", "allowed_pairs"))
    parts = set(ARM_PARTS) | {shape.name for shape in tool}
    _unique(reader, [(shape.name, line) for shape, (_, line) in zip(tool, tool_items, strict=True)],
            "tool shape", reserved=dict.fromkeys(ARM_PARTS, "a part of the arm"))
    zone_items = reader.items(top, "zones", most=MAX_ZONES, what="zones")
    zones = [reader.zone(item, line, parts, margin) for item, line in zone_items]
    _unique(reader, [(zone.name, line) for zone, (_, line) in zip(zones, zone_items, strict=True)],
            "zone", reserved={**dict.fromkeys(ARM_PARTS, "a part of the arm"),
                              **{shape.name: "a tool shape" for shape in tool}})
    self_collision = reader.boolean(arm, "self_collision", True)
    padding, part_padding = reader.padding(arm)
    pairs = []
    for item, line in reader.items(arm, "allowed_pairs"):
        pair = reader.names(item, line, "an allowed pair", parts)
        if len(pair) != 2 or pair[0] == pair[1]:
            raise reader.error(line, f"an allowed pair names two different parts, not {pair}")
        pairs.append(pair)
    return Cell(source=source, margin_mm=margin, zones=zones, tool=tool, self_collision=self_collision,
                arm_padding_mm=padding, arm_padding_parts=part_padding, allowed_pairs=pairs,
                sha256=sha256 if sha256 is not None else hashlib.sha256(text.encode("utf-8")).hexdigest())


def _load(text: str, reader: _Reader) -> Any:
    """The YAML document of ``text``, after a look at its events (cheap, flat: no recursion)
    has refused what would make the loader recurse, grow or convert without bound."""
    yaml = YAML(typ="rt", pure=True)
    try:
        depth = 0
        for event in yaml.parse(text):
            line = event.start_mark.line if event.start_mark is not None else None
            if isinstance(event, AliasEvent):
                raise reader.error(line, f"an alias (*{event.anchor}): a cell file has no anchors and aliases "
                                         f"(&name, *name); write each value out")
            if isinstance(event, CollectionStartEvent):
                depth += 1
                if depth > MAX_DEPTH:
                    raise reader.error(line, f"nested more than {MAX_DEPTH} deep: not a cell file")
            elif isinstance(event, CollectionEndEvent):
                depth -= 1
            elif isinstance(event, ScalarEvent) and len(event.value) > MAX_SCALAR_CHARS:
                raise reader.error(line, f"a value of {len(event.value)} characters "
                                         f"(at most {MAX_SCALAR_CHARS}): {_plain(event.value)}")
        return yaml.load(text)
    except MarkedYAMLError as exc:  # a duplicate key too
        mark = exc.problem_mark or exc.context_mark
        raise reader.error(mark.line if mark is not None else None,
                           f"not YAML: {exc.problem or exc.context}") from None
    except ReaderError as exc:  # a character YAML does not allow (a NUL, a control character)
        line = text.count("\n", 0, exc.position) if isinstance(exc.position, int) else None
        character = chr(exc.character) if isinstance(exc.character, int) else str(exc.character)
        raise reader.error(line, f"not YAML: character {character!r} is not allowed") from None
    except YAMLError as exc:
        raise reader.error(None, f"not YAML: {exc}") from None


def _unique(reader: _Reader, named: list[tuple[str, int | None]], what: str, reserved: dict[str, str]) -> None:
    """Every name in ``named`` differs from the others and from the ``reserved`` ones (name -> whose)."""
    seen: set[str] = set()
    for name, line in named:
        if name in seen or name in reserved:
            taken = reserved.get(name, f"another {what}")
            raise reader.error(line, f"{what} name {name!r} is taken by {taken}: names must differ")
        seen.add(name)


class _Reader:
    """Values out of the YAML document, each checked, with the line it came from."""

    def __init__(self, source: str) -> None:
        self.source = source

    def error(self, line: int | None, message: str) -> CellError:
        where = f" line {line + 1}" if line is not None else ""
        return CellError(f"cell file {self.source}{where}: {message}")

    @staticmethod
    def line_of(mapping: Any, key: str) -> int | None:
        try:
            return int(mapping.lc.key(key)[0])
        except (AttributeError, KeyError, TypeError):
            return None

    @staticmethod
    def line_of_item(sequence: Any, index: int) -> int | None:
        try:
            return int(sequence.lc.item(index)[0])
        except (AttributeError, KeyError, TypeError, IndexError):
            return None

    def mapping(self, value: Any, line: int | None, what: str, keys: tuple[str, ...]) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(line, f"{what} must be a mapping of {', '.join(keys)}")
        for key in value:
            if key not in keys:
                raise self.error(self.line_of(value, key) if isinstance(key, str) else line,
                                 f"unknown key {key!r} in {what} (expected {', '.join(keys)})")
        return value

    def items(self, mapping: dict[str, Any], key: str, *, most: int | None = None,
              what: str = "") -> list[tuple[Any, int | None]]:
        value = mapping.get(key, [])
        if value is None:
            return []
        if not isinstance(value, list):
            raise self.error(self.line_of(mapping, key), f"{key} must be a list")
        if most is not None and len(value) > most:
            raise self.error(self.line_of_item(value, most) or self.line_of(mapping, key),
                             f"{len(value)} {what or key}, at most {most}: every setpoint check measures each "
                             f"of them, within the driver's cycle")
        return [(item, self.line_of_item(value, i)) for i, item in enumerate(value)]

    def number(self, mapping: dict[str, Any], key: str, default: float | None = None, *,
               minimum: float | None = None, positive: bool = False) -> float:
        """A number; a radius, margin or padding (``_LENGTH_KEYS``) at most ``MAX_LENGTH_MM``,
        any other at most ``MAX_COORDINATE_MM`` (an int of any size is compared, never converted)."""
        line = self.line_of(mapping, key)
        if key not in mapping:
            if default is None:
                raise self.error(getattr(getattr(mapping, "lc", None), "line", None), f"{key} is missing")
            return default
        value = mapping[key]
        if not _is_number(value):
            raise self.error(line, f"{key} must be a number, not {_plain(value)}")
        if (minimum is not None and value < minimum) or (positive and value <= 0):
            bound = "above 0" if positive else f"at least {minimum:g}"
            raise self.error(line, f"{key} must be {bound}, not {_plain(value)}")
        most = MAX_LENGTH_MM if key in _LENGTH_KEYS else MAX_COORDINATE_MM
        if abs(value) > most:
            raise self.error(line, f"{key} must be at most {most:g} mm, not {_plain(value)}")
        return float(value)

    def padding(self, arm: dict[str, Any]) -> tuple[float, dict[str, float]]:
        """``padding_mm``: one number for every part, or a mapping of parts (and ``default``) to numbers."""
        value = arm.get("padding_mm")
        if not isinstance(value, dict):
            return self.number(arm, "padding_mm", 0.0, minimum=0.0), {}
        parts = self.mapping(value, self.line_of(arm, "padding_mm"), "padding_mm", ("default", *ARM_PARTS))
        own = {str(part): self.number(parts, str(part), minimum=0.0) for part in parts if part != "default"}
        return self.number(parts, "default", 0.0, minimum=0.0), own

    def boolean(self, mapping: dict[str, Any], key: str, default: bool) -> bool:
        value = mapping.get(key, default)
        if not isinstance(value, bool):
            raise self.error(self.line_of(mapping, key), f"{key} must be true or false, not {value!r}")
        return value

    def vector(self, mapping: dict[str, Any], key: str, line: int | None, *,
               limit: float = MAX_COORDINATE_MM, unit: str = "mm", of: str = "the base") -> list[float]:
        """Three numbers, each within ``limit`` (``unit``) of ``of``."""
        if key not in mapping:
            raise self.error(line, f"{key} is missing (three numbers, {unit})")
        value = mapping[key]
        at = self.line_of(mapping, key)
        if not isinstance(value, list) or len(value) != 3 or not all(_is_number(v) for v in value):
            raise self.error(at, f"{key} must be three numbers, not {_plain(value)}")
        if any(abs(v) > limit for v in value):
            within = f"{limit:g} {unit} of {of}" if unit == "mm" else f"±{limit:g} {unit}"
            raise self.error(at, f"{key} must lie within {within}, not {_plain(value)}")
        return [float(v) for v in value]

    def name(self, mapping: dict[str, Any], line: int | None, what: str) -> str:
        value = mapping.get("name")
        at = self.line_of(mapping, "name") or line
        if not isinstance(value, str) or not value.strip():
            raise self.error(at, f"{what} needs a name")
        if len(value.strip()) > MAX_NAME_CHARS or not value.isprintable():
            raise self.error(at, f"{what} needs a name of at most {MAX_NAME_CHARS} printable characters on one "
                                 f"line, not {value!r:.80}")
        return value.strip()

    def names(self, value: Any, line: int | None, what: str, parts: set[str]) -> list[str]:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(line, f"{what} must be a list of part names, not {_plain(value)}")
        for name in value:
            if name not in parts:
                raise self.error(line, f"{what}: no part is called {name!r} (parts: {', '.join(sorted(parts))})")
        return [str(v) for v in value]

    def zone(self, item: Any, line: int | None, parts: set[str], cell_margin: float) -> Zone:
        zone = self.mapping(item, line, "a zone", ("name", "keep", "half_space", "box", "ignore", "margin_mm"))
        name = self.name(zone, line, "every zone")
        margin: float | None = None
        if "margin_mm" in zone:
            margin = self.number(zone, "margin_mm", minimum=0.0)
            if margin < cell_margin:
                raise self.error(self.line_of(zone, "margin_mm"),
                                 f"zone {name!r}: margin_mm {margin:g} is less than the cell's margin_mm "
                                 f"{cell_margin:g}: a zone may ask for more room, not less")
        keep = zone.get("keep")
        if keep not in ("out", "in"):
            raise self.error(self.line_of(zone, "keep") or line,
                             f"zone {name!r}: keep must be out or in, not {_plain(keep)}")
        shapes = [key for key in ("half_space", "box") if key in zone]
        if len(shapes) != 1:
            raise self.error(line, f"zone {name!r} needs exactly one shape: half_space or box")
        ignore = self.names(zone.get("ignore", []), self.line_of(zone, "ignore") or line,
                            f"zone {name!r}: ignore", parts)
        at = self.line_of(zone, shapes[0])
        if shapes[0] == "half_space":
            if keep == "in":
                raise self.error(at, f"zone {name!r}: a keep-in zone must be a box (a half-space to stay in is "
                                     f"a keep-out half-space with the normal turned round)")
            plane = self.mapping(zone["half_space"], at, f"zone {name!r}: half_space", ("point", "normal"))
            normal = self.vector(plane, "normal", at)
            length = math.sqrt(sum(v * v for v in normal))
            if length < 1e-9:
                raise self.error(self.line_of(plane, "normal") or at, f"zone {name!r}: the normal is zero")
            return Zone(name=name, keep="out", ignore=ignore, margin_mm=margin,
                        half_space=HalfSpace(point=self.vector(plane, "point", at), normal=[v / length for v in normal]))
        box = self.mapping(zone["box"], at, f"zone {name!r}: box", ("min", "max", "rpy_deg"))
        low, high = self.vector(box, "min", at), self.vector(box, "max", at)
        if not all(hi > lo for lo, hi in zip(low, high, strict=True)):
            raise self.error(self.line_of(box, "max") or at, f"zone {name!r}: max must be above min on every axis")
        rpy = (self.vector(box, "rpy_deg", at, limit=MAX_ANGLE_DEG, unit="degrees") if "rpy_deg" in box
               else [0.0, 0.0, 0.0])
        return Zone(name=name, keep=keep, ignore=ignore, margin_mm=margin, box=Box(min=low, max=high, rpy_deg=rpy))

    def tool_shape(self, item: Any, line: int | None) -> ToolShape:
        shape = self.mapping(item, line, "a tool shape", ("name", "sphere", "capsule"))
        name = self.name(shape, line, "every tool shape")
        kinds = [key for key in ("sphere", "capsule") if key in shape]
        if len(kinds) != 1:
            raise self.error(line, f"tool shape {name!r} is either a sphere or a capsule")
        at = self.line_of(shape, kinds[0])
        if kinds[0] == "sphere":
            sphere = self.mapping(shape["sphere"], at, f"tool shape {name!r}: sphere", ("center", "radius"))
            return ToolShape(name=name, radius=self.number(sphere, "radius", positive=True),
                             a=self.vector(sphere, "center", at, limit=MAX_TOOL_MM, of="the flange"))
        capsule = self.mapping(shape["capsule"], at, f"tool shape {name!r}: capsule", ("from", "to", "radius"))
        return ToolShape(name=name, radius=self.number(capsule, "radius", positive=True),
                         a=self.vector(capsule, "from", at, limit=MAX_TOOL_MM, of="the flange"),
                         b=self.vector(capsule, "to", at, limit=MAX_TOOL_MM, of="the flange"))


def _is_number(value: Any) -> bool:
    """An int or a finite float (not a bool); an int of any size: bounds compare it exactly."""
    if isinstance(value, bool):
        return False
    return isinstance(value, int) or (isinstance(value, float) and math.isfinite(value))


#: the longest value an error message shows
_SHOWN_CHARS = 60


def _plain(value: Any) -> str:
    """A YAML value as the user wrote it, for an error message (ruamel's types print oddly),
    at most ``_SHOWN_CHARS`` characters (a 400-digit number: its first digits and its length)."""
    if isinstance(value, list):
        text = "[" + ", ".join(_plain(v) for v in value[:8]) + (", ...]" if len(value) > 8 else "]")
    elif isinstance(value, dict):
        text = "{" + ", ".join(f"{k}: {_plain(v)}" for k, v in list(value.items())[:8]) + "}"
    elif isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** _SHOWN_CHARS:
        return f"{str(value)[:12]}... (a number of {len(str(abs(value)))} digits)"
    else:
        text = repr(value) if isinstance(value, str) else str(value)
    return text if len(text) <= _SHOWN_CHARS else text[:_SHOWN_CHARS - 3] + "..."
