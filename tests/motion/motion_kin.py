"""Kinematics for the LIN tests: the kinematics service's own closed form (``rob6_kinematics``),
not a second copy of it.

``make_ik`` gives ``plan_lin`` the ``ik_fn`` the planner service builds over the bus (one
configuration, nearest to a reference); ``fk`` checks straightness. Degrees and millimetres.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import numpy.typing as npt

from rob6.robots import RobotModel
from rob6_kinematics.calc import Kinematics
from rob6_planner.lin_planner import IkFn


@cache
def _kinematics(robot: RobotModel) -> Kinematics:
    return Kinematics(robot)


def fk(robot: RobotModel, q: npt.ArrayLike) -> np.ndarray:
    """q (N,6) deg -> poses (N,3,4)."""
    return _kinematics(robot).fk(q)


def make_ik(robot: RobotModel, q_ref: npt.ArrayLike, max_err_mm: float = 1e-6) -> IkFn:
    """ik_fn for plan_lin: the solution in the configuration of q_ref, nearest to q_ref."""
    ref = np.asarray(q_ref, float)
    status_ref = robot.status(tuple(ref))
    kin = _kinematics(robot)

    def ik_fn(poses_in: np.ndarray) -> np.ndarray:
        poses = np.asarray(poses_in, float)
        sols = kin.ik(poses)
        out = np.full((len(poses), 6), np.nan)
        for n in range(len(poses)):
            best, best_d = None, np.inf
            for s in sols[n]:
                if np.isnan(s).any() or robot.status(tuple(s)) != status_ref:
                    continue
                d = np.abs(((s - ref) + 180) % 360 - 180).sum()
                if d < best_d:
                    best, best_d = s, d
            if best is not None:
                err = np.abs(fk(robot, best)[0] - poses[n]).max()
                if err < max(max_err_mm, 1e-6 * np.abs(poses[n]).max()):
                    out[n] = best
        return out

    return ik_fn
