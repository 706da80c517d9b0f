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

import numpy as np

from rob6 import robots

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
    def of(cls, robot) -> "Geometry":
        return cls(robot.d1, robot.a1, robot.a2, robot.a3, robot.d4, robot.d6)

    @property
    def d(self) -> np.ndarray:
        return np.array([self.d1, 0.0, 0.0, self.d4, 0.0, self.d6])

    @property
    def a(self) -> np.ndarray:
        return np.array([self.a1, self.a2, self.a3, 0.0, 0.0, 0.0])


# --------------------------------------------------------------------------- helpers
def wrap180(q):
    """Map angles (deg) into (-180, 180]."""
    q = np.asarray(q, dtype=float)
    return 180.0 - np.mod(180.0 - q, 360.0)


def as_poses(T) -> np.ndarray:
    """Accept (12,), (3,4), (4,4), (N,12), (N,3,4), (N,4,4); return (N,3,4) float."""
    T = np.asarray(T, dtype=float)
    if T.shape[-1] == 12:
        T = T.reshape(T.shape[:-1] + (3, 4))
    if T.shape[-2:] == (4, 4):
        T = T[..., :3, :]
    if T.shape[-2:] != (3, 4):
        raise ValueError(f"pose shape {T.shape} is not (...,3,4)/(...,4,4)/(...,12)")
    return T.reshape((-1, 3, 4))


def as_joints(q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != 6:
        raise ValueError(f"joint shape {q.shape} is not (...,6)")
    return q.reshape((-1, 6))


def dh_chain(theta, d, a, alpha) -> np.ndarray:
    """Product A1..An of standard DH matrices, vectorised.

    theta: (N, n) radians; d, a, alpha: (n,).  Returns (N, 4, 4).
    """
    theta = np.asarray(theta, dtype=float)
    N, n = theta.shape
    ct, st = np.cos(theta), np.sin(theta)
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
def fk(g: Geometry, q_deg) -> np.ndarray:
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


def fk_compiled(g: Geometry, q_deg, n: int = 6) -> np.ndarray:
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


def fk_dh(g: Geometry, q_deg) -> np.ndarray:
    """Reference FK by the literal DH product (slower; used in tests)."""
    q = as_joints(q_deg) * DEG
    theta = DH_SIGNS * q + DH_OFFSETS
    T = dh_chain(theta, g.d, g.a, DH_ALPHA)
    Ry180 = np.diag([-1.0, 1.0, -1.0, 1.0])
    return (T @ Ry180)[:, :3, :]


# --------------------------------------------------------------------------- IK
def ik(g: Geometry, T, *, clamp_tol: float = CLAMP_TOL) -> np.ndarray:
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
    T = as_poses(T)
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

    def dh_rot(th, ca, sa):
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
