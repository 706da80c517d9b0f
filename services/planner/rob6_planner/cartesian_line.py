"""The geometry of a LIN move's straight line: linear position, quaternion slerp orientation.

The straight Cartesian line of a LIN move: position interpolated linearly, orientation
by quaternion slerp (``rob6.rotations`` gives the quaternions, scalar first)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from rob6.rotations import quat_from_matrix


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Rotation matrix (3,3) -> unit quaternion (w, x, y, z); tolerates non-orthonormal input."""
    u, _, vt = np.linalg.svd(R)
    R = u @ vt
    if np.linalg.det(R) < 0:
        u[:, -1] *= -1
        R = u @ vt
    return np.array(quat_from_matrix(R.tolist()))


def _matrix_from_quats(q: np.ndarray) -> np.ndarray:
    """(N,4) unit quaternions -> (N,3,3)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((len(q), 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Quaternion slerp along the shorter arc; s (N,) in [0,1] -> (N,4)."""
    dot = float(np.dot(q0, q1))
    if dot < 0:
        q1, dot = -q1, -dot
    s = np.asarray(s, float)[:, None]
    if dot > 0.9999995:
        out = q0 + s * (q1 - q0)
        unit: np.ndarray = out / np.linalg.norm(out, axis=1, keepdims=True)
        return unit
    theta = math.acos(min(dot, 1.0))
    sin_t = math.sin(theta)
    arc: np.ndarray = (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / sin_t
    return arc


class LinePath:
    """p(s) = p0 + s (p1 - p0), R(s) = slerp(R0, R1, s), s in [0, 1]."""

    def __init__(self, pose0: ArrayLike, pose1: ArrayLike) -> None:
        T0 = np.asarray(pose0, float).reshape(3, 4)
        T1 = np.asarray(pose1, float).reshape(3, 4)
        self.p0, self.p1 = T0[:, 3].copy(), T1[:, 3].copy()
        self.q0, self.q1 = _quat_from_matrix(T0[:, :3]), _quat_from_matrix(T1[:, :3])
        if np.dot(self.q0, self.q1) < 0:
            self.q1 = -self.q1
        self.length_mm = float(np.linalg.norm(self.p1 - self.p0))
        self.angle_deg = math.degrees(2 * math.acos(min(1.0, abs(float(np.dot(self.q0, self.q1))))))

    def poses(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, float)
        out = np.empty((len(s), 3, 4))
        out[:, :, :3] = _matrix_from_quats(slerp(self.q0, self.q1, s))
        out[:, :, 3] = self.p0 + s[:, None] * (self.p1 - self.p0)
        return out
