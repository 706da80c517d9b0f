"""Trajectory generation with Ruckig: PTP (joint space) and LIN (Cartesian straight line).

Units
-----
Inside this module: degrees, seconds. The protocol's limits are per 12 ms *unit* cycle
(``rob6.units``, which the driver's limit monitor converts with too) whatever the driver rate:

* ``v [deg/s]   = speed / 0.012``
* ``a [deg/s^2] = accel / 0.012**2``
* ``j [deg/s^3] = a / JERK_RAMP_S`` -- the jerk limit is chosen so that the acceleration
  ramps from 0 to its maximum in ``JERK_RAMP_S = 0.048 s`` (4 unit cycles). It scales
  with the acceleration setting, so the profile shape does not depend on it; a
  profile that reaches both limits lasts ``d/v + v/a + JERK_RAMP_S``.

Trajectories are sampled at the driver cycle of the robot (``robot.cycle_s``), from
t = 0 (the start position) to the end; Ruckig's discrete-duration mode makes the
duration an integer number of cycles, so the last sample is exactly the target and
the samples' finite differences respect the speed/acceleration limits exactly (a
sampled, limit-respecting C2 motion has ``|dq/dt| <= v`` and ``|d2q/dt2| <= a``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import ruckig

from rob6.robots import RobotModel, get_robot
from rob6.rotations import quat_from_matrix
from rob6.status import reach_term, status_flags, status_matches
from rob6.units import JERK_RAMP_S, accel_si, jerk_si, speed_si

N_JOINTS = 6
#: max-change comparison tolerance (deg); the check is inclusive
MAX_CHANGE_EPS = 1e-9
#: positions closer than this are "the same" (deg)
SAME_EPS = 1e-9
#: speed (deg/s) or acceleration (deg/s^2) limits below this: the joint cannot move
MIN_LIMIT = 1e-9
#: moves that would take longer are refused (tiny speed limits; memory of the samples)
MAX_DURATION_S = 600.0


# ====================================================================== limits
@dataclass(frozen=True)
class JointLimits:
    """Per-joint kinematic limits in deg/s, deg/s^2, deg/s^3."""

    vmax: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray

    @classmethod
    def from_protocol(cls, speed: Sequence[float], accel: Sequence[float],
                      jerk_ramp_s: float = JERK_RAMP_S) -> "JointLimits":
        a = accel_si(accel)
        return cls(np.array(speed_si(speed)), np.array(a), np.array(jerk_si(a, jerk_ramp_s)))

    @classmethod
    def from_config(cls, config) -> "JointLimits":
        return cls.from_protocol(config.speed, config.accel)


# ====================================================================== results
@dataclass
class SampledTrajectory:
    """Joint trajectory sampled every ``dt`` seconds; row 0 is the start position."""

    dt: float
    t: np.ndarray  # (N,)
    q: np.ndarray  # (N, 6) deg
    qd: np.ndarray  # (N, 6) deg/s
    qdd: np.ndarray  # (N, 6) deg/s^2

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def end(self) -> np.ndarray:
        return self.q[-1]

    @classmethod
    def still(cls, q, dt) -> "SampledTrajectory":
        q = np.asarray(q, float).reshape(1, N_JOINTS)
        z = np.zeros_like(q)
        return cls(dt, np.zeros(1), q.copy(), z, z.copy())


@dataclass
class PlanResult:
    ok: bool
    reason: str = ""
    trajectory: SampledTrajectory | None = None
    info: dict = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.ok


# ====================================================================== sampling
def sample_profiles(traj: ruckig.Trajectory, times: np.ndarray):
    """Vectorised sampling of a Ruckig trajectory (no brake phase) at sorted ``times``.

    Uses the 7-phase constant-jerk profiles of each DoF; after a profile's end the DoF
    keeps its final state (rest, for our position targets).
    -> q, qd, qdd arrays (len(times), dofs). Agrees with ``Trajectory.at_time`` to ~1e-13.
    """
    profiles = traj.profiles[0]
    dofs = len(profiles)
    times = np.asarray(times, float)
    n = len(times)
    tab = np.empty((dofs, 7, 6))  # per phase: start time, duration, p, v, a, j
    idx = np.empty((n, dofs), dtype=np.intp)
    phases = np.arange(7)
    for d, prof in enumerate(profiles):
        if prof.brake.duration > 0.0:
            raise ValueError("brake phase present: use Trajectory.at_time")
        t = prof.t
        tab[d, :, 1] = t
        tab[d, :, 2] = prof.p[:7]
        tab[d, :, 3] = prof.v[:7]
        tab[d, :, 4] = prof.a[:7]
        tab[d, :, 5] = prof.j
        cum = np.cumsum(tab[d, :, 1])
        tab[d, 0, 0] = 0.0
        tab[d, 1:, 0] = cum[:6]
        # sample k is in phase i when start_i <= t_k < start_{i+1} (the last phase is open)
        bounds = np.searchsorted(times, cum[:6], side="left")
        counts = np.diff(np.concatenate(([0], bounds, [n])))
        idx[:, d] = np.repeat(phases, counts) + 7 * d
    flat = tab.reshape(dofs * 7, 6)
    start, dur, P, V, A, J = (np.ascontiguousarray(flat[:, k]).take(idx) for k in range(6))
    # in-place Horner evaluation (large temporaries are what costs here)
    tau = start
    np.subtract(times[:, None], start, out=tau)
    np.minimum(tau, dur, out=tau)
    qdd = tau * J
    qdd += A
    qd = tau * J
    qd *= 0.5
    qd += A
    qd *= tau
    qd += V
    q = tau * J
    q *= 1.0 / 6.0
    A *= 0.5
    q += A
    q *= tau
    q += V
    q *= tau
    q += P
    return q, qd, qdd


def sample_at_time(traj: ruckig.Trajectory, times: np.ndarray):
    """Reference sampler through Ruckig's ``at_time`` (slow; for tests and brake phases)."""
    out = [traj.at_time(float(t)) for t in times]
    q = np.array([o[0] for o in out])
    qd = np.array([o[1] for o in out])
    qdd = np.array([o[2] for o in out])
    return q, qd, qdd


def finite_difference_violations(q: np.ndarray, dt: float, vmax: np.ndarray, amax: np.ndarray,
                                 qd0=None, rtol: float = 1e-6, atol_v: float = 1e-9,
                                 atol_a: float = 1e-6) -> list[str]:
    """Speed/acceleration violations of samples q (N,6) seen as a cycle-by-cycle monitor.

    ``qd0``: velocity before the first sample (default 0, i.e. starting at rest).
    """
    q = np.asarray(q, float)
    if len(q) < 2:
        return []
    v = np.diff(q, axis=0) / dt
    v_prev = np.vstack([np.zeros((1, q.shape[1])) if qd0 is None else np.asarray(qd0, float)[None],
                        v[:-1]])
    a = (v - v_prev) / dt
    problems = []
    bad_v = np.abs(v) > vmax * (1 + rtol) + atol_v
    bad_a = np.abs(a) > amax * (1 + rtol) + atol_a
    for kind, bad, val, lim in (("speed", bad_v, v, vmax), ("acceleration", bad_a, a, amax)):
        if bad.any():
            k, j = np.argwhere(bad)[0]
            problems.append(f"joint {j + 1} {kind} {abs(val[k, j]):.6g} > {lim[j]:.6g} at sample {k + 1}")
    return problems


# ====================================================================== checks
def turn_limit_violation(q: np.ndarray, turn_min, turn_max, start=None) -> tuple[int, int] | None:
    """First (sample, joint) not strictly inside the turn limits, or None.

    ``start``: if given, a joint that already is outside its limits there (limits changed
    after it got there) may stay outside as long as it does not go further out.
    """
    q = np.atleast_2d(np.asarray(q, float))
    lo = np.asarray(turn_min, float)
    hi = np.asarray(turn_max, float)
    if start is not None:
        s = np.asarray(start, float)
        lo_ok = np.where(s <= lo, q >= s, q > lo)
        hi_ok = np.where(s >= hi, q <= s, q < hi)
        ok = lo_ok & hi_ok
    else:
        ok = (q > lo) & (q < hi)
    if ok.all():
        return None
    k, j = np.argwhere(~ok)[0]
    return int(k), int(j)


def check_target(q0, q1, config, pattern=None) -> str:
    """Validation of a joint target before any motion: '' if OK, else the reason.

    Strict turn limits at the target (``min < q < max``), max change per joint from the
    current position (inclusive), and -- when ``config`` has ``allowed`` and ``robot``
    (a MotionConfig) -- the allowed status and the optional status ``pattern``
    (MovePTPJointsStatus) for the target's status computed from its joints, as the
    original (REFERENCE.md 6.4, 6.6).
    """
    q0 = np.asarray(q0, float)
    q1 = np.asarray(q1, float)
    if q1.shape != (N_JOINTS,) or not np.all(np.isfinite(q1)):
        return "target is not 6 finite joint values"
    lo = np.asarray(config.turn_min, float)
    hi = np.asarray(config.turn_max, float)
    bad = ~((q1 > lo) & (q1 < hi))
    if bad.any():
        j = int(np.argmax(bad))
        return f"joint {j + 1} target {q1[j]:.6f} outside turn limits ({lo[j]:g}, {hi[j]:g})"
    change = np.abs(q1 - q0)
    mc = np.asarray(config.max_change, float)
    bad = change > mc + MAX_CHANGE_EPS
    if bad.any():
        j = int(np.argmax(bad))
        return f"joint {j + 1} change {change[j]:.6f} exceeds max change {mc[j]:g}"
    robot = getattr(config, "robot", None)
    allowed = getattr(config, "allowed", None)
    if robot is not None and (allowed is not None or pattern is not None):
        target = robot.status(tuple(q1))
        current = robot.status(tuple(q0))
        for name, pat in (("allowed status", allowed), ("status", pattern)):
            if pat is not None and not status_matches(pat, target, current):
                return f"target status {' '.join(target)} does not match the {name} {' '.join(pat)}"
    return ""


# ====================================================================== planner
class TrajectoryPlanner:
    """PTP and LIN planning for one robot type at its driver cycle.

    Not thread-safe (it reuses its Ruckig instances); use one per thread.
    """

    def __init__(self, robot: RobotModel | str, dt: float | None = None,
                 jerk_ramp_s: float = JERK_RAMP_S):
        self.robot = get_robot(robot) if isinstance(robot, str) else robot
        self.dt = float(dt if dt is not None else self.robot.cycle_s)
        self.jerk_ramp_s = jerk_ramp_s
        self.max_duration_s = MAX_DURATION_S
        self._otg = ruckig.Ruckig(N_JOINTS, self.dt)
        self._inp = ruckig.InputParameter(N_JOINTS)
        self._inp.synchronization = ruckig.Synchronization.Phase
        self._inp.duration_discretization = ruckig.DurationDiscretization.Discrete
        self._traj = ruckig.Trajectory(N_JOINTS)
        self._otg1 = ruckig.Ruckig(1, self.dt)
        self._inp1 = ruckig.InputParameter(1)
        self._inp1.duration_discretization = ruckig.DurationDiscretization.Discrete
        self._traj1 = ruckig.Trajectory(1)

    def limits(self, config) -> JointLimits:
        return JointLimits.from_protocol(config.speed, config.accel, self.jerk_ramp_s)

    # ------------------------------------------------------------------ PTP
    def plan_ptp(self, q0, q1, config, *, check: bool = True, sample: bool = True,
                 pattern: Sequence[str] | None = None) -> PlanResult:
        """Jerk-limited, time-synchronised joint move q0 -> q1 (rest to rest).

        ``config``: a MotionConfig (or anything with speed, accel, turn_min, turn_max,
        max_change). ``check``: validate the target first (turn limits, max change).
        ``sample=False`` skips sampling (``info['duration']`` only). ``pattern``: an
        explicit status pattern the target must match (MovePTPJointsStatus).
        """
        q0 = np.asarray(q0, float)
        q1 = np.asarray(q1, float)
        if check:
            reason = check_target(q0, q1, config, pattern)
            if reason:
                return PlanResult(False, reason)
        delta = q1 - q0
        moving = np.abs(delta) > SAME_EPS
        if not moving.any():
            traj = SampledTrajectory.still(q1, self.dt)
            return PlanResult(True, trajectory=traj, info={"duration": 0.0})
        lim = self.limits(config)
        stuck = moving & ~((lim.vmax > MIN_LIMIT) & (lim.amax > MIN_LIMIT))
        if stuck.any():
            j = int(np.argmax(stuck))
            return PlanResult(False, f"joint {j + 1} cannot move: max speed or acceleration is 0")
        inp = self._inp
        # joints that do not move get harmless nonzero limits (Ruckig needs > 0)
        vmax = np.where(moving, lim.vmax, 1.0)
        amax = np.where(moving, lim.amax, 1.0)
        jmax = np.where(moving, lim.jmax, 1.0)
        target = np.where(moving, q1, q0)
        inp.current_position = q0.tolist()
        inp.current_velocity = [0.0] * N_JOINTS
        inp.current_acceleration = [0.0] * N_JOINTS
        inp.target_position = target.tolist()
        inp.target_velocity = [0.0] * N_JOINTS
        inp.target_acceleration = [0.0] * N_JOINTS
        inp.max_velocity = vmax.tolist()
        inp.max_acceleration = amax.tolist()
        inp.max_jerk = jmax.tolist()
        try:
            result = self._otg.calculate(inp, self._traj)
        except Exception as exc:  # ruckig raises on invalid input
            return PlanResult(False, f"trajectory generation failed: {exc}")
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            return PlanResult(False, f"trajectory generation failed: {result}")
        duration = self._traj.duration
        if duration > self.max_duration_s:
            return PlanResult(False, f"move would take {duration:.6g} s (limit {self.max_duration_s:g} s)")
        # rest-to-rest profiles are monotone; make sure nothing leaves the limits anyway
        ext = self._traj.position_extrema
        lo_ext = np.array([b.min for b in ext])
        hi_ext = np.array([b.max for b in ext])
        bad = turn_limit_violation(np.vstack([lo_ext, hi_ext]), config.turn_min, config.turn_max,
                                   start=q0) if check else None
        if bad is not None:
            return PlanResult(False, f"joint {bad[1] + 1} would leave its turn limits on the way")
        info = {"duration": duration}
        if not sample:
            return PlanResult(True, info=info)
        n = int(round(duration / self.dt)) + 1
        times = np.arange(n) * self.dt
        q, qd, qdd = sample_profiles(self._traj, times)
        q[-1] = target  # exact end
        qd[-1] = 0.0
        qdd[-1] = 0.0
        return PlanResult(True, trajectory=SampledTrajectory(self.dt, times, q, qd, qdd), info=info)

    def ptp_duration(self, q0, q1, config) -> float:
        """Duration (s) of the PTP move, no sampling, no target checks."""
        res = self.plan_ptp(q0, q1, config, check=False, sample=False)
        if not res.ok:
            raise ValueError(res.reason)
        return res.info["duration"]

    # ------------------------------------------------------------------ LIN
    def plan_lin(self, q0, pose0, pose1, config, ik_fn: Callable[[np.ndarray], np.ndarray], *,
                 manip_fn: Callable[[np.ndarray], np.ndarray] | None = None,
                 options: "LinOptions | None" = None) -> PlanResult:
        """Straight Cartesian line pose0 -> pose1 (orientation slerp), see ``plan_lin``."""
        return plan_lin(self, q0, pose0, pose1, config, ik_fn, manip_fn=manip_fn,
                        options=options or LinOptions())

    def _plan_1d(self, vmax: float, amax: float, jmax: float) -> ruckig.Trajectory | None:
        inp = self._inp1
        inp.current_position = [0.0]
        inp.current_velocity = [0.0]
        inp.current_acceleration = [0.0]
        inp.target_position = [1.0]
        inp.target_velocity = [0.0]
        inp.target_acceleration = [0.0]
        inp.max_velocity = [vmax]
        inp.max_acceleration = [amax]
        inp.max_jerk = [jmax]
        try:
            result = self._otg1.calculate(inp, self._traj1)
        except Exception:
            return None
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            return None
        return self._traj1


# ====================================================================== LIN
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
        return out / np.linalg.norm(out, axis=1, keepdims=True)
    theta = math.acos(min(dot, 1.0))
    sin_t = math.sin(theta)
    return (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / sin_t


class LinePath:
    """p(s) = p0 + s (p1 - p0), R(s) = slerp(R0, R1, s), s in [0, 1]."""

    def __init__(self, pose0, pose1):
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


def _validate_joint_path(robot: RobotModel, q0, Q: np.ndarray, s: np.ndarray, path: LinePath,
                         config, opts: LinOptions, manip_fn) -> str:
    """Reason why the joint path Q (N,6) (Q[0] == q0) is not acceptable, or ''.

    Of all problems, the one nearest to the start of the line is reported.
    """
    def at(k):
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


def _ik(ik_fn, poses: np.ndarray, q0) -> np.ndarray:
    Q = np.asarray(ik_fn(poses), float).reshape(len(poses), N_JOINTS)
    return _unwrap_sequence(Q, q0)


def plan_lin(planner: TrajectoryPlanner, q0, pose0, pose1, config, ik_fn, *,
             manip_fn=None, options: LinOptions | None = None) -> PlanResult:
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
