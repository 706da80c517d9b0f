"""The collision shapes of each robot geometry's arm, read from ``arms/<geometry>.yaml``.

Each part (``base``, ``link_1`` ... ``link_6``) has a list of capsules, spheres and boxes in
its joint frame (rob6's URDF, mm) that enclose the real arm: fitted to the ROS-Industrial
collision meshes and the vendors' dimensions (``arms/REFERENCES.md`` gives each source and
margin). ``model`` builds the guard's geometry from them; the URDF stays the live view's drawing.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

from ruamel.yaml import YAML

from .file import ARM_PARTS

#: where the shapes of each geometry are (one file per ``RobotModel.geometry``)
ARMS_DIR = Path(__file__).with_name("arms")


@dataclass(frozen=True)
class ArmShape:
    """One shape of a part: a capsule (``a`` to ``b``), a sphere (``a``, ``b`` None) or a box
    (``a`` its centre, ``size`` its sides); mm, in the part's joint frame."""

    kind: str  # "capsule" | "sphere" | "box"
    a: tuple[float, float, float]
    b: tuple[float, float, float] | None = None
    radius: float = 0.0
    size: tuple[float, float, float] | None = None
    source: str = ""


@cache
def arm_shapes(geometry: str) -> dict[str, tuple[ArmShape, ...]]:
    """The shapes of each part of ``geometry``'s arm (every part of ``ARM_PARTS`` has one at least)."""
    path = ARMS_DIR / f"{geometry}.yaml"
    doc = YAML(typ="safe", pure=True).load(path.read_text(encoding="utf-8"))
    parts = doc["parts"]
    if doc.get("geometry") != geometry or set(parts) != set(ARM_PARTS):
        raise ValueError(f"{path}: expected geometry {geometry} and the parts {', '.join(ARM_PARTS)}")
    return {part: tuple(_shape(item, f"{path} {part}") for item in parts[part]) for part in ARM_PARTS}


def _vector(value: object, where: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise ValueError(f"{where}: expected three numbers, not {value!r}")
    x, y, z = (float(v) for v in value)
    return x, y, z


def _shape(item: dict[str, object], where: str) -> ArmShape:
    source = str(item.get("source", ""))
    if not source:
        raise ValueError(f"{where}: every shape names its source")
    if "capsule" in item:
        c = item["capsule"]
        assert isinstance(c, dict)
        return ArmShape("capsule", _vector(c["from"], where), _vector(c["to"], where), float(c["radius"]), source=source)
    if "sphere" in item:
        s = item["sphere"]
        assert isinstance(s, dict)
        return ArmShape("sphere", _vector(s["center"], where), radius=float(s["radius"]), source=source)
    if "box" in item:
        b = item["box"]
        assert isinstance(b, dict)
        return ArmShape("box", _vector(b["center"], where), size=_vector(b["size"], where), source=source)
    raise ValueError(f"{where}: a shape is a capsule, a sphere or a box, not {sorted(item)}")
