"""A cell for the zone tests of every robot type: a table box under the tool, found with the kinematics.

The arm hovers over the table in the family ``q(s) = (0, s, 90, 0, -s, 0)``, where the flange
points straight down (its z axis, which points into it, is the base's z): as ``s`` grows the
tool goes down. The tool is a capsule with a tip sphere below the flange. Heights come from
rob6's closed-form kinematics (``rob6_kinematics.opw``), not from the Pinocchio model the
guard uses, so the tests measure the guard with other code than its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rob6.robots import get_robot
from rob6_kinematics.opw import Geometry, fk

HOVER_S = -55.0
#: the table's top, below the tool tip's lowest point at the hover pose (mm)
TABLE_BELOW_MM = 100.0


@dataclass(frozen=True)
class Rig:
    robot: str
    tool_mm: float  # from the flange to the tip sphere's centre
    tip_radius_mm: float
    table_z: float  # the table's top (mm)

    def q(self, s: float) -> list[float]:
        return [0.0, s, 90.0, 0.0, -s, 0.0]

    def tip_clearance(self, q: np.ndarray) -> np.ndarray:
        """How far (mm) the tip sphere is above the table's top, for joints (N, 6)."""
        T = fk(Geometry.of(get_robot(self.robot)), np.asarray(q, float).reshape(-1, 6))
        tip = T[:, :, 3] - self.tool_mm * T[:, :, 2]  # along the flange's -z: out of the flange
        clearance: np.ndarray = tip[:, 2] - self.tip_radius_mm - self.table_z
        return clearance

    def s_at(self, clearance_mm: float) -> float:
        """The ``s`` at which the tip is ``clearance_mm`` above the table (< 0: inside)."""
        lo, hi = HOVER_S, HOVER_S + 60.0
        for _ in range(60):
            mid = (lo + hi) / 2
            if self.tip_clearance(np.array(self.q(mid)))[0] > clearance_mm:
                lo = mid
            else:
                hi = mid
        return (lo + hi) / 2

    def cell_yaml(self) -> str:
        flange = fk(Geometry.of(get_robot(self.robot)), np.array(self.q(HOVER_S)))[0][:, 3]
        x, half = float(flange[0]), 2.5 * self.tool_mm
        r = self.tip_radius_mm
        return f"""\
margin_mm: 5
zones:
  - name: table
    keep: out
    box: {{min: [{x - half:.1f}, {-half:.1f}, {self.table_z - 100:.1f}], max: [{x + half:.1f}, {half:.1f}, {self.table_z:.1f}]}}
tool:
  - {{name: gripper, capsule: {{from: [0, 0, {-r / 2:.1f}], to: [0, 0, {-self.tool_mm + r:.1f}], radius: {r / 2:.1f}}}}}
  - {{name: tool tip, sphere: {{center: [0, 0, {-self.tool_mm:.1f}], radius: {r:.1f}}}}}
""" + ("arm:\n  allowed_pairs: [[link_4, gripper]]   # the Viper's wrist estimate reaches the flange\n"
       if self.robot == "ad850" else "")

    def write(self, directory: Path) -> Path:
        path = directory / f"{self.robot}-cell.yaml"
        path.write_text(self.cell_yaml())
        return path


def rig(robot: str) -> Rig:
    small = get_robot(robot).a2 < 500  # kr3, kaw_fs, ad850: a shorter tool
    tool, radius = (80.0, 15.0) if small else (150.0, 25.0)
    base = Rig(robot, tool, radius, 0.0)
    hover = float(base.tip_clearance(np.array(base.q(HOVER_S)))[0])
    return Rig(robot, tool, radius, hover - TABLE_BELOW_MM)
