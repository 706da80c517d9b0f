"""Joint-space trajectories with Ruckig: limits, sampling at the driver cycle, target checks, PTP.

Trajectory generation with Ruckig: joint limits, sampling Ruckig's profiles at the
driver cycle, target checks and PTP (joint space) planning. LIN (the Cartesian straight
line) builds on it and this module knows nothing of it: ``lin_planner`` (checks and time
law, ``plan_lin(planner, ...)``) and ``cartesian_line`` (the line's geometry).

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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import ruckig
from numpy.typing import ArrayLike

from rob6.robots import RobotModel, get_robot
from rob6.status import status_matches
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
class Limits(Protocol):
    """What planning reads of a configuration: a ``MotionSettings``, a ``MotionConfig`` or
    anything else with these per-joint protocol values."""

    @property
    def speed(self) -> Sequence[float]: ...
    @property
    def accel(self) -> Sequence[float]: ...
    @property
    def max_change(self) -> Sequence[float]: ...
    @property
    def turn_min(self) -> Sequence[float]: ...
    @property
    def turn_max(self) -> Sequence[float]: ...


@dataclass(frozen=True)
class JointLimits:
    """Per-joint kinematic limits in deg/s, deg/s^2, deg/s^3."""

    vmax: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray

    @classmethod
    def from_protocol(cls, speed: Sequence[float], accel: Sequence[float],
                      jerk_ramp_s: float = JERK_RAMP_S) -> JointLimits:
        a = accel_si(accel)
        return cls(np.array(speed_si(speed)), np.array(a), np.array(jerk_si(a, jerk_ramp_s)))

    @classmethod
    def from_config(cls, config: Limits) -> JointLimits:
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
        end: np.ndarray = self.q[-1]
        return end

    @classmethod
    def still(cls, q: ArrayLike, dt: float) -> SampledTrajectory:
        q = np.asarray(q, float).reshape(1, N_JOINTS)
        z = np.zeros_like(q)
        return cls(dt, np.zeros(1), q.copy(), z, z.copy())


@dataclass
class PlanResult:
    ok: bool
    reason: str = ""
    trajectory: SampledTrajectory | None = None
    info: dict[str, float] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return self.ok


# ====================================================================== sampling
def sample_profiles(traj: ruckig.Trajectory, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised sampling of a Ruckig trajectory (no brake phase) at sorted ``times``.

    Uses the 7-phase constant-jerk profiles of each DoF; after a profile's end the DoF
    keeps its final state (rest, for our position targets). Every DoF at once: a move's
    planning is on the request path, and a numpy call costs more than its arithmetic here.
    -> q, qd, qdd arrays (len(times), dofs). Agrees with ``Trajectory.at_time`` to ~1e-12.
    """
    profiles = traj.profiles[0]
    if any(prof.brake.duration > 0.0 for prof in profiles):
        raise ValueError("brake phase present: use Trajectory.at_time")
    dofs = len(profiles)
    times = np.asarray(times, float)
    n = len(times)
    tab = np.empty((dofs, 7, 6))  # per DoF and phase: start time, duration, p, v, a, j
    tab[:, :, 1:] = np.array([(prof.t, prof.p[:7], prof.v[:7], prof.a[:7], prof.j)
                              for prof in profiles]).transpose(0, 2, 1)
    ends = np.cumsum(tab[:, :, 1], axis=1)
    tab[:, 0, 0] = 0.0
    tab[:, 1:, 0] = ends[:, :6]
    # sample k is in phase i when start_i <= t_k < start_{i+1} (the last phase is open):
    # per DoF, its samples run through the 7 phases in turn, counts[d, i] of them in phase i
    counts = np.diff(np.searchsorted(times, ends[:, :6], side="left"), prepend=0, append=n, axis=1)
    idx = np.repeat(np.arange(dofs * 7), counts.ravel()).reshape(dofs, n).T
    start, dur, P, V, A, J = np.moveaxis(tab.reshape(dofs * 7, 6)[idx], 2, 0)
    # in-place Horner evaluation (large temporaries are what costs on long moves)
    tau = times[:, None] - start
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
    q += 0.5 * A
    q *= tau
    q += V
    q *= tau
    q += P
    return q, qd, qdd


def sample_at_time(traj: ruckig.Trajectory, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference sampler through Ruckig's ``at_time`` (slow; for tests and brake phases)."""
    out = [traj.at_time(float(t)) for t in times]
    q = np.array([o[0] for o in out])
    qd = np.array([o[1] for o in out])
    qdd = np.array([o[2] for o in out])
    return q, qd, qdd


def finite_difference_violations(q: np.ndarray, dt: float, vmax: np.ndarray, amax: np.ndarray,
                                 qd0: ArrayLike | None = None, rtol: float = 1e-6, atol_v: float = 1e-9,
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
def turn_limit_violation(q: ArrayLike, turn_min: ArrayLike, turn_max: ArrayLike,
                         start: ArrayLike | None = None) -> tuple[int, int] | None:
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


def check_target(q0: ArrayLike, q1: ArrayLike, config: Limits, pattern: Sequence[str] | None = None) -> str:
    """Validation of a joint target before any motion: '' if OK, else the reason.

    Strict turn limits at the target (``min < q < max``), max change per joint from the
    current position (inclusive), and -- when ``config`` has ``allowed`` and ``robot``
    (a ``MotionSettings``) -- the allowed status and the optional status ``pattern``
    (MovePTPJointsStatus) for the target's status computed from its joints, as the
    original (REFERENCE.md 6.4, 6.6).
    """
    goal = np.asarray(q1, float)
    if goal.shape != (N_JOINTS,) or not np.isfinite(goal).all():
        return "target is not 6 finite joint values"
    # six numbers: plain Python, cheaper than numpy's calls on the request path
    end, start = goal.tolist(), np.asarray(q0, float).tolist()
    for j, (q, lo, hi) in enumerate(zip(end, config.turn_min, config.turn_max, strict=True)):
        if not lo < q < hi:
            return f"joint {j + 1} target {q:.6f} outside turn limits ({lo:g}, {hi:g})"
    for j, (a, b, most) in enumerate(zip(start, end, config.max_change, strict=True)):
        if abs(b - a) > most + MAX_CHANGE_EPS:
            return f"joint {j + 1} change {abs(b - a):.6f} exceeds max change {most:g}"
    robot = getattr(config, "robot", None)
    allowed = getattr(config, "allowed", None)
    if robot is not None and (allowed is not None or pattern is not None):
        target = robot.status(end)
        current = robot.status(start)
        for name, pat in (("allowed status", allowed), ("status", pattern)):
            if pat is not None and not status_matches(pat, target, current):
                return f"target status {' '.join(target)} does not match the {name} {' '.join(pat)}"
    return ""


# ====================================================================== planner
class TrajectoryPlanner:
    """PTP planning for one robot type at its driver cycle (LIN: ``lin_planner.plan_lin``,
    which plans its time law with ``_plan_1d``).

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

    def limits(self, config: Limits) -> JointLimits:
        return JointLimits.from_protocol(config.speed, config.accel, self.jerk_ramp_s)

    # ------------------------------------------------------------------ PTP
    def plan_ptp(self, q0: ArrayLike, q1: ArrayLike, config: Limits, *, check: bool = True, sample: bool = True,
                 pattern: Sequence[str] | None = None) -> PlanResult:
        """Jerk-limited, time-synchronised joint move q0 -> q1 (rest to rest).

        ``config``: a ``MotionSettings`` (or anything with speed, accel, turn_min, turn_max,
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
        # six joints: plain Python, cheaper than numpy's calls on the request path
        start, end = q0.tolist(), q1.tolist()
        moving = [abs(b - a) > SAME_EPS for a, b in zip(start, end, strict=True)]
        if not any(moving):
            traj = SampledTrajectory.still(q1, self.dt)
            return PlanResult(True, trajectory=traj, info={"duration": 0.0})
        lim = self.limits(config)
        speed, accel, jerk = lim.vmax.tolist(), lim.amax.tolist(), lim.jmax.tolist()
        for j, (m, v, a) in enumerate(zip(moving, speed, accel, strict=True)):
            if m and not (v > MIN_LIMIT and a > MIN_LIMIT):
                return PlanResult(False, f"joint {j + 1} cannot move: max speed or acceleration is 0")
        inp = self._inp
        # joints that do not move stay where they are, with harmless nonzero limits (Ruckig needs > 0)
        target = [b if m else a for m, a, b in zip(moving, start, end, strict=True)]
        inp.current_position = start
        inp.current_velocity = [0.0] * N_JOINTS
        inp.current_acceleration = [0.0] * N_JOINTS
        inp.target_position = target
        inp.target_velocity = [0.0] * N_JOINTS
        inp.target_acceleration = [0.0] * N_JOINTS
        inp.max_velocity = [v if m else 1.0 for m, v in zip(moving, speed, strict=True)]
        inp.max_acceleration = [a if m else 1.0 for m, a in zip(moving, accel, strict=True)]
        inp.max_jerk = [x if m else 1.0 for m, x in zip(moving, jerk, strict=True)]
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
        bad = turn_limit_violation([[b.min for b in ext], [b.max for b in ext]], config.turn_min,
                                   config.turn_max, start=q0) if check else None
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

    def ptp_duration(self, q0: ArrayLike, q1: ArrayLike, config: Limits) -> float:
        """Duration (s) of the PTP move, no sampling, no target checks."""
        res = self.plan_ptp(q0, q1, config, check=False, sample=False)
        if not res.ok:
            raise ValueError(res.reason)
        return res.info["duration"]

    # ------------------------------------------------------------------ path parameter (LIN)
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
