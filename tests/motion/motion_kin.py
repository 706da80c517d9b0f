"""Test-only kinematics for the LIN tests (motion_kin) (robots.md DH chain and OPW closed-form IK).

Not the kinematics service: just enough to give ``plan_lin`` an ``ik_fn`` and to check
straightness. Degrees and millimetres.
"""

from __future__ import annotations

import numpy as np

from rob6.robots import DH_ALPHA_DEG, DH_OFFSETS_DEG, DH_SIGNS, RobotModel

SIGNS = np.array(DH_SIGNS)
OFFS = np.radians(DH_OFFSETS_DEG)
ALPHA = np.radians(DH_ALPHA_DEG)


def fk(robot: RobotModel, q) -> np.ndarray:
    """q (N,6) deg -> poses (N,3,4)."""
    q = np.atleast_2d(np.asarray(q, float))
    n = len(q)
    d = [robot.d1, 0, 0, robot.d4, 0, robot.d6]
    a = [robot.a1, robot.a2, robot.a3, 0, 0, 0]
    T = np.tile(np.eye(4), (n, 1, 1))
    th = np.radians(q) * SIGNS + OFFS
    for i in range(6):
        ct, st = np.cos(th[:, i]), np.sin(th[:, i])
        ca, sa = np.cos(ALPHA[i]), np.sin(ALPHA[i])
        A = np.zeros((n, 4, 4))
        A[:, 0, 0] = ct
        A[:, 0, 1] = -st * ca
        A[:, 0, 2] = st * sa
        A[:, 0, 3] = a[i] * ct
        A[:, 1, 0] = st
        A[:, 1, 1] = ct * ca
        A[:, 1, 2] = -ct * sa
        A[:, 1, 3] = a[i] * st
        A[:, 2, 1] = sa
        A[:, 2, 2] = ca
        A[:, 2, 3] = d[i]
        A[:, 3, 3] = 1
        T = T @ A
    Ry = np.diag([-1.0, 1.0, -1.0, 1.0])  # Ry(180)
    T = T @ Ry
    return T[:, :3, :]


def ik_all(robot: RobotModel, poses) -> np.ndarray:
    """poses (N,3,4) -> (N,8,6) joint solutions (deg, NaN where none), OPW algorithm."""
    P = np.asarray(poses, float).reshape(-1, 3, 4)
    o = robot.opw
    a1, a2, b, c1, c2, c3, c4 = o["a1"], o["a2"], o["b"], o["c1"], o["c2"], o["c3"], o["c4"]
    # pose = OPW.fk * Rx(180): OPW rotation = R * Rx(180)
    R = P[:, :, :3] @ np.diag([1.0, -1.0, -1.0])
    p = P[:, :, 3]
    C = p - c4 * R[:, :, 2]
    cx, cy, cz = C[:, 0], C[:, 1], C[:, 2]
    with np.errstate(invalid="ignore"):
        nx1 = np.sqrt(cx**2 + cy**2 - b**2) - a1
        t1 = np.arctan2(cy, cx)
        t2 = np.arctan2(b, nx1 + a1)
        th1_i = t1 - t2
        th1_ii = t1 + t2 - np.pi
        tmp3 = cz - c1
        s1_2 = nx1**2 + tmp3**2
        tmp4 = nx1 + 2 * a1
        s2_2 = tmp4**2 + tmp3**2
        kappa_2 = a2**2 + c3**2
        c2_2 = c2**2
        tmp5 = s1_2 + c2_2 - kappa_2
        s1 = np.sqrt(s1_2)
        s2 = np.sqrt(s2_2)
        acs1 = np.arccos(np.clip(tmp5 / (2 * s1 * c2), -1 - 1e-12, 1 + 1e-12))
        tmp6 = s2_2 + c2_2 - kappa_2
        acs2 = np.arccos(np.clip(tmp6 / (2 * s2 * c2), -1 - 1e-12, 1 + 1e-12))
        th2_i = -acs1 + np.arctan2(nx1, tmp3)
        th2_ii = acs1 + np.arctan2(nx1, tmp3)
        th2_iii = -acs2 - np.arctan2(nx1 + 2 * a1, tmp3)
        th2_iv = acs2 - np.arctan2(nx1 + 2 * a1, tmp3)
        tmp9 = 2 * c2 * np.sqrt(kappa_2)
        acs3 = np.arccos(np.clip((s1_2 - c2_2 - kappa_2) / tmp9, -1 - 1e-12, 1 + 1e-12))
        acs4 = np.arccos(np.clip((s2_2 - c2_2 - kappa_2) / tmp9, -1 - 1e-12, 1 + 1e-12))
        at = np.arctan2(a2, c3)
        th3_i = acs3 - at
        th3_ii = -acs3 - at
        th3_iii = acs4 - at
        th3_iv = -acs4 - at
    arms = [(th1_i, th2_i, th3_i), (th1_i, th2_ii, th3_ii),
            (th1_ii, th2_iii, th3_iii), (th1_ii, th2_iv, th3_iv)]
    out = np.full((len(P), 8, 6), np.nan)
    for k, (t1_, t2_, t3_) in enumerate(arms):
        s1_, c1_ = np.sin(t1_), np.cos(t1_)
        s23, c23 = np.sin(t2_ + t3_), np.cos(t2_ + t3_)
        m = R[:, 0, 2] * s23 * c1_ + R[:, 1, 2] * s23 * s1_ + R[:, 2, 2] * c23
        th5 = np.arctan2(np.sqrt(np.clip(1 - m**2, 0, None)), m)
        th4 = np.arctan2(R[:, 1, 2] * c1_ - R[:, 0, 2] * s1_,
                         R[:, 0, 2] * c23 * c1_ + R[:, 1, 2] * c23 * s1_ - R[:, 2, 2] * s23)
        th6 = np.arctan2(R[:, 0, 1] * s23 * c1_ + R[:, 1, 1] * s23 * s1_ + R[:, 2, 1] * c23,
                         -R[:, 0, 0] * s23 * c1_ - R[:, 1, 0] * s23 * s1_ - R[:, 2, 0] * c23)
        for flip, (a4, a5, a6) in enumerate([(th4, th5, th6), (th4 + np.pi, -th5, th6 + np.pi)]):
            sol = np.stack([t1_, t2_, t3_, a4, a5, a6], axis=1)
            # OPW joint = (theta + offset) * sign with offsets [0, -90, 0, 0, 0, 0]
            sol = (sol + np.radians([0, -90, 0, 0, 0, 0])) * np.array(robot_signs())
            sol = np.degrees(sol)
            sol = (sol + 180.0) % 360.0 - 180.0
            out[:, 2 * k + flip] = sol
    return out


def robot_signs():
    return [-1, 1, 1, -1, 1, -1]


def make_ik(robot: RobotModel, q_ref, max_err_mm: float = 1e-6):
    """ik_fn for plan_lin: the solution in the configuration of q_ref, nearest to q_ref."""
    q_ref = np.asarray(q_ref, float)
    status_ref = robot.status(tuple(q_ref))

    def ik_fn(poses):
        poses = np.asarray(poses, float)
        sols = ik_all(robot, poses)
        out = np.full((len(poses), 6), np.nan)
        for n in range(len(poses)):
            best, best_d = None, np.inf
            for s in sols[n]:
                if np.isnan(s).any() or robot.status(tuple(s)) != status_ref:
                    continue
                d = np.abs(((s - q_ref) + 180) % 360 - 180).sum()
                if d < best_d:
                    best, best_d = s, d
            if best is not None:
                err = np.abs(fk(robot, best)[0] - poses[n]).max()
                if err < max(max_err_mm, 1e-6 * np.abs(poses[n]).max()):
                    out[n] = best
        return out

    return ik_fn
