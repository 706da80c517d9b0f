"""The limit monitor: every setpoint the driver commands is checked against the joint limits first.

Kept apart from the motion it bounds (as ros2_control keeps joint limits apart from its
controllers): this module knows nothing of trajectories, Alter or stops. ``MotionCore``
(``motion.py``) hands the monitor each next setpoint and applies only what it admits;
the planner plans within the same limits, the monitor is the defence in depth that
catches whatever would still break them.

What is checked, for one sample ``q_k`` as a controller's monitor sees it cycle by cycle
(``q_{k-1}``, ``v_{k-1}``: the setpoint and finite-difference velocity of the last cycle):

* turn limits strict, ``min < q < max`` (a joint already outside -- limits changed
  while it was there -- may only move back inwards, 1e-9 deg rounding tolerance);
* speed ``|q_k - q_{k-1}| / dt <= v_max``;
* acceleration ``|(q_k - 2 q_{k-1} + q_{k-2})| / dt^2 <= a_max``
  (relative tolerance 1e-6, absolute 1e-9 deg/s and 1e-6 deg/s^2 for rounding).

A sampled C2 motion that respects the limits everywhere always passes (the finite
differences are averages of the true velocity/acceleration). When a generated sample
fails anyway, the monitor also gives the last resorts: the admissible sample closest to
it (``clamp``) and the hardest admissible brake (``brake``).

The enforced limits (``LimitMonitor.enforced``) are the current ones, except while
limits change under a motion: new speed/acceleration limits are enforced as
``max(old, new)`` until the robot has settled within the new ones (``loosen``, then
``update`` every cycle); new turn limits that the current motion would cross are widened
just enough to contain the stop (``widen_turn``) and close again at rest.

Units: deg, deg/s, deg/s^2, deg/s^3 (``Limits.from_protocol`` converts the protocol's
deg per 12 ms cycle and deg per cycle^2 with ``rob6.units``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from rob6.robots import RobotModel
from rob6.units import JERK_RAMP_S, accel_si, jerk_si, speed_si

RTOL = 1e-6
ATOL_V = 1e-9
ATOL_A = 1e-6
#: a joint already outside its turn limits (limits changed) may not move further out
#: than this (deg; rounding at the end of a stop)
OUTSIDE_TOL = 1e-9
#: speed (deg/s) or acceleration (deg/s^2) limits below this freeze the joint
MIN_LIMIT = 1e-9
#: cycles the state must stay within new speed/acceleration limits before they are enforced
SETTLE_CYCLES = 3


@dataclass
class Limits:
    """Limits in deg, deg/s, deg/s^2, deg/s^3."""

    turn_min: np.ndarray
    turn_max: np.ndarray
    vmax: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray
    max_change: np.ndarray  # deg: an Alter target's largest distance from where the robot is

    @classmethod
    def from_protocol(cls, turn_min: npt.ArrayLike, turn_max: npt.ArrayLike, max_speed: Sequence[float],
                      max_accel: Sequence[float], max_change: npt.ArrayLike,
                      jerk_ramp_s: float = JERK_RAMP_S) -> Limits:
        a = accel_si(max_accel)
        return cls(np.asarray(turn_min, float).copy(), np.asarray(turn_max, float).copy(),
                   np.array(speed_si(max_speed)), np.array(a), np.array(jerk_si(a, jerk_ramp_s)),
                   np.asarray(max_change, float).copy())

    @classmethod
    def defaults(cls, robot: RobotModel) -> Limits:
        return cls.from_protocol(robot.turn_min, robot.turn_max, robot.default_speed,
                                 robot.default_accel, robot.default_max_change)

    def copy(self) -> Limits:
        return Limits(self.turn_min.copy(), self.turn_max.copy(), self.vmax.copy(),
                      self.amax.copy(), self.jmax.copy(), self.max_change.copy())


class Breach(NamedTuple):
    """A sample the monitor refuses: which limit, on which joint (0-based), by what value."""

    kind: str  # turn | speed | acceleration
    joint: int
    value: float
    limit: float


class LimitMonitor:
    """Checks each next setpoint against the limits it enforces (``enforced``).

    Not thread-safe on its own: the motion core calls it under its lock.
    """

    def __init__(self, limits: Limits, dt: float) -> None:
        self.dt = float(dt)
        self.enforced = limits.copy()
        # 0: speed/acceleration enforced as set; -1: wider, waiting for the state to get
        # within the new ones; n > 0: within for n cycles
        self._settle = 0

    # ------------------------------------------------------------------ one sample
    def check(self, qn: np.ndarray, q: np.ndarray, v_prev: np.ndarray) -> Breach | None:
        """None if ``qn`` may follow ``q`` (reached with velocity ``v_prev``), else why not.

        In plain floats, the same arithmetic as numpy's element by element: it runs every
        cycle, where numpy's calls on six values cost more than the check itself
        (docs/PERFORMANCE.md, "Python run cold")."""
        mon = self.enforced
        new, last = qn.tolist(), q.tolist()
        if not all(lo < x < hi for lo, x, hi in zip(mon.turn_min.tolist(), new, mon.turn_max.tolist(), strict=True)):
            bad = turn_bad(qn[None], mon.turn_min, mon.turn_max, q)  # the start rule, in numpy
            if bad is not None:
                j = bad[1]
                lim = mon.turn_max[j] if qn[j] >= mon.turn_max[j] else mon.turn_min[j]
                return Breach("turn", j, qn[j], lim)
        dt = self.dt
        v = [(x - x0) / dt for x, x0 in zip(new, last, strict=True)]
        vmax = mon.vmax.tolist()
        over = [abs(x) - (m * (1 + RTOL) + ATOL_V) for x, m in zip(v, vmax, strict=True)]
        if any(o > 0 for o in over):
            j = int(np.argmax(over))
            return Breach("speed", j, v[j], vmax[j])
        a = [(x - x0) / dt for x, x0 in zip(v, v_prev.tolist(), strict=True)]
        amax = mon.amax.tolist()
        over = [abs(x) - (m * (1 + RTOL) + ATOL_A) for x, m in zip(a, amax, strict=True)]
        if any(o > 0 for o in over):
            j = int(np.argmax(over))
            return Breach("acceleration", j, a[j], amax[j])
        return None

    def outside_turn(self, qn: np.ndarray, q: np.ndarray) -> int | None:
        """The first joint (0-based) of ``qn`` breaking the turn limits from ``q``, or None."""
        bad = turn_bad(qn[None], self.enforced.turn_min, self.enforced.turn_max, q)
        return None if bad is None else bad[1]

    def check_trajectory(self, samples: np.ndarray, q: np.ndarray, v_prev: np.ndarray,
                         dynamics: bool = True) -> str:
        """Why a whole sampled trajectory (row 0 = ``q``) would be stopped, or "".

        The robot holds the last sample afterwards, so the deceleration into it counts.
        ``dynamics=False`` checks the turn limits only (a dummy robot jumps).
        """
        mon = self.enforced
        bad = turn_bad(samples[1:] if len(samples) > 1 else samples, mon.turn_min, mon.turn_max, q)
        if bad is not None:
            k, j = bad
            value = samples[k + 1 if len(samples) > 1 else 0, j]
            return f"joint {j + 1} sample {k + 1} at {value:.6f} breaks its turn limits"
        if not dynamics or len(samples) < 2:
            return ""
        held = np.vstack([samples, samples[-1:]])
        v = np.diff(held, axis=0) / self.dt
        a = np.diff(np.vstack([v_prev[None], v]), axis=0) / self.dt
        for kind, val, lim, atol in (("speed", v, mon.vmax, ATOL_V), ("acceleration", a, mon.amax, ATOL_A)):
            over = np.abs(val) > lim * (1 + RTOL) + atol
            if over.any():
                k, j = np.argwhere(over)[0]
                return f"joint {j + 1} {kind} {abs(val[k, j]):.6g} > {lim[j]:.6g} at sample {k + 1}"
        return ""

    # ------------------------------------------------------------------ last resorts
    def admissible_velocity(self, v_prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-joint velocity interval the monitor admits for the next cycle."""
        mon = self.enforced
        vmax = mon.vmax * (1 - 1e-9)
        dv = mon.amax * (1 - 1e-9) * self.dt
        v_lo = np.maximum(-vmax, v_prev - dv)
        v_hi = np.minimum(vmax, v_prev + dv)
        return v_lo, np.maximum(v_hi, v_lo)

    def clamp(self, qn: np.ndarray, q: np.ndarray, v_prev: np.ndarray) -> np.ndarray:
        """The admissible sample closest to ``qn``; braking as hard as allowed if even that
        would leave the turn limits."""
        v_lo, v_hi = self.admissible_velocity(v_prev)
        v = np.clip((qn - q) / self.dt, v_lo, v_hi)
        q_new = q + v * self.dt
        if self.outside_turn(q_new, q) is not None:
            v = np.clip(np.zeros_like(q), v_lo, v_hi)
            q_new = q + v * self.dt
        out: np.ndarray = q_new
        return out

    def brake(self, q: np.ndarray, v_prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One cycle of the hardest admissible brake: (next setpoint, its velocity)."""
        v_lo, v_hi = self.admissible_velocity(v_prev)
        v = np.clip(np.zeros_like(q), v_lo, v_hi)
        return q + v * self.dt, v

    # ------------------------------------------------------------------ limit changes
    def reset(self, limits: Limits) -> None:
        """At rest: enforce ``limits`` as they are, at once."""
        self.enforced = limits.copy()
        self._settle = 0

    def loosen(self, new: Limits) -> None:
        """New speed/acceleration limits under a motion: enforce the wider of old and new
        until ``update`` sees the state settled within the new ones."""
        mon = self.enforced
        mon.vmax = np.maximum(mon.vmax, new.vmax)
        mon.amax = np.maximum(mon.amax, new.amax)
        mon.jmax = np.maximum(mon.jmax, new.jmax)
        self._settle = -1

    def take_turn(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Enforce new turn limits at once (the current motion stays inside them)."""
        self.enforced.turn_min, self.enforced.turn_max = lo.copy(), hi.copy()

    def widen_turn(self, lo: np.ndarray, hi: np.ndarray, fmin: np.ndarray, fmax: np.ndarray,
                   start: np.ndarray) -> int:
        """New turn limits ``lo``/``hi`` that a stop spanning ``fmin``..``fmax`` from ``start``
        crosses: enforce them widened just enough to contain it; returns the first
        crossing joint (1-based)."""
        eps = 1e-6
        ok_lo, ok_hi = within_lo(fmin, lo, start), within_hi(fmax, hi, start)
        self.enforced.turn_min = np.where(ok_lo, lo, np.minimum(lo, fmin - eps))
        self.enforced.turn_max = np.where(ok_hi, hi, np.maximum(hi, fmax + eps))
        return int(np.argmax(~(ok_lo & ok_hi))) + 1

    def update(self, current: Limits, moving: bool, on_current_plan: bool,
               v_prev: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> None:
        """Once a cycle: close transitional limits once the robot is within ``current``.

        At rest (``moving`` False) everything closes. In motion speed/acceleration close
        ``SETTLE_CYCLES`` cycles after the state (``v_prev``, ``qd``, ``qdd``) got within
        the new limits while following a plan made with them (``on_current_plan``);
        widened turn bounds close at rest only.
        """
        mon = self.enforced
        if self._settle == 0 and mon.turn_min.tolist() == current.turn_min.tolist() \
                and mon.turn_max.tolist() == current.turn_max.tolist():  # lists: cheaper every cycle
            return
        if not moving:
            self.reset(current)
            return
        if self._settle == 0:
            return  # only the turn bounds are widened: they close at rest
        within = bool(on_current_plan
                      and np.all(np.abs(v_prev) <= current.vmax * (1 + RTOL) + ATOL_V)
                      and np.all(np.abs(qd) <= current.vmax * (1 + RTOL) + ATOL_V)
                      and np.all(np.abs(qdd) <= current.amax * (1 + RTOL) + ATOL_A))
        if within:
            # a joint frozen by a zero limit must be exactly at rest before the monitor
            # takes the zero limit
            frozen = ~((current.vmax > MIN_LIMIT) & (current.amax > MIN_LIMIT))
            still = (v_prev == 0) & (qd == 0) & (qdd == 0)
            within = bool(np.all(~frozen | still))
        self._settle = self._settle + 1 if (within and self._settle > 0) else (1 if within else -1)
        if self._settle >= SETTLE_CYCLES:
            mon.vmax = current.vmax.copy()
            mon.amax = current.amax.copy()
            mon.jmax = current.jmax.copy()
            self._settle = 0


# ====================================================================== turn-limit geometry
def turn_bad(q: np.ndarray, lo: np.ndarray, hi: np.ndarray, start: np.ndarray) -> tuple[int, int] | None:
    """First (row, joint) of q breaking the strict turn limits (start rule), or None."""
    if ((q > lo) & (q < hi)).all():  # strictly inside passes whatever the start (the common case, cheap)
        return None
    lo_ok = np.where(start <= lo, q >= start - OUTSIDE_TOL, q > lo)
    hi_ok = np.where(start >= hi, q <= start + OUTSIDE_TOL, q < hi)
    ok = lo_ok & hi_ok
    if ok.all():
        return None
    k, j = np.argwhere(~ok)[0]
    return int(k), int(j)


def within_lo(qmin: np.ndarray, lo: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Per joint: does a motion from ``start`` reaching down to ``qmin`` respect ``lo``?"""
    ok: np.ndarray = np.where(start <= lo, qmin >= start - OUTSIDE_TOL, qmin > lo)
    return ok


def within_hi(qmax: np.ndarray, hi: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Per joint: does a motion from ``start`` reaching up to ``qmax`` respect ``hi``?"""
    ok: np.ndarray = np.where(start >= hi, qmax <= start + OUTSIDE_TOL, qmax < hi)
    return ok


def within(qmin: npt.ArrayLike, qmax: npt.ArrayLike, lo: np.ndarray, hi: np.ndarray, start: np.ndarray) -> bool:
    """Does a motion from ``start`` spanning ``qmin``..``qmax`` stay inside the turn limits?"""
    low, high = np.asarray(qmin, float), np.asarray(qmax, float)
    # strictly inside passes whatever the start; in plain floats, as it is asked every cycle
    # of an Alter stream (docs/PERFORMANCE.md, "Python run cold")
    if all(a > b and c < d for a, b, c, d in zip(low.tolist(), lo.tolist(), high.tolist(), hi.tolist(), strict=True)):
        return True
    return bool(np.all(within_lo(low, lo, start) & within_hi(high, hi, start)))
