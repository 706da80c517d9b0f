"""Rotations shared by the services: unit quaternions (of matrices, roll/pitch/yaw, axis-angle) and their product.

Rotations shared by the services: unit quaternions of a rotation matrix, of roll/pitch/yaw
angles and of an axis and angle, and their product.

One component order everywhere: ``(w, x, y, z)``, the scalar first. Foxglove messages
name their fields (``x, y, z, w``), so a writer of them unpacks by name.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Quaternion = tuple[float, float, float, float]  # (w, x, y, z)


def quat_from_rpy(r: float, p: float, y: float) -> Quaternion:
    """The rotation of URDF's ``rpy``: about x by r, then y by p, then z by y (fixed axes)."""
    cr, sr = math.cos(r / 2), math.sin(r / 2)
    cp, sp = math.cos(p / 2), math.sin(p / 2)
    cy, sy = math.cos(y / 2), math.sin(y / 2)
    return (cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


def quat_axis_angle(axis: Sequence[float], angle: float) -> Quaternion:
    """The rotation by ``angle`` (rad) about ``axis`` (any length but zero)."""
    n = math.sqrt(sum(a * a for a in axis)) or 1.0
    s = math.sin(angle / 2) / n
    return math.cos(angle / 2), axis[0] * s, axis[1] * s, axis[2] * s


def quat_mul(a: Quaternion, b: Quaternion) -> Quaternion:
    """The product ``a b``: rotation b, then a."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def quat_conjugate(q: Quaternion) -> Quaternion:
    """The inverse rotation of a unit quaternion."""
    return q[0], -q[1], -q[2], -q[3]


def quat_from_matrix(m: Sequence[Sequence[float]]) -> Quaternion:
    """The unit quaternion ``(w, x, y, z)`` of a 3x3 rotation matrix given by its rows
    (Shepperd's method: the largest of w, x, y, z is computed first, for precision).
    The matrix must be orthonormal; the result is normalised."""
    m00, m01, m02 = m[0][0], m[0][1], m[0][2]
    m10, m11, m12 = m[1][0], m[1][1], m[1][2]
    m20, m21, m22 = m[2][0], m[2][1], m[2][2]
    tr = m00 + m11 + m22
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = (0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s)
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2
        q = ((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s)
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2
        q = ((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s)
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2
        q = ((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s)
    n = math.sqrt(sum(c * c for c in q)) or 1.0
    return q[0] / n, q[1] / n, q[2] / n, q[3] / n
