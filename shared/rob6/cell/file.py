"""Reading a cell file (YAML): every value checked, every error naming its line.

The format (all lengths in mm, robot base frame; docs/SAFETY_ZONES.md)::

    margin_mm: 5                     # kept clear of every zone and between parts of the arm
    zones:
      - name: table
        keep: out                    # out: no part may enter it; in: no part may leave it
        half_space: {point: [0, 0, 120], normal: [0, 0, 1]}   # normal: towards the arm's side
      - name: fixture
        keep: out
        box: {min: [500, -100, 120], max: [700, 100, 300], rpy_deg: [0, 0, 30]}
        ignore: [tool tip]           # parts never checked against this zone
    tool:
      - {name: gripper, capsule: {from: [0, 0, 0], to: [0, 0, 120], radius: 40}}
      - {name: tool tip, sphere: {center: [0, 0, 150], radius: 10}}
    arm:
      self_collision: true
      padding_mm: 0                  # added around every shape of the arm, or per part:
                                     # {link_3: 20, link_6: 30, default: 0}
      allowed_pairs: [[link_2, gripper]]   # may touch, beyond the adjacent parts

A keep-in zone is a box. Parts are the arm's links ``link_1`` ... ``link_6`` (and
``base``) and the tool's shapes by name.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ruamel.yaml import YAML
from ruamel.yaml.error import MarkedYAMLError

from ..errors import InputError
from ..messages import Box, Cell, HalfSpace, ToolShape, Zone
from ..robots import RobotModel

#: the cell of every robot type when ROB6_CELL is not set: the floor at the base, self-collision on
DEFAULT_FILE = Path(__file__).with_name("default.yaml")
#: kept clear of every zone when the file does not say (mm)
DEFAULT_MARGIN_MM = 5.0
#: the arm's parts, as the URDF names its links (rob6/urdf): what ``ignore`` and ``allowed_pairs`` may name
ARM_PARTS = ("base", "link_1", "link_2", "link_3", "link_4", "link_5", "link_6")


class CellError(InputError):
    """A cell file that cannot be used: the message names the file, the line and the fix."""


def load_cell(path: str | Path) -> Cell:
    """The cell described in ``path``; raises ``CellError`` naming the line of the first problem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise CellError(f"cell file {path}: cannot be read: {exc.strerror or exc}") from None
    return parse_cell(text, str(path))


def default_cell(robot: RobotModel) -> Cell:
    """The cell of ``robot`` when ROB6_CELL is not set (``default.yaml``)."""
    cell = load_cell(DEFAULT_FILE)
    cell.source, cell.from_file = f"default {robot.name}", False
    return cell


def parse_cell(text: str, source: str) -> Cell:
    try:
        doc = YAML(typ="rt", pure=True).load(text)
    except MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise CellError(f"cell file {source}{where}: not YAML: {exc.problem or exc.context}") from None
    reader = _Reader(source)
    if doc is None:
        doc = {}
    top = reader.mapping(doc, None, "the file", ("margin_mm", "zones", "tool", "arm"))
    margin = reader.number(top, "margin_mm", DEFAULT_MARGIN_MM, minimum=0.0)
    tool = [reader.tool_shape(item, line) for item, line in reader.items(top, "tool")]
    arm = reader.mapping(top.get("arm", {}), reader.line_of(top, "arm"), "arm",
                         ("self_collision", "padding_mm", "allowed_pairs"))
    parts = set(ARM_PARTS) | {shape.name for shape in tool}
    _unique(reader, [(shape.name, line) for shape, (_, line) in zip(tool, reader.items(top, "tool"), strict=True)],
            "tool shape", reserved=set(ARM_PARTS))
    zones = [reader.zone(item, line, parts) for item, line in reader.items(top, "zones")]
    _unique(reader, [(zone.name, line) for zone, (_, line) in zip(zones, reader.items(top, "zones"), strict=True)],
            "zone", reserved=set())
    self_collision = reader.boolean(arm, "self_collision", True)
    padding, part_padding = reader.padding(arm)
    pairs = []
    for item, line in reader.items(arm, "allowed_pairs"):
        pair = reader.names(item, line, "an allowed pair", parts)
        if len(pair) != 2 or pair[0] == pair[1]:
            raise reader.error(line, f"an allowed pair names two different parts, not {pair}")
        pairs.append(pair)
    return Cell(source=source, margin_mm=margin, zones=zones, tool=tool, self_collision=self_collision,
                arm_padding_mm=padding, arm_padding_parts=part_padding, allowed_pairs=pairs)


def _unique(reader: _Reader, named: list[tuple[str, int | None]], what: str, reserved: set[str]) -> None:
    seen: set[str] = set()
    for name, line in named:
        if name in seen or name in reserved:
            taken = "a part of the arm" if name in reserved else f"another {what}"
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

    def items(self, mapping: dict[str, Any], key: str) -> list[tuple[Any, int | None]]:
        value = mapping.get(key, [])
        if value is None:
            return []
        if not isinstance(value, list):
            raise self.error(self.line_of(mapping, key), f"{key} must be a list")
        return [(item, self.line_of_item(value, i)) for i, item in enumerate(value)]

    def number(self, mapping: dict[str, Any], key: str, default: float | None = None, *,
               minimum: float | None = None, positive: bool = False) -> float:
        line = self.line_of(mapping, key)
        if key not in mapping:
            if default is None:
                raise self.error(getattr(getattr(mapping, "lc", None), "line", None), f"{key} is missing")
            return default
        value = mapping[key]
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self.error(line, f"{key} must be a number, not {value!r}")
        if (minimum is not None and value < minimum) or (positive and value <= 0):
            bound = "above 0" if positive else f"at least {minimum:g}"
            raise self.error(line, f"{key} must be {bound}, not {value}")
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

    def vector(self, mapping: dict[str, Any], key: str, line: int | None) -> list[float]:
        if key not in mapping:
            raise self.error(line, f"{key} is missing (three numbers, mm)")
        value = mapping[key]
        at = self.line_of(mapping, key)
        if (not isinstance(value, list) or len(value) != 3
                or any(isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) for v in value)):
            raise self.error(at, f"{key} must be three numbers, not {_plain(value)}")
        return [float(v) for v in value]

    def name(self, mapping: dict[str, Any], line: int | None, what: str) -> str:
        value = mapping.get("name")
        if not isinstance(value, str) or not value.strip():
            raise self.error(self.line_of(mapping, "name") or line, f"{what} needs a name")
        return value.strip()

    def names(self, value: Any, line: int | None, what: str, parts: set[str]) -> list[str]:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.error(line, f"{what} must be a list of part names, not {_plain(value)}")
        for name in value:
            if name not in parts:
                raise self.error(line, f"{what}: no part is called {name!r} (parts: {', '.join(sorted(parts))})")
        return [str(v) for v in value]

    def zone(self, item: Any, line: int | None, parts: set[str]) -> Zone:
        zone = self.mapping(item, line, "a zone", ("name", "keep", "half_space", "box", "ignore"))
        name = self.name(zone, line, "every zone")
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
            return Zone(name=name, keep="out", ignore=ignore,
                        half_space=HalfSpace(point=self.vector(plane, "point", at), normal=[v / length for v in normal]))
        box = self.mapping(zone["box"], at, f"zone {name!r}: box", ("min", "max", "rpy_deg"))
        low, high = self.vector(box, "min", at), self.vector(box, "max", at)
        if not all(hi > lo for lo, hi in zip(low, high, strict=True)):
            raise self.error(self.line_of(box, "max") or at, f"zone {name!r}: max must be above min on every axis")
        rpy = self.vector(box, "rpy_deg", at) if "rpy_deg" in box else [0.0, 0.0, 0.0]
        return Zone(name=name, keep=keep, ignore=ignore, box=Box(min=low, max=high, rpy_deg=rpy))

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
                             a=self.vector(sphere, "center", at))
        capsule = self.mapping(shape["capsule"], at, f"tool shape {name!r}: capsule", ("from", "to", "radius"))
        return ToolShape(name=name, radius=self.number(capsule, "radius", positive=True),
                         a=self.vector(capsule, "from", at), b=self.vector(capsule, "to", at))


def _plain(value: Any) -> str:
    """A YAML value as the user wrote it, for an error message (ruamel's types print oddly)."""
    if isinstance(value, list):
        return "[" + ", ".join(_plain(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_plain(v)}" for k, v in value.items()) + "}"
    return repr(value) if isinstance(value, str) else str(value)
