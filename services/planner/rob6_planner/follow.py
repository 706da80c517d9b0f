"""Time-parameterised trajectories from outside (ROS 2's FollowJointTrajectory): checked and sampled.

A trajectory is points (time from start, positions, optional velocities and accelerations).
It starts where the arm is: a point at t = 0 must lie within the start tolerance of the
current position (and is replaced by it); a first point later than 0 is reached from the
current position at rest. Between two points each joint follows the quintic Hermite
polynomial through both positions, velocities and accelerations (cubic when the points
have no accelerations; velocities absent are estimated from the neighbouring points, zero
at both ends). The last point must be at rest. Every point and every sample is checked
against the turn limits and the configured speeds and accelerations before anything moves;
the refusal names the point or time, the joint and by how much.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rob6.errors import RefusedError

from .trajectory import SampledTrajectory

#: tolerances of the sampled trajectory against the limits (relative, and absolute for a
#: sampling grid that lands a hair over a limit the points respect)
RTOL = 1e-6
#: the last point counts as at rest below these (deg/s, deg/s^2)
REST_V, REST_A = 1e-3, 1e-2
MAX_DURATION_S = 3600.0


class FollowRefused(RefusedError):
    """The trajectory is not one rob6 follows (the message says why, for the goal's error string)."""


def _arr(rows: Sequence[Sequence[float]] | None, n: int, what: str) -> np.ndarray | None:
    if rows is None or len(rows) == 0:
        return None
    a = np.asarray(rows, float)
    if a.shape != (n, 6):
        raise FollowRefused(f"{what}: expected {n} points of 6 joints, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise FollowRefused(f"{what} contain values that are not finite")
    return a


def sample(t: Sequence[float], q: Sequence[Sequence[float]], qd: Sequence[Sequence[float]] | None,
           qdd: Sequence[Sequence[float]] | None, *, current: Sequence[float], dt: float,
           turn_min: Sequence[float], turn_max: Sequence[float], speed: Sequence[float],
           accel: Sequence[float], start_tolerance: float) -> SampledTrajectory:
    """The trajectory sampled every ``dt`` from ``current``; ``FollowRefused`` if it breaks a limit."""
    n = len(t)
    if n == 0:
        raise FollowRefused("the trajectory has no points")
    T = np.asarray(t, float)
    if not np.all(np.isfinite(T)) or T[0] < 0 or np.any(np.diff(T) <= 0):
        raise FollowRefused("the points' time_from_start must be >= 0 and strictly increasing")
    if T[-1] > MAX_DURATION_S:
        raise FollowRefused(f"the trajectory lasts {T[-1]:.0f} s, more than {MAX_DURATION_S:.0f} s")
    Q = _arr(q, n, "positions")
    if Q is None:
        raise FollowRefused("the points have no positions")
    V, A = _arr(qd, n, "velocities"), _arr(qdd, n, "accelerations")
    lo, hi = np.asarray(turn_min, float), np.asarray(turn_max, float)
    vmax, amax = np.asarray(speed, float), np.asarray(accel, float)
    for k in range(n):
        for j in range(6):
            if not lo[j] <= Q[k, j] <= hi[j]:
                raise FollowRefused(f"point {k}: joint {j + 1} at {Q[k, j]:.3f} deg is outside its turn limits "
                                    f"[{lo[j]:.3f}, {hi[j]:.3f}] deg")
    cur = np.asarray(current, float)
    if T[0] == 0.0:
        off = np.abs(Q[0] - cur)
        j = int(np.argmax(off))
        if off[j] > start_tolerance:
            raise FollowRefused(f"the trajectory starts {off[j]:.3f} deg away from where joint {j + 1} is "
                                f"({cur[j]:.3f} deg); the start tolerance is {start_tolerance:g} deg")
        Q[0] = cur
        if V is not None:
            V[0] = 0.0 if np.abs(V[0]).max() < REST_V else V[0]
    else:  # from where the arm is, at rest, to the first point
        T = np.concatenate([[0.0], T])
        Q = np.vstack([cur, Q])
        V = None if V is None else np.vstack([np.zeros(6), V])
        A = None if A is None else np.vstack([np.zeros(6), A])
    if V is None:
        V = np.zeros_like(Q)
        if len(T) > 2:
            V[1:-1] = (Q[2:] - Q[:-2]) / (T[2:] - T[:-2])[:, None]
    if np.abs(V[-1]).max() > REST_V or (A is not None and np.abs(A[-1]).max() > REST_A):
        raise FollowRefused("the last point is not at rest (its velocities and accelerations must be 0)")
    for k in range(len(T)):
        over = np.abs(V[k]) > vmax * (1 + RTOL)
        if over.any():
            j = int(np.argmax(over))
            raise FollowRefused(f"point at {T[k]:.3f} s: joint {j + 1} speed {abs(V[k, j]):.3f} deg/s exceeds its "
                                f"limit {vmax[j]:.3f} deg/s")
    count = int(np.ceil(T[-1] / dt - 1e-9)) + 1
    times = np.minimum(np.arange(count) * dt, T[-1])
    qs, vs, as_ = _hermite(T, Q, V, A, times)
    qs[0] = cur  # exactly where the arm is: the driver takes no other start
    qs[-1], vs[-1], as_[-1] = Q[-1], 0.0, 0.0
    _check_samples(times, qs, vs, as_, lo, hi, vmax, amax)
    return SampledTrajectory(dt=dt, t=times, q=qs, qd=vs, qdd=as_)


def _hermite(T: np.ndarray, Q: np.ndarray, V: np.ndarray, A: np.ndarray | None,
             times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities, accelerations at ``times`` of the piecewise Hermite polynomials."""
    seg = np.clip(np.searchsorted(T, times, side="right") - 1, 0, len(T) - 2)
    h = (T[seg + 1] - T[seg])[:, None]
    s = ((times - T[seg])[:, None] / h)
    p0, p1, v0, v1 = Q[seg], Q[seg + 1], V[seg] * h, V[seg + 1] * h
    if A is None:  # cubic
        c0, c1 = p0, v0
        c2 = 3 * (p1 - p0) - 2 * v0 - v1
        c3 = 2 * (p0 - p1) + v0 + v1
        q = c0 + s * (c1 + s * (c2 + s * c3))
        dq = c1 + s * (2 * c2 + s * 3 * c3)
        ddq = 2 * c2 + 6 * c3 * s
    else:  # quintic
        a0, a1 = A[seg] * h * h, A[seg + 1] * h * h
        c0, c1, c2 = p0, v0, a0 / 2
        c3 = 10 * (p1 - p0) - 6 * v0 - 4 * v1 - 1.5 * a0 + 0.5 * a1
        c4 = -15 * (p1 - p0) + 8 * v0 + 7 * v1 + 1.5 * a0 - a1
        c5 = 6 * (p1 - p0) - 3 * v0 - 3 * v1 - 0.5 * a0 + 0.5 * a1
        q = c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))))
        dq = c1 + s * (2 * c2 + s * (3 * c3 + s * (4 * c4 + s * 5 * c5)))
        ddq = 2 * c2 + s * (6 * c3 + s * (12 * c4 + s * 20 * c5))
    return q, dq / h, ddq / (h * h)


def _check_samples(times: np.ndarray, q: np.ndarray, v: np.ndarray, a: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> None:
    for what, bad in (("below its lower turn limit", q < lo - 1e-9), ("above its upper turn limit", q > hi + 1e-9)):
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise FollowRefused(f"at {times[k]:.3f} s joint {j + 1} would be at {q[k, j]:.3f} deg, {what} "
                                f"(between the points)")
    for kind, val, lim, unit in (("speed", v, vmax, "deg/s"), ("acceleration", a, amax, "deg/s^2")):
        over = np.abs(val) > lim * (1 + RTOL) + 1e-9
        if over.any():
            k, j = np.argwhere(over)[0]
            raise FollowRefused(f"at {times[k]:.3f} s joint {j + 1} {kind} {abs(val[k, j]):.3f} {unit} exceeds its "
                                f"limit {lim[j]:.3f} {unit}")
