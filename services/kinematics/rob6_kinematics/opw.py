"""Vectorised closed-form kinematics (numpy) of the rob6 robots.

All robots share one chain (``robots.md`` "Kinematic chain"): standard DH,
``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, ``T = A1..A6 Ry(180deg)``,
``theta = s*q + o`` with s = [-1, 1, 1, -1, 1, -1], o = [0, 0, -90, 0, 0, 0] deg and
alpha = [-90, 0, -90, 90, -90, 0] deg.  It is an OPW manipulator (offset wrist,
parallel J2/J3, spherical wrist); the inverse below is the closed form of that
geometry written directly in the DH convention (equivalent to opw_kinematics
with the parameters ``RobotModel.opw``), so no sign/offset table is needed.

Units: mm and degrees at the interface, radians inside.  Poses are ``(..., 3, 4)``
homogeneous matrices (the protocol's row-wise 12 numbers reshaped).

Branch order (``BRANCHES``) is the order of the original's status words, hand
major::

    index = 4*hand + 2*elbow + arm   with hand 0=noflip 1=flip, elbow 0=up 1=down,
                                          arm 0=lefty 1=righty
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

from rob6 import robots

#: the arrays this package computes with: float64 joints (deg, rad), poses (mm)
FloatArray = npt.NDArray[np.float64]

DEG = np.pi / 180.0
RAD = 180.0 / np.pi

DH_SIGNS = np.array(robots.DH_SIGNS)
DH_OFFSETS = np.array(robots.DH_OFFSETS_DEG) * DEG
DH_ALPHA = np.array(robots.DH_ALPHA_DEG) * DEG

HANDS = ("noflip", "flip")
ELBOWS = ("up", "down")
ARMS = ("lefty", "righty")
BRANCHES: tuple[str, ...] = tuple(
    f"{h} {e} {a}" for h in HANDS for e in ELBOWS for a in ARMS
)
BRANCH_INDEX = {s: i for i, s in enumerate(BRANCHES)}

#: The original's wrist-singularity threshold on r13, r23 of the wrist rotation.
WRIST_SING_EPS = 1e-4
#: Relative tolerance of the stretched-elbow clamp: a cosine with |c| <= 1 + CLAMP_TOL
#: is clamped to +-1 (up == down), beyond it the pose is out of reach.  The
#: transcripts bracket the original's threshold: |c| - 1 = 2.2e-7 was still
#: solved (6-decimal rounding of a stretched pose), 3.1e-4 was not.
CLAMP_TOL = 1e-5


@dataclass(frozen=True)
class Geometry:
    """The six DH lengths (mm) that differ between the robots."""

    d1: float
    a1: float
    a2: float
    a3: float
    d4: float
    d6: float

    @classmethod
    def of(cls, robot: robots.RobotModel) -> Geometry:
        return cls(robot.d1, robot.a1, robot.a2, robot.a3, robot.d4, robot.d6)

    @property
    def d(self) -> FloatArray:
        return np.array([self.d1, 0.0, 0.0, self.d4, 0.0, self.d6])

    @property
    def a(self) -> FloatArray:
        return np.array([self.a1, self.a2, self.a3, 0.0, 0.0, 0.0])


# --------------------------------------------------------------------------- helpers
#: an angle this close above -180 deg is the same joint position as 180: it is reported as 180.
#: Without it the result depended on the CPU: a J4 of +-pi came out of numpy's SIMD arctan2 as
#: 180 and out of math.atan2 as -179.99999999999994, printed "-180.000000" (seen on AVX-512)
WRAP_EPS_DEG = 1e-9


def wrap180(q: npt.ArrayLike) -> FloatArray:
    """Map angles (deg) into (-180, 180]."""
    w = 180.0 - np.mod(180.0 - np.asarray(q, dtype=float), 360.0)
    return np.where(w < -180.0 + WRAP_EPS_DEG, w + 360.0, w)


def as_poses(T: npt.ArrayLike) -> FloatArray:
    """Accept (12,), (3,4), (4,4), (N,12), (N,3,4), (N,4,4); return (N,3,4) float."""
    P = np.asarray(T, dtype=float)
    if P.shape[-1] == 12:
        P = P.reshape(P.shape[:-1] + (3, 4))
    if P.shape[-2:] == (4, 4):
        P = P[..., :3, :]
    if P.shape[-2:] != (3, 4):
        raise ValueError(f"pose shape {P.shape} is not (...,3,4)/(...,4,4)/(...,12)")
    return P.reshape((-1, 3, 4))


def as_joints(q: npt.ArrayLike) -> FloatArray:
    Q = np.asarray(q, dtype=float)
    if Q.shape[-1] != 6:
        raise ValueError(f"joint shape {Q.shape} is not (...,6)")
    return Q.reshape((-1, 6))


def dh_chain(theta: npt.ArrayLike, d: FloatArray, a: FloatArray, alpha: FloatArray) -> FloatArray:
    """Product A1..An of standard DH matrices, vectorised.

    theta: (N, n) radians; d, a, alpha: (n,).  Returns (N, 4, 4).
    """
    th = np.asarray(theta, dtype=float)
    N, n = th.shape
    ct, st = np.cos(th), np.sin(th)
    ca, sa = np.cos(alpha), np.sin(alpha)
    A = np.zeros((N, n, 4, 4))
    A[..., 0, 0] = ct
    A[..., 0, 1] = -st * ca
    A[..., 0, 2] = st * sa
    A[..., 0, 3] = a * ct
    A[..., 1, 0] = st
    A[..., 1, 1] = ct * ca
    A[..., 1, 2] = -ct * sa
    A[..., 1, 3] = a * st
    A[..., 2, 1] = sa
    A[..., 2, 2] = ca
    A[..., 2, 3] = d
    A[..., 3, 3] = 1.0
    T = A[:, 0]
    for i in range(1, n):
        T = T @ A[:, i]
    return T


# --------------------------------------------------------------------------- FK
def fk(g: Geometry, q_deg: npt.ArrayLike) -> FloatArray:
    """Flange poses for joints q (deg), (N,6) or (6,) -> (N,3,4), mm.

    Closed-form product (no 4x4 loop): wrist centre from the planar arm, rotation
    ``R = R0_3 R3_6 Ry(180)``.
    """
    q = as_joints(q_deg) * DEG
    t1 = -q[:, 0]
    t2 = q[:, 1]
    t23 = q[:, 1] + q[:, 2] - np.pi / 2  # theta2 + theta3
    t4, t5, t6 = -q[:, 3], q[:, 4], -q[:, 5]
    c1, s1 = np.cos(t1), np.sin(t1)
    c2, s2 = np.cos(t2), np.sin(t2)
    c23, s23 = np.cos(t23), np.sin(t23)
    c4, s4 = np.cos(t4), np.sin(t4)
    c5, s5 = np.cos(t5), np.sin(t5)
    c6, s6 = np.cos(t6), np.sin(t6)
    N = q.shape[0]
    # R0_3 = Rz(t1) Rx(-90) Rz(t23) Rx(-90)
    R03 = np.empty((N, 3, 3))
    R03[:, 0, 0] = c1 * c23
    R03[:, 0, 1] = s1
    R03[:, 0, 2] = -c1 * s23
    R03[:, 1, 0] = s1 * c23
    R03[:, 1, 1] = -c1
    R03[:, 1, 2] = -s1 * s23
    R03[:, 2, 0] = -s23
    R03[:, 2, 1] = 0.0
    R03[:, 2, 2] = -c23
    # R3_6 = Rz(t4) Rx(90) Rz(t5) Rx(-90) Rz(t6)
    R36 = np.empty((N, 3, 3))
    R36[:, 0, 0] = c4 * c5 * c6 - s4 * s6
    R36[:, 0, 1] = -c4 * c5 * s6 - s4 * c6
    R36[:, 0, 2] = -c4 * s5
    R36[:, 1, 0] = s4 * c5 * c6 + c4 * s6
    R36[:, 1, 1] = -s4 * c5 * s6 + c4 * c6
    R36[:, 1, 2] = -s4 * s5
    R36[:, 2, 0] = s5 * c6
    R36[:, 2, 1] = -s5 * s6
    R36[:, 2, 2] = c5
    R = R03 @ R36
    # planar arm in the J1 frame: x1 radial, y1 downwards
    x1 = g.a1 + g.a2 * c2 + g.a3 * c23 - g.d4 * s23
    y1 = g.a2 * s2 + g.a3 * s23 + g.d4 * c23
    T = np.empty((N, 3, 4))
    # Ry(180) on the right: x -> -x, z -> -z
    T[:, :, 0] = -R[:, :, 0]
    T[:, :, 1] = R[:, :, 1]
    T[:, :, 2] = -R[:, :, 2]
    z6 = R[:, :, 2]  # DH z6 = -flange z
    T[:, 0, 3] = x1 * c1 + g.d6 * z6[:, 0]
    T[:, 1, 3] = x1 * s1 + g.d6 * z6[:, 1]
    T[:, 2, 3] = g.d1 - y1 + g.d6 * z6[:, 2]
    return T


def fk_compiled(g: Geometry, q_deg: npt.ArrayLike, n: int = 6) -> FloatArray:
    """FK through the original's "compiled" chain, (N,6) deg -> (N,3,4) mm.

    ``A1'..An'`` with theta' = [-q1, q2, q3+90, q4, q5, q6] deg, d4 -> -d4,
    d6 -> -d6, a3 -> -a3, the same twists and no final Ry(180) (robots.md,
    "ForwardCalc quirks").  For n = 6 this is the flange pose; for n < 6 the frame
    the original's short ForwardCalc returns.  Multiplying the DH matrices out
    left to right reproduces the original's ForwardCalc replies byte for byte
    (also the signs of -0.000000), which the closed form ``fk`` does not.
    """
    q = as_joints(q_deg) * DEG
    theta = np.stack(
        [-q[:, 0], q[:, 1], q[:, 2] + np.pi / 2, q[:, 3], q[:, 4], q[:, 5]], axis=1
    )
    d = np.array([g.d1, 0.0, 0.0, -g.d4, 0.0, -g.d6])
    a = np.array([g.a1, g.a2, -g.a3, 0.0, 0.0, 0.0])
    return dh_chain(theta[:, :n], d[:n], a[:n], DH_ALPHA[:n])[:, :3, :]


def fk_dh(g: Geometry, q_deg: npt.ArrayLike) -> FloatArray:
    """Reference FK by the literal DH product (slower; used in tests)."""
    q = as_joints(q_deg) * DEG
    theta = DH_SIGNS * q + DH_OFFSETS
    T = dh_chain(theta, g.d, g.a, DH_ALPHA)
    Ry180 = np.diag([-1.0, 1.0, -1.0, 1.0])
    return (T @ Ry180)[:, :3, :]


# --------------------------------------------------------------------------- IK
def ik(g: Geometry, poses: npt.ArrayLike, *, clamp_tol: float = CLAMP_TOL) -> FloatArray:
    """All 8 closed-form solutions, (N,3,4) -> (N,8,6) degrees in (-180, 180].

    NaN where the branch has no solution (wrist centre out of reach, zero
    rotation).  Reproduces the original's conventions:

    * stretched elbow: ``cos`` of the elbow angle clamped to +-1 when it exceeds 1
      by at most ``clamp_tol`` (``CLAMP_TOL``), so up and down coincide;
    * wrist singularity: when |r13| and |r23| of the wrist rotation R3_6 are both
      < 1e-4, q4 := 0 and the whole wrist rotation goes to q6 (flip == noflip);
    * the rotation is used as given (no orthonormalisation): its z column gives
      the wrist centre and J1..J5, x and y only J6.

    The turn limits are *not* applied here (see ``calc.Kinematics``).
    """
    T = as_poses(poses)
    N = T.shape[0]
    R = T[:, :, :3]
    p = T[:, :, 3]
    z = R[:, :, 2]
    wc = p + g.d6 * z
    wx, wy, wz = wc[:, 0], wc[:, 1], wc[:, 2]

    # ---- J1 (arm: lefty = wrist centre in front of the J1 axis, radial > 0)
    rho = np.hypot(wx, wy)
    t1 = np.stack([np.arctan2(wy, wx), np.arctan2(-wy, -wx)], axis=1)  # (N,2 arm)
    radial = np.stack([rho, -rho], axis=1)
    r = radial - g.a1
    h = (g.d1 - wz)[:, None] * np.ones((1, 2))

    # ---- J3 (elbow): (r,h) = Rot(q2) (a2 + u, v), u = L cos(q3-b), v = L sin(q3-b)
    L2 = g.a3 * g.a3 + g.d4 * g.d4
    L = np.sqrt(L2)
    u = (r * r + h * h - g.a2 * g.a2 - L2) / (2.0 * g.a2)
    c = u / L
    ok = np.abs(c) <= 1.0 + clamp_tol
    c = np.clip(c, -1.0, 1.0)
    sn = np.sqrt(np.maximum(1.0 - c * c, 0.0))  # exactly 0 when clamped
    sn = np.stack([sn, -sn], axis=1)  # (N, 2 elbow, 2 arm): up = sin(q3-b) > 0
    c = c[:, None, :]
    u = L * c
    v = L * sn
    beta = np.arctan2(g.a3, g.d4)
    t3 = np.arctan2(sn, c) + beta - np.pi / 2  # theta3 = q3 - 90deg
    t2 = np.arctan2(h[:, None, :], r[:, None, :]) - np.arctan2(v, g.a2 + u)
    t1 = np.broadcast_to(t1[:, None, :], t2.shape)

    # ---- wrist, in the original's "compiled" chain (robots.md, ForwardCalc
    # quirks): theta' = [-q1, q2, q3+90, q4, q5, q6], no final Ry(180), so that
    # R3_6' = (A1' A2' A3')^T R = Rz(q4) Rx(90) Rz(q5) Rx(-90) Rz(q6) directly in
    # the robot's joint angles.  The DH rotations are multiplied out literally
    # (cos(-90deg) = 6e-17 included): that reproduces the original's rounding
    # noise where it decides a sign (q4 = +-180 at a J4 limit of +-180, -0.000000).
    t3c = t3 + np.pi  # q3 + 90deg
    ca = np.cos(-np.pi / 2)
    sa = np.sin(-np.pi / 2)

    def dh_rot(th: FloatArray, ca: float, sa: float) -> FloatArray:
        c, s = np.cos(th), np.sin(th)
        z = np.zeros_like(c)
        return np.stack(
            [
                np.stack([c, -s * ca, s * sa], axis=-1),
                np.stack([s, c * ca, -c * sa], axis=-1),
                np.stack([z, z + sa, z + ca], axis=-1),
            ],
            axis=-2,
        )

    R03 = dh_rot(t1, ca, sa) @ dh_rot(t2, 1.0, 0.0) @ dh_rot(t3c, ca, sa)  # (N,2e,2a,3,3)
    W = np.swapaxes(R03, -1, -2) @ R[:, None, None]
    r11, r12, r13 = W[..., 0, 0], W[..., 0, 1], W[..., 0, 2]
    r21, r22, r23 = W[..., 1, 0], W[..., 1, 1], W[..., 1, 2]
    r33 = W[..., 2, 2]

    sing = (np.abs(r13) < WRIST_SING_EPS) & (np.abs(r23) < WRIST_SING_EPS)
    # third column of R3_6' = (-c4 s5, -s4 s5, c5): noflip (q5 > 0) ->
    # q4 = atan2(-r23, -r13), flip -> atan2(r23, r13); singular -> q4 = 0
    t4 = np.stack([np.arctan2(-r23, -r13), np.arctan2(r23, r13)], axis=1)  # (N,2h,2e,2a)
    t4 = np.where(sing[:, None], 0.0, t4)
    c4, s4 = np.cos(t4), np.sin(t4)
    R13, R23, R33 = r13[:, None], r23[:, None], r33[:, None]
    t5 = np.arctan2(-(c4 * R13 + s4 * R23), R33)
    # q6 from the third row of Rz(-q5) Rx(-90) Rz(-q4) R3_6' = Rx(-90) Rz(q6):
    # (-s6, -c6, 0) = (s4 r11 - c4 r21, s4 r12 - c4 r22, .), independent of q5.
    # This is the form the original uses: it matches its J6 to print resolution
    # also on rounded / non-orthonormal input, where equivalent forms differ.
    m20 = s4 * r11[:, None] - c4 * r21[:, None]
    m21 = s4 * r12[:, None] - c4 * r22[:, None]
    t6 = np.arctan2(-m20, -m21)

    shp = t4.shape
    q = np.empty(shp + (6,))
    q[..., 0] = -np.broadcast_to(t1[:, None], shp)
    q[..., 1] = np.broadcast_to(t2[:, None], shp)
    q[..., 2] = np.broadcast_to(t3[:, None], shp) + np.pi / 2
    q[..., 3] = t4
    q[..., 4] = t5
    q[..., 5] = t6
    q = wrap180(q * RAD)
    bad = ~ok[:, None, None, :] | ~np.isfinite(q).all(axis=-1)
    zero_rot = ~np.any(R != 0.0, axis=(1, 2))
    bad = bad | zero_rot[:, None, None, None]
    q[np.broadcast_to(bad[..., None], q.shape)] = np.nan
    return q.reshape(N, 8, 6)


# --------------------------------------------------------------------------- single pose
# Scalar (``math``, plain floats) versions of ``ik`` and ``fk_compiled`` for one pose:
# numpy's per-call overhead (array creation, np.stack, clip, broadcasting) costs
# ~1 ms per ``ik`` call on N = 1, the arithmetic itself a few microseconds.  They
# follow the vectorised functions operation by operation, so they give the same
# numbers; the two places where numpy's arithmetic is not plain IEEE float
# arithmetic are reproduced exactly where it can decide a result:
#
# * ``np.hypot`` is libm's ``hypot`` (``math.hypot`` rounds differently in the last
#   bit, which the stretched-elbow ``sqrt(1 - c*c)`` would amplify to ~1e-6 deg);
# * the 3x3 / 4x4 products of ``@`` go to OpenBLAS, whose kernel accumulates with
#   fused multiply-adds, ``fma(a2, b2, fma(a1, b1, a0*b0 + 0))``.  The fast path uses
#   plain products (a few ulps off); where those ulps can decide something -- the
#   sign of the rounding noise that puts J4 / J5 / J6 at +180 or -180, the wrist
#   singularity threshold -- the wrist rotation is recomputed with exact fmas
#   (``_W_exact``), and ``fk_compiled_one`` falls back to ``fk_compiled`` where the
#   printed ``%f`` could differ (noise around 0 prints as -0.000000 or 0.000000).
import ctypes  # noqa: E402
import ctypes.util  # noqa: E402
import math  # noqa: E402
from collections.abc import Callable, Iterable, Sequence  # noqa: E402
from fractions import Fraction  # noqa: E402


def _fma_fraction(a: float, b: float, c: float) -> float:
    return float(Fraction(a) * Fraction(b) + Fraction(c))


def _load_libm() -> tuple[Callable[[float, float, float], float], Callable[[float, float], float]]:
    fma: Callable[..., float] | None = getattr(math, "fma", None)  # Python >= 3.13
    hypot: Callable[..., float] | None = None
    try:
        libm = ctypes.CDLL(ctypes.util.find_library("m") or "libm.so.6")
        if fma is None:
            fma = libm.fma
            fma.restype = ctypes.c_double
            fma.argtypes = [ctypes.c_double] * 3
        hypot = libm.hypot
        hypot.restype = ctypes.c_double
        hypot.argtypes = [ctypes.c_double] * 2
    except (OSError, AttributeError):  # pragma: no cover - no libm
        pass
    if fma is None or fma(0.1, 10.0, -1.0) != _fma_fraction(0.1, 10.0, -1.0):  # pragma: no cover
        fma = _fma_fraction
    if hypot is None or hypot(1e-3, 7.0) != float(np.hypot(1e-3, 7.0)):  # pragma: no cover
        def np_hypot(x: float, y: float) -> float:
            return float(np.hypot(x, y))

        hypot = np_hypot
    return fma, hypot


_fma, _hypot = _load_libm()
_PI = math.pi
_HALF_PI = math.pi / 2
_RAD = 180.0 / math.pi
_DEG = math.pi / 180.0
_CA = math.cos(-math.pi / 2)  # 6.1e-17, as np.cos(-np.pi / 2)
_SA = math.sin(-math.pi / 2)
#: |y| below this (relative to the rotation's scale) in an atan2 of the wrist makes
#: ``ik_one`` recompute the wrist rotation exactly (see above).
_NOISE = 1e-11


def _pose12(T: npt.ArrayLike) -> list[float]:
    if isinstance(T, (list, tuple)) and len(T) == 12:
        return [float(x) for x in T]
    P = as_poses(T)
    if P.shape[0] != 1:
        raise ValueError(f"one pose expected, got {P.shape[0]}")
    return P.reshape(12).tolist()


def _dh_rot(th: float, ca: float, sa: float) -> list[list[float]]:
    c, s = math.cos(th), math.sin(th)
    return [[c, -s * ca, s * sa], [s, c * ca, -c * sa], [0.0, 0.0 + sa, 0.0 + ca]]


def _fma_x(a: float, b: float, c: float) -> float:
    """fma(a, b, c); a*b + c where the product is exact (structural 0 and +-1)."""
    if b in (0.0, 1.0, -1.0) or a in (0.0, 1.0, -1.0):
        return a * b + c
    return _fma(a, b, c)


def _mm3_blas(A: Sequence[Sequence[float]], B: Sequence[Sequence[float]]) -> list[list[float]]:
    """A @ B as numpy/OpenBLAS computes it (fma accumulation, bit for bit)."""
    f = _fma_x
    return [[f(a[2], B[2][j], f(a[1], B[1][j], a[0] * B[0][j] + 0.0)) for j in range(3)] for a in A]


def _W_exact(t1: float, t2: float, t3c: float, R: Sequence[Sequence[float]]) -> list[list[float]]:
    """(A1 A2 A3)^T R of ``ik`` bit for bit."""
    R03 = _mm3_blas(_mm3_blas(_dh_rot(t1, _CA, _SA), _dh_rot(t2, 1.0, 0.0)), _dh_rot(t3c, _CA, _SA))
    return _mm3_blas([list(col) for col in zip(*R03, strict=True)], R)


def _wrist(W: Sequence[Sequence[float]]) -> list[tuple[float, float, float]]:
    """(t4, t5, t6) of hands noflip, flip from the wrist rotation W (radians)."""
    r11, r12, r13 = W[0]
    r21, r22, r23 = W[1]
    r33 = W[2][2]
    sing = abs(r13) < WRIST_SING_EPS and abs(r23) < WRIST_SING_EPS
    out = []
    for branch in (math.atan2(-r23, -r13), math.atan2(r23, r13)):
        t4 = 0.0 if sing else branch
        c4, s4 = math.cos(t4), math.sin(t4)
        t5 = math.atan2(-(c4 * r13 + s4 * r23), r33)
        m20 = s4 * r11 - c4 * r21
        m21 = s4 * r12 - c4 * r22
        out.append((t4, t5, math.atan2(-m20, -m21)))
    return out


def _wrap180(x: float) -> float:
    x = 180.0 - (180.0 - x) % 360.0
    return x + 360.0 if x < -180.0 + WRAP_EPS_DEG else x


def ik_one(g: Geometry, T: npt.ArrayLike, *, clamp_tol: float = CLAMP_TOL) -> list[list[float] | None]:
    """``ik`` of one pose without numpy: 12 row-wise numbers (or (3,4)/(4,4)) -> 8
    branches (``BRANCHES`` order), each a list of 6 joints (deg, (-180, 180]) or
    None where ``ik`` gives NaN.  Same numbers as ``ik(g, T)[0]`` (see above)."""
    t = _pose12(T)
    if not all(map(math.isfinite, t)):
        return _ik_via_numpy(g, t, clamp_tol)
    try:
        return _ik_one(g, t, clamp_tol)
    except (ValueError, OverflowError):  # pragma: no cover - overflow on absurd input
        return _ik_via_numpy(g, t, clamp_tol)


def _ik_via_numpy(g: Geometry, t: list[float], clamp_tol: float) -> list[list[float] | None]:
    with np.errstate(invalid="ignore", over="ignore"):
        Q = ik(g, np.array(t).reshape(1, 12), clamp_tol=clamp_tol)[0]
    return [q.tolist() if np.all(np.isfinite(q)) else None for q in Q]


def _ik_one(g: Geometry, t: list[float], clamp_tol: float) -> list[list[float] | None]:
    r00, r01, r02, px, r10, r11, r12, py, r20, r21, r22, pz = t
    out: list[list[float] | None] = [None] * 8
    R = [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]]
    scale = max(abs(r00), abs(r01), abs(r02), abs(r10), abs(r11), abs(r12), abs(r20), abs(r21), abs(r22))
    if scale == 0.0:  # zero rotation
        return out
    noise = _NOISE * scale
    d6 = g.d6
    wx = px + d6 * r02
    wy = py + d6 * r12
    wz = pz + d6 * r22
    rho = _hypot(wx, wy)
    a2 = g.a2
    L2 = g.a3 * g.a3 + g.d4 * g.d4
    L = math.sqrt(L2)
    beta = math.atan2(g.a3, g.d4)
    h = g.d1 - wz
    lim = 1.0 + clamp_tol
    for arm in (0, 1):
        if arm == 0:
            t1 = math.atan2(wy, wx)
            r = rho - g.a1
        else:
            t1 = math.atan2(-wy, -wx)
            r = -rho - g.a1
        c = (r * r + h * h - a2 * a2 - L2) / (2.0 * a2) / L
        if not abs(c) <= lim:
            continue
        c = -1.0 if c < -1.0 else (1.0 if c > 1.0 else c)
        s2 = 1.0 - c * c
        sn0 = math.sqrt(s2 if s2 > 0.0 else 0.0)
        u = L * c
        th_r = math.atan2(h, r)
        c1, s1 = math.cos(t1), math.sin(t1)
        q1 = _wrap180(-t1 * _RAD)
        for elbow in (0, 1):
            sn = sn0 if elbow == 0 else -sn0
            v = L * sn
            t3 = math.atan2(sn, c) + beta - _HALF_PI
            t2 = th_r - math.atan2(v, a2 + u)
            t3c = t3 + _PI
            # fast wrist rotation: R03 = Rz(t1) Rx(-90) Rz(t2 + t3c) Rx(-90), W = R03^T R
            t23 = t2 + t3c
            c23, s23 = math.cos(t23), math.sin(t23)
            a00, a01, a02 = c1 * c23, s1, -c1 * s23
            a10, a11, a12 = s1 * c23, -c1, -s1 * s23
            a20, a22 = -s23, -c23
            w13 = a00 * r02 + a10 * r12 + a20 * r22
            w23 = a01 * r02 + a11 * r12
            w = [
                [a00 * r00 + a10 * r10 + a20 * r20, a00 * r01 + a10 * r11 + a20 * r21, w13],
                [a01 * r00 + a11 * r10, a01 * r01 + a11 * r11, w23],
                [0.0, 0.0, a02 * r02 + a12 * r12 + a22 * r22],
            ]
            hands = _wrist(w)
            if _near_cut(w, hands, noise):
                hands = _wrist(_W_exact(t1, t2, t3c, R))
            q2 = _wrap180(t2 * _RAD)
            q3 = _wrap180((t3 + _HALF_PI) * _RAD)
            for hand, (t4, t5, t6) in enumerate(hands):
                q = [q1, q2, q3, _wrap180(t4 * _RAD), _wrap180(t5 * _RAD), _wrap180(t6 * _RAD)]
                if all(map(math.isfinite, q)):
                    out[4 * hand + 2 * elbow + arm] = q
    return out


def _near_cut(W: Sequence[Sequence[float]], hands: Sequence[tuple[float, float, float]], noise: float) -> bool:
    """Whether plain-arithmetic noise in W could change a result of ``_wrist``."""
    r11, r12, r13 = W[0]
    r21, r22, r23 = W[1]
    if abs(abs(r13) - WRIST_SING_EPS) < noise or abs(abs(r23) - WRIST_SING_EPS) < noise:
        return True
    sing = abs(r13) < WRIST_SING_EPS and abs(r23) < WRIST_SING_EPS
    if not sing and abs(r23) <= noise:  # J4 at 0 / +-180
        return True
    for t4, _t5, _t6 in hands:
        c4, s4 = math.cos(t4), math.sin(t4)
        if abs(c4 * r13 + s4 * r23) <= noise:  # J5 at 0 / +-180
            return True
        if abs(s4 * r11 - c4 * r21) <= noise:  # J6 at 0 / +-180
            return True
    return False


def fk_compiled_one(g: Geometry, q_deg: Iterable[float], n: int = 6) -> list[float]:
    """``fk_compiled`` of one joint vector without numpy: 6 joints (deg) -> the 12
    row-wise numbers of the frame of joint n (n = 6: the flange pose).

    Plain-float products (within a few ulps of ``fk_compiled``); where those ulps
    could change the ``%f`` text -- an entry that is rounding noise around 0
    (``-0.000000`` / ``0.000000``) or next to a 6-decimal rounding boundary -- the
    result is ``fk_compiled``'s, so the printed reply is the same byte for byte.
    """
    q = [float(x) for x in q_deg]
    if len(q) != 6:
        raise ValueError(f"6 joints expected, got {len(q)}")
    if not all(map(math.isfinite, q)):
        return _fk_via_numpy(g, q, n)
    th = [-(q[0] * _DEG), q[1] * _DEG, q[2] * _DEG + _HALF_PI, q[3] * _DEG, q[4] * _DEG, q[5] * _DEG]
    d = (g.d1, 0.0, 0.0, -g.d4, 0.0, -g.d6)
    a = (g.a1, g.a2, -g.a3, 0.0, 0.0, 0.0)
    T = None
    for i in range(n):
        ct, st = math.cos(th[i]), math.sin(th[i])
        ca, sa = _ALPHA_CS[i]
        b00, b01, b02, b03 = ct, -st * ca, st * sa, a[i] * ct
        b10, b11, b12, b13 = st, ct * ca, -ct * sa, a[i] * st
        b21, b22, b23 = sa, ca, d[i]
        if T is None:
            T = [[b00, b01, b02, b03], [b10, b11, b12, b13], [0.0, b21, b22, b23]]
            continue
        T = [
            [t0 * b00 + t1 * b10, t0 * b01 + t1 * b11 + t2 * b21, t0 * b02 + t1 * b12 + t2 * b22,
             t0 * b03 + t1 * b13 + t2 * b23 + t3]
            for t0, t1, t2, t3 in T
        ]
    assert T is not None
    out = T[0] + T[1] + T[2]
    for v in out:
        x = abs(v)
        if x < 1e-9 or abs((x * 1e6) % 1.0 - 0.5) < 1e-6 * max(1.0, x):
            return _fk_via_numpy(g, q, n)
    return out


def _fk_via_numpy(g: Geometry, q: list[float], n: int) -> list[float]:
    return cast(list[float], fk_compiled(g, np.array(q).reshape(1, 6), n)[0].reshape(12).tolist())


_ALPHA_CS = [(float(c), float(s)) for c, s in zip(np.cos(DH_ALPHA), np.sin(DH_ALPHA), strict=True)]
