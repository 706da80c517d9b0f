"""LIN planning: the straight line solved into joints, checked, and timed by one Ruckig profile.

LIN planning: a straight Cartesian line solved into joints, checked (reachability, turn
limits, max change, configuration, jumps, singularities) and timed by one jerk-limited
Ruckig profile of the path parameter (``plan_lin``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from rob6.robots import RobotModel
from rob6.status import reach_term, status_flags, status_matches

from .cartesian_line import LinePath
from .trajectory import (
    MAX_CHANGE_EPS,
    MIN_LIMIT,
    N_JOINTS,
    Limits,
    PlanResult,
    SampledTrajectory,
    TrajectoryPlanner,
    finite_difference_violations,
    sample_profiles,
    turn_limit_violation,
)

#: poses (N, 3, 4) -> joints (N, 6) in the current configuration, NaN where unreachable
IkFn = Callable[[np.ndarray], ArrayLike]
#: joints (N, 6) -> manipulability (N,)
ManipFn = Callable[[np.ndarray], ArrayLike]


@dataclass
class LinOptions:
    """Parameters of LIN planning (lengths mm, angles deg)."""

    step_mm: float = 1.0  # max translation between geometric check samples
    step_deg: float = 0.5  # max rotation between geometric check samples
    jump_deg: float = 5.0  # a joint changing more than this between check samples = jump
    wrist_margin_deg: float = 1.0  # |q5| below this: wrist singularity
    elbow_margin_deg: float = 1.0  # elbow within this of stretched: elbow singularity
    shoulder_margin_mm: float = 10.0  # wrist centre this close to the J1 axis: shoulder sing.
    manip_min: float = 0.0  # with manip_fn: manipulability below this = singular
    start_tol_deg: float = 0.01  # IK of the start pose must reproduce q0 within this
    accel_share_max: float = 0.5  # at most this share of a_max for the path-curvature term
    max_retries: int = 8  # time-scaling retries when the sampled motion breaks a limit


def _unwrap_sequence(q: np.ndarray, q_start: np.ndarray) -> np.ndarray:
    """Shift each joint by multiples of 360 deg for continuity from q_start (NaN-safe)."""
    q = np.array(q, float)
    prev = np.asarray(q_start, float).copy()
    for k in range(len(q)):
        row = q[k]
        finite = np.isfinite(row)
        row[finite] += 360.0 * np.round((prev[finite] - row[finite]) / 360.0)
        prev = np.where(finite, row, prev)
    return q


def _validate_joint_path(robot: RobotModel, q0: np.ndarray, Q: np.ndarray, s: np.ndarray, path: LinePath,
                         config: Limits, opts: LinOptions, manip_fn: ManipFn | None) -> str:
    """Reason why the joint path Q (N,6) (Q[0] == q0) is not acceptable, or ''.

    Of all problems, the one nearest to the start of the line is reported.
    """
    def at(k: int) -> str:
        return f"at {100 * s[k]:.1f}% of the line"

    problems: list[tuple[int, str]] = []  # (sample index, reason); first wins
    nan_rows = np.isnan(Q).any(axis=1)
    if nan_rows.any():
        k = int(np.argmax(nan_rows))
        p = path.poses(s[k:k + 1])[0, :, 3]
        problems.append((k, f"unreachable {at(k)} (x={p[0]:.3f} y={p[1]:.3f} z={p[2]:.3f})"))
        end = k  # the checks below only look at the reachable part before it
    else:
        end = len(Q)
    Qv = Q[:end]
    if end > 1:
        bad = turn_limit_violation(Qv[1:], config.turn_min, config.turn_max, start=q0)
        if bad is not None:
            k, j = bad[0] + 1, bad[1]
            problems.append((k, f"joint {j + 1} leaves its turn limits {at(k)} ({Qv[k, j]:.3f})"))
        mc = np.asarray(config.max_change, float)
        over = np.abs(Qv - q0) > mc + MAX_CHANGE_EPS
        if over.any():
            k, j = np.argwhere(over)[0]
            problems.append((int(k), f"joint {j + 1} changes {abs(Qv[k, j] - q0[j]):.3f} > max change {mc[j]:g} {at(k)}"))
        steps = np.abs(np.diff(Qv, axis=0))
        if (steps > opts.jump_deg).any():
            k, j = np.argwhere(steps > opts.jump_deg)[0]
            problems.append((int(k) + 1, f"joint {j + 1} jumps {steps[k, j]:.3f} deg {at(k + 1)}"))
    # singularities (the path is refused when it gets this close)
    q5 = np.abs(Qv[:, 4])
    near = q5 < opts.wrist_margin_deg
    if near.any():
        k = int(np.argmax(near))
        problems.append((k, f"wrist singularity (|q5| = {q5[k]:.3f} < {opts.wrist_margin_deg:g} deg) {at(k)}"))
    q2 = np.radians(Qv[:, 1])
    q3 = np.radians(Qv[:, 2])
    phi = math.atan2(robot.a3, robot.d4)  # up <=> sin(q3 - phi) > 0; stretched at q3 = phi
    near = np.abs(np.sin(q3 - phi)) < math.sin(math.radians(opts.elbow_margin_deg))
    if near.any():
        k = int(np.argmax(near))
        problems.append((k, f"elbow singularity (arm stretched) {at(k)}"))
    reach = reach_term(robot, q2, q3, sin=np.sin, cos=np.cos)
    near = np.abs(reach) < opts.shoulder_margin_mm
    if near.any():
        k = int(np.argmax(near))
        problems.append((k, f"shoulder singularity (wrist centre on the J1 axis) {at(k)}"))
    if manip_fn is not None and len(Qv):
        m = np.asarray(manip_fn(Qv), float)
        near = m < opts.manip_min
        if near.any():
            k = int(np.argmax(near))
            problems.append((k, f"near singularity (manipulability {m[k]:.3g} < {opts.manip_min:g}) {at(k)}"))
    # configuration must not change (robots.md status formulas, vectorised)
    if len(Qv):
        flags = np.stack(status_flags(robot, q2, q3, Qv[:, 4], sin=np.sin, cos=np.cos), axis=1)
        changed = (flags != flags[0]).any(axis=1)
        if changed.any():
            k = int(np.argmax(changed))
            problems.append((k, f"configuration changes to {' '.join(robot.status(tuple(Qv[k])))} {at(k)}"))
    if not problems:
        return ""
    return min(problems, key=lambda kp: kp[0])[1]


def _ik(ik_fn: IkFn, poses: np.ndarray, q0: np.ndarray) -> np.ndarray:
    Q = np.asarray(ik_fn(poses), float).reshape(len(poses), N_JOINTS)
    return _unwrap_sequence(Q, q0)


def plan_lin(planner: TrajectoryPlanner, q0: ArrayLike, pose0: ArrayLike, pose1: ArrayLike, config: Limits,
             ik_fn: IkFn, *, manip_fn: ManipFn | None = None, options: LinOptions | None = None) -> PlanResult:
    """Plan a LIN move from the current joints q0 (whose pose is pose0) to pose1.

    * The line (position lerp, orientation slerp) is sampled every ``step_mm`` /
      ``step_deg`` and solved with ``ik_fn(poses (N,3,4)) -> (N,6)`` (joints in the
      current configuration, NaN where unreachable). Joint values are unwrapped by
      360 deg for continuity. Rejected with a reason if any point is unreachable, leaves
      the strict turn limits, exceeds the max change from q0, changes configuration,
      jumps more than ``jump_deg`` between samples, or comes within the singularity
      margins (|q5| < 1 deg, elbow within 1 deg of stretched, wrist centre within 10 mm
      of the J1 axis, optional ``manip_fn(Q) < manip_min``).
    * Time law: one jerk-limited Ruckig profile for the path parameter s with
      ``s' <= min v_j / max|dq_j/ds|`` and the acceleration budget split between the
      curvature term ``|d2q/ds2| s'^2`` and ``|dq/ds| s''``. The samples at the driver
      cycle are solved again with ``ik_fn``, re-validated and checked cycle by cycle
      against the speed/acceleration limits; on a violation the time law is slowed down
      (up to ``max_retries`` times).
    """
    opts = options or LinOptions()
    robot = planner.robot
    dt = planner.dt
    q0 = np.asarray(q0, float)
    path = LinePath(pose0, pose1)
    n_geo = max(int(math.ceil(max(path.length_mm / opts.step_mm, path.angle_deg / opts.step_deg))), 1) + 1
    if path.length_mm < 1e-9 and path.angle_deg < 1e-9:
        return PlanResult(True, trajectory=SampledTrajectory.still(q0, dt), info={"duration": 0.0})
    s_geo = np.linspace(0.0, 1.0, n_geo)
    Q = _ik(ik_fn, path.poses(s_geo), q0)
    if np.all(np.isfinite(Q[0])) and np.abs(Q[0] - q0).max() > opts.start_tol_deg:
        return PlanResult(False, "the start pose does not match the current joints in this configuration")
    Q[0] = q0
    reason = _validate_joint_path(robot, q0, Q, s_geo, path, config, opts, manip_fn)
    if reason:
        return PlanResult(False, reason)
    allowed = getattr(config, "allowed", None)
    if allowed is not None:

        target, current = robot.status(tuple(Q[-1])), robot.status(tuple(q0))
        if not status_matches(allowed, target, current):
            return PlanResult(False, f"target status {' '.join(target)} does not match the "
                                     f"allowed status {' '.join(allowed)}")

    lim = planner.limits(config)
    d1 = np.gradient(Q, s_geo, axis=0)
    d2 = np.gradient(d1, s_geo, axis=0)
    D1 = np.abs(d1).max(axis=0) * 1.05 + 1e-12
    D2 = np.abs(d2).max(axis=0) * 1.05 + 1e-12
    moving = D1 > 1e-9
    can_move = (lim.vmax > MIN_LIMIT) & (lim.amax > MIN_LIMIT)
    if (moving & ~can_move).any():
        j = int(np.argmax(moving & ~can_move))
        return PlanResult(False, f"joint {j + 1} cannot move: max speed or acceleration is 0")
    with np.errstate(divide="ignore", invalid="ignore"):
        sd_v = np.min(np.where(moving, lim.vmax / D1, np.inf))
        # curvature term may use at most accel_share_max of a_max
        sd_a = np.min(np.where(moving, np.sqrt(opts.accel_share_max * lim.amax / D2), np.inf))
        sd_max = min(sd_v, sd_a)
        share = np.where(moving, D2 * sd_max**2 / lim.amax, 0.0)
        sdd_max = np.min(np.where(moving, (1.0 - share) * lim.amax / D1, np.inf))
    if not (np.isfinite(sd_max) and np.isfinite(sdd_max) and sd_max > 0 and sdd_max > 0):
        return PlanResult(False, "cannot time-parametrise the line")

    scale = 1.0
    last_problem = ""
    for _ in range(opts.max_retries + 1):
        v_s, a_s = sd_max * scale, sdd_max * scale**2
        traj = planner._plan_1d(v_s, a_s, a_s / planner.jerk_ramp_s)
        if traj is None:
            return PlanResult(False, "time law generation failed")
        duration = traj.duration
        if duration > planner.max_duration_s:
            return PlanResult(False, f"move would take {duration:.6g} s (limit {planner.max_duration_s:g} s)")
        n = int(round(duration / dt)) + 1
        times = np.arange(n) * dt
        s_t, _, _ = sample_profiles(traj, times)
        s_t = np.clip(s_t[:, 0], 0.0, 1.0)
        s_t[-1] = 1.0
        Qt = _ik(ik_fn, path.poses(s_t), q0)
        Qt[0] = q0
        # jumps show up here as speed violations (the sample spacing follows the speed)
        reason = _validate_joint_path(robot, q0, Qt, s_t, path, config,
                                      replace(opts, jump_deg=math.inf), manip_fn)
        if reason:
            return PlanResult(False, reason)
        problems = finite_difference_violations(Qt, dt, lim.vmax, lim.amax)
        if not problems:
            vel = np.gradient(Qt, dt, axis=0)
            acc = np.gradient(vel, dt, axis=0)
            vel[0] = vel[-1] = 0.0
            acc[0] = acc[-1] = 0.0
            return PlanResult(True, trajectory=SampledTrajectory(dt, times, Qt, vel, acc),
                              info={"duration": duration, "time_scale": scale,
                                    "samples_checked": n_geo, "length_mm": path.length_mm,
                                    "angle_deg": path.angle_deg})
        last_problem = problems[0]
        scale *= 0.8
    return PlanResult(False, f"cannot keep the joint limits along the line: {last_problem}")
