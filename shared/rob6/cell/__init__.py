"""The robot's cell: safety zones, the tool and the arm's collision shapes, read from a file and checked.

A lab describes its cell in a YAML file (``ROB6_CELL``; ``default.yaml`` beside this module
when unset: the floor at the robot's base, self-collision on): keep-out half-spaces and
boxes, keep-in boxes, the tool's spheres and capsules on the flange, and which parts of the
arm may touch. ``file`` reads and validates it (an error names the line), ``model`` turns it
into Pinocchio/coal geometry and measures distances, ``guard`` holds the rule every setpoint
of the driver and every sampled path of the planner obeys. docs/SAFETY_ZONES.md is the guide.

Pinocchio, coal, Ruckig and ruamel.yaml come with the ``cell`` extra of rob6-shared: the
services that check (planner, driver) declare it; the others only read the ``Cell`` message.
"""

from __future__ import annotations

from .file import ARM_PARTS, CellError, default_cell, load_cell
from .guard import Guard, PathRefusal, Stop
from .model import CellModel

__all__ = ["ARM_PARTS", "CellError", "CellModel", "Guard", "PathRefusal", "Stop", "default_cell", "load_cell"]
