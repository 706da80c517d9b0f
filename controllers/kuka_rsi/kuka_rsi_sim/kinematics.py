"""Forward kinematics of the KR3/KR16, as the controller reports it in RIst/RSol.

Chain: standard DH, A_i = Rz(th_i) Tz(d_i) Tx(a_i) Rx(alpha_i), th_i = s_i * A_i + o_i with
s = (-1, 1, 1, -1, 1, -1), o = (0, 0, -90, 0, 0, 0) deg, alpha = (-90, 0, -90, 90, -90, 0) deg.

Frame reported (null tool, null base): KUKA's flange frame, X out of the flange. At
A1..A6 = 0 (arm stretched forward) it is parallel to the base frame (A = B = C = 0); at
the home 0 -90 90 0 90 0 the flange faces down: A 0, B 90, C 0.
Angles: KUKA's Z-Y'-X'' Euler angles, R = Rz(A) Ry(B) Rx(C), in degrees.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .machine import Machine

#: a flange pose: X, Y, Z (mm), A, B, C (deg)
Pose = tuple[float, float, float, float, float, float]

_SIGN = (-1.0, 1.0, 1.0, -1.0, 1.0, -1.0)
_OFFSET = (0.0, 0.0, -90.0, 0.0, 0.0, 0.0)
_ALPHA = (-90.0, 0.0, -90.0, 90.0, -90.0, 0.0)

# The DH chain ends in a frame with z along the flange normal; this constant rotation turns
# it into KUKA's flange frame (x out of the flange, parallel to the base at A1..A6 = 0): a
# fixed re-labelling of the axes, the same for every pose.
_TO_FLANGE = ((0.0, 0.0, 1.0), (0.0, -1.0, 0.0), (1.0, 0.0, 0.0))

_DEG = math.pi / 180.0
_RAD = 180.0 / math.pi


class Kinematics:
    """FK of one robot; the DH constants are precomputed once."""

    def __init__(self, machine: Machine) -> None:
        m = machine
        self._d = (m.d1, 0.0, 0.0, m.d4, 0.0, m.d6)
        self._a = (m.a1, m.a2, m.a3, 0.0, 0.0, 0.0)
        self._ca = tuple(round(math.cos(a * _DEG)) for a in _ALPHA)  # exactly 0/1/-1
        self._sa = tuple(round(math.sin(a * _DEG)) for a in _ALPHA)

    def pose(self, q: Sequence[float]) -> Pose:
        """Flange pose (X, Y, Z mm; A, B, C deg) for axis angles q (deg)."""
        # running product T = [R | p], rows of R kept as plain floats
        r11, r12, r13, r21, r22, r23, r31, r32, r33 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        px = py = pz = 0.0
        for i in range(6):
            th = (_SIGN[i] * q[i] + _OFFSET[i]) * _DEG
            ct, st = math.cos(th), math.sin(th)
            ca, sa, a, d = self._ca[i], self._sa[i], self._a[i], self._d[i]
            # A_i rotation columns: x = (ct, st, 0), y = (-st ca, ct ca, sa), z = (st sa, -ct sa, ca)
            # translation: (a ct, a st, d)
            tx, ty, tz = a * ct, a * st, d
            px, py, pz = (
                px + r11 * tx + r12 * ty + r13 * tz,
                py + r21 * tx + r22 * ty + r23 * tz,
                pz + r31 * tx + r32 * ty + r33 * tz,
            )
            yx, yy, yz = -st * ca, ct * ca, sa
            zx, zy, zz = st * sa, -ct * sa, ca
            r11, r12, r13 = (r11 * ct + r12 * st, r11 * yx + r12 * yy + r13 * yz, r11 * zx + r12 * zy + r13 * zz)
            r21, r22, r23 = (r21 * ct + r22 * st, r21 * yx + r22 * yy + r23 * yz, r21 * zx + r22 * zy + r23 * zz)
            r31, r32, r33 = (r31 * ct + r32 * st, r31 * yx + r32 * yy + r33 * yz, r31 * zx + r32 * zy + r33 * zz)
        f = _TO_FLANGE
        rows = (
            (r11, r12, r13),
            (r21, r22, r23),
            (r31, r32, r33),
        )
        k = [[sum(row[j] * f[j][c] for j in range(3)) for c in range(3)] for row in rows]
        a, b, c = euler_zyx(k)
        return px, py, pz, a, b, c


def euler_zyx(r: Sequence[Sequence[float]]) -> tuple[float, float, float]:
    """KUKA A, B, C (deg) of a rotation matrix r (rows): r = Rz(A) Ry(B) Rx(C).

    At B = +-90 deg only C - A (resp. C + A) is defined; the controller then reports A = 0.
    """
    r11, r21, r31 = r[0][0], r[1][0], r[2][0]
    cb = math.hypot(r11, r21)
    b = math.atan2(-r31, cb)
    if cb > 1e-9:
        a = math.atan2(r21, r11)
        c = math.atan2(r[2][1], r[2][2])
    else:
        a = 0.0
        c = math.atan2(r[0][1], r[1][1]) if r31 < 0 else math.atan2(-r[0][1], r[1][1])
    return a * _RAD, b * _RAD, c * _RAD


def rotation_zyx(a: float, b: float, c: float) -> tuple[tuple[float, float, float], ...]:
    """Rz(A) Ry(B) Rx(C) as rows (degrees in); the inverse of euler_zyx, for checks."""
    ca, sa = math.cos(a * _DEG), math.sin(a * _DEG)
    cb, sb = math.cos(b * _DEG), math.sin(b * _DEG)
    cc, sc = math.cos(c * _DEG), math.sin(c * _DEG)
    return (
        (ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc),
        (sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc),
        (-sb, cb * sc, cb * cc),
    )
