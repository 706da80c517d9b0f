"""Pinocchio model of a rob6 robot, built from the generated URDF.

Used for the Jacobian / manipulability and as an independent check of the numpy
FK (tests).  Units at this interface: joints in degrees, poses in mm (Pinocchio
itself works in radians and metres).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from rob6.robots import RobotModel

from .opw import DEG, FloatArray, Geometry
from .urdf import generate


class PinModel:
    """Pinocchio model + data of one robot; ``flange`` is the protocol's frame."""

    def __init__(self, robot: RobotModel, geometry: Geometry | None = None):
        if geometry is not None and geometry != Geometry.of(robot):
            robot = replace(robot, **{k: getattr(geometry, k) for k in ("d1", "a1", "a2", "a3", "d4", "d6")})
        self.robot = robot
        self.urdf = generate(robot)
        self.model = pin.buildModelFromXML(self.urdf)
        self.data = self.model.createData()
        self.flange = self.model.getFrameId("flange")
        if self.model.nq != 6:
            raise RuntimeError(f"expected 6 joints, URDF has {self.model.nq}")

    # ------------------------------------------------------------------
    def _q(self, q_deg: npt.ArrayLike) -> FloatArray:
        return np.asarray(q_deg, dtype=float).reshape(6) * DEG

    def fk(self, q_deg: npt.ArrayLike) -> FloatArray:
        """Flange pose (3,4), mm, of joints q (deg)."""
        pin.framesForwardKinematics(self.model, self.data, self._q(q_deg))
        M = self.data.oMf[self.flange]
        T = np.empty((3, 4))
        T[:, :3] = M.rotation
        T[:, 3] = M.translation * 1000.0
        return T

    def fk_batch(self, q_deg: npt.ArrayLike) -> FloatArray:
        q = np.asarray(q_deg, float).reshape(-1, 6)
        return np.stack([self.fk(x) for x in q])

    def jacobian(self, q_deg: npt.ArrayLike, *, si: bool = False) -> FloatArray:
        """Flange Jacobian (6,6) in LOCAL_WORLD_ALIGNED (base-aligned axes at the
        flange origin): rows (vx, vy, vz, wx, wy, wz) per rad/s of each joint.
        Linear rows in mm/rad (``si=True``: m/rad)."""
        J: FloatArray = pin.computeFrameJacobian(
            self.model, self.data, self._q(q_deg), self.flange, pin.LOCAL_WORLD_ALIGNED
        ).copy()
        if not si:
            J[:3] *= 1000.0
        return J

    def manipulability(self, q_deg: npt.ArrayLike) -> float:
        """Yoshikawa measure sqrt(det(J J^T)) = |det J| with J in SI units (m, rad);
        0 at a singularity (wrist: q5 = 0, elbow stretched, wrist centre on J1)."""
        J = self.jacobian(q_deg, si=True)
        return float(abs(np.linalg.det(J)))

    def condition(self, q_deg: npt.ArrayLike) -> float:
        """Condition number of the SI Jacobian (inf at a singularity)."""
        s = np.linalg.svd(self.jacobian(q_deg, si=True), compute_uv=False)
        return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
