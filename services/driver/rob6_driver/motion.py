"""The driver's motion core: trajectories, Alter, stops and brakes, every setpoint through the limit monitor.

The motion core of the driver, independent of the robot it drives: state at the
controller cycle, trajectory execution, Alter (real-time target) mode with Ruckig
online generation, watchdog and stops; every setpoint passes the independent limit
monitor of ``limits.py`` (defence in depth) before it is applied.

A *link* (``links/``) owns the clock: it calls ``step()`` once per controller cycle
and hands the new setpoint to the plant (the simulation takes it as reached; RSI sends
it to a KUKA controller). When the plant cannot be reached the link calls
``offline(reason)``: any motion ends (``ok`` False, ``error`` = the reason) and motion
commands are refused with ``Offline`` until ``online(q_actual)`` resumes from where the
robot really is, at rest.

Units: degrees, seconds (``qd`` deg/s, ``qdd`` deg/s^2). Limits are given in the
protocol's units (deg per 12 ms cycle, deg per cycle^2) and converted by ``rob6.units``,
as the planner's are: ``v = speed / 0.012``, ``a = accel / 0.012**2``, ``j = a / 0.048``.

Nothing here sleeps: ``step()`` advances exactly one controller cycle. The links call
it in real time; tests call it in fast-forward.

Limit monitor
-------------
Every commanded sample (from a trajectory or from the internal generator) goes through
``_command``, which asks the ``LimitMonitor`` (``limits.py``: the checks, their
tolerances and the transitions when limits change) *before* it is applied, as a
controller's monitor sees it cycle by cycle. A sample that fails is not applied: the
violation is reported (``violations``, ``on_event``) and the robot makes a controlled,
jerk-limited stop from its last good state. Samples the core generates itself (Alter,
stops) are planned from the exact state and checked too; if one ever failed it would be
clamped to the largest admissible step the monitor gives instead (and reported), so the
state itself never breaks the speed/acceleration limits.

Generated motion (Ruckig, online): a new Alter target or a stop is planned from the
exact current state (position, velocity, acceleration; from a trajectory without
``qd``/``qdd`` a finite-difference estimate made consistent with the limits) and is
adopted only if its whole future stays strictly inside the turn limits (exact
extrema of the jerk segments); otherwise the robot keeps its current, already
checked motion and retries next cycle. A stop that cannot stay inside (limits changed
under the motion) becomes an acceleration-limited emergency brake (shortest stopping
distance). Alter targets use target velocity 0: the robot never runs past the last
target it received.

Safety zones: with a cell (``zones.ZoneGuard``), each next setpoint of a trajectory or
of Alter is also asked whether a stop from it would keep the arm out of every zone; if
not, it is not applied and the robot stops from its last setpoint (``ok`` False, the
reason a ``ZoneReason`` the client is told). An Alter target whose pose is in a zone is
refused, and the first target after such a stop is refused with that stop's reason, so
a client streaming targets learns why the arm stopped.

Limit changes while moving: new speed/acceleration limits drive the generator at
once; the monitor keeps ``max(old, new)`` until the robot has settled within the new
ones (a running trajectory keeps its old limits until it ends). New turn limits that
the current motion would cross cause a controlled stop; the monitor's turn bounds are
widened just enough to contain that stop (reported), and close again at rest.

Time scaling (the feed)
-----------------------
A link whose arm runs at its own pace (the Adept's V+ program moves every point at the
controller's monitor speed) slows the core so that its setpoints and the arm stay
together: ``set_feed(f)``, 0 <= f <= 1, the plan's seconds per controller second. A
trajectory then advances ``f`` samples per cycle along the same path (positions
interpolated between its samples, so a LIN move stays on the line the monitor checked),
and the feed changes only as fast as the acceleration limits leave room for: the
acceleration a change of pace adds to the path's own stays within them. Alter plans its
generated motion with its speed limits times the feed, and its watchdog counts the plan's
time (a target missing for ``alter_timeout_s`` of it stops the motion). A stop is never
slowed: it brakes from the speed the arm is commanded at. ``held_back_s`` says how much
longer the current trajectory takes than planned (the driver extends its deadline by it).
"""

from __future__ import annotations

import functools
import logging
import math
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import ruckig

from rob6.cell.brake import LineBrake, line_brake
from rob6.deadlines import stop_s
from rob6.errors import RefusedError
from rob6.robots import RobotModel, get_robot
from rob6.units import accel_si, jerk_si, speed_si

from .limits import MIN_LIMIT, Breach, LimitMonitor, Limits, within
from .zones import ZoneGuard, ZoneReason, straight

log = logging.getLogger(__name__)

N_JOINTS = 6
#: how close the current state must be to a trajectory's first sample (deg)
START_TOL_DEG = 1e-6
REST_EPS = 1e-9
#: a change of the feed may add acceleration up to this share of the limit, less the path's own
FEED_ACCEL_SHARE = 0.95
#: a change of the feed that does not fit is halved this often before the feed stays
FEED_HALVINGS = 12
#: Alter plans with its speed limits times the feed, never less than this share of them
ALTER_FEED_MIN = 0.02
#: Alter replans the motion under way when the feed has changed this much since its plan
ALTER_FEED_STEP = 0.05
#: the cell's violations are reported at most once in this long (controller seconds)
ZONE_EVENT_PERIOD_S = 1.0


# ====================================================================== data
@dataclass
class CoreState:
    """One controller cycle. ``t`` = cycle * dt (the controller's clock, seconds)."""

    t: float
    cycle: int
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    mode: str  # idle | trajectory | alter | stopping
    moving: bool


@dataclass
class Violation:
    t: float
    cycle: int
    kind: str  # turn | speed | acceleration | limits_changed | unavoidable | zone
    joint: int  # 1..6 (0: not joint specific)
    value: float
    limit: float
    source: str  # trajectory | alter | stop | limits
    message: str


class Motion:
    """Handle of a trajectory (or stop): completion is awaitable.

    ``done`` is a threading.Event set when the robot has arrived (``ok`` True) or has
    come to rest after a stop/violation (``ok`` False, ``reason``); ``error`` is set
    (to the reason) when the plant failed, not the command (link lost). Callbacks added
    with ``add_done_callback(fn)`` run once with the motion, on the cycle thread (use
    ``loop.call_soon_threadsafe`` to hand over to asyncio).
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.done = threading.Event()
        self.ok: bool | None = None
        self.reason = ""
        self.error = ""
        self.started = False  # it ran (a refused one never does)
        self.final: CoreState | None = None
        self._callbacks: list[Callable[[Motion], None]] = []
        self._lock = threading.Lock()

    def wait(self, timeout: float | None = None) -> bool:
        return self.done.wait(timeout)

    def add_done_callback(self, fn: Callable[[Motion], None]) -> None:
        with self._lock:
            if not self.done.is_set():
                self._callbacks.append(fn)
                return
        fn(self)

    def _finish(self, ok: bool, reason: str, state: CoreState | None,
                error: str = "") -> list[Callable[[], None]]:
        """Mark finished; returns the callbacks to run (outside the core's lock)."""
        with self._lock:
            if self.done.is_set():
                return []
            self.ok, self.reason, self.final, self.error = ok, reason, state, error
            self.done.set()
            callbacks, self._callbacks = self._callbacks, []
        return [functools.partial(fn, self) for fn in callbacks]

    def __repr__(self) -> str:
        return f"Motion({self.kind}, done={self.done.is_set()}, ok={self.ok}, reason={self.reason!r})"


class Offline(RefusedError):
    """A motion command while the plant cannot be reached (the message says why)."""


# ====================================================================== the core
class MotionCore:
    """The robot's motion. Thread-safe: commands from any thread, ``step()`` from one."""

    def __init__(self, robot: RobotModel | str, dt: float | None = None, *, dummy: bool = False,
                 q0: npt.ArrayLike | None = None, limits: Limits | None = None,
                 alter_timeout_s: float = 0.5, offline: str = "",
                 on_event: Callable[[dict[str, Any]], None] | None = None, max_violations: int = 1000,
                 zones: ZoneGuard | None = None) -> None:
        self.robot = get_robot(robot) if isinstance(robot, str) else robot
        self._offline = offline  # why the plant cannot be reached ("": it can)
        self.dt = float(dt if dt is not None else self.robot.cycle_s)
        self.dummy = dummy
        self.alter_timeout_s = float(alter_timeout_s)
        self.on_event = on_event
        self.violations: deque[Violation] = deque(maxlen=max_violations)
        self.violation_count = 0
        self._lock = threading.RLock()
        self._lim = (limits or Limits.defaults(self.robot)).copy()
        self._plant: tuple[np.ndarray, np.ndarray] | None = None  # the plant's own range (``restrict``)
        # every setpoint passes it; its limits may be wider than _lim during a transition
        self._monitor = LimitMonitor(self._lim, self.dt)
        self._cycle = 0
        self._q = np.zeros(N_JOINTS) if q0 is None else np.asarray(q0, float).copy()
        self._qd = np.zeros(N_JOINTS)
        self._qdd = np.zeros(N_JOINTS)
        self._v_fd = np.zeros(N_JOINTS)  # finite-difference velocity of the last cycle
        self._mode = "idle"
        # trajectory mode
        self._samples: np.ndarray | None = None
        self._samples_qd: np.ndarray | None = None
        self._samples_qdd: np.ndarray | None = None
        self._pos = 0.0  # where along the samples the setpoint is (a sample index, fractional when slowed)
        self._motion: Motion | None = None
        # time scaling: plan seconds per controller second, now and as the link asks
        self._feed = 1.0
        self._feed_target = 1.0
        self._held_back = 0.0  # controller seconds the running trajectory has lost to the feed
        self._alter_feed = 1.0  # the feed the current Alter plan was made with
        self._plan_t = 0.0  # the plan's clock: controller seconds times the feed (the Alter watchdog's)
        # internal generator (Alter, stops)
        self._otg = ruckig.Ruckig(N_JOINTS, self.dt)
        self._inp = ruckig.InputParameter(N_JOINTS)
        self._gen: ruckig.Trajectory | LineBrake | None = None
        self._gen_t = 0.0
        self._gen_kind = ""  # alter | stop
        self._resync = False
        self._ebrake = False
        self._lim_version = 0
        self._gen_version = 0
        # alter mode
        self._alter = False
        self._target: np.ndarray | None = None
        self._target_pending = False
        self._sync = False
        self._last_heard = 0.0
        self._watchdog_fired = False
        self._stop_motion: Motion | None = None
        self._deferred: list[Callable[[], None]] = []
        self._zones = zones if zones is not None and not zones.empty else None
        self._zone_stop: ZoneReason | None = None  # why the cell stopped Alter: told with the next target
        self._zone_blocked: tuple[np.ndarray, ZoneReason] | None = None  # an Alter target refused, and why
        self._zone_events_at = -math.inf  # when the last zone violation was reported (they are rate-limited)
        self._zone_events_quiet = 0  # zone violations not reported since
        self._along: np.ndarray | None = None  # the end of the straight trajectory being followed

    # ------------------------------------------------------------------ queries
    @property
    def t(self) -> float:
        return self._cycle * self.dt

    @property
    def cycle(self) -> int:
        return self._cycle

    def state(self) -> CoreState:
        with self._lock:
            return self._state()

    def _state(self, moving: bool | None = None) -> CoreState:
        return CoreState(self.t, self._cycle, self._q.copy(), self._qd.copy(), self._qdd.copy(),
                        self._mode, self._moving() if moving is None else moving)

    def _moving(self) -> bool:
        return self._mode in ("trajectory", "stopping") or self._gen is not None or self._ebrake or \
            bool((np.abs(self._v_fd) > REST_EPS).any())

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def alter_enabled(self) -> bool:
        return self._alter

    def limits(self) -> Limits:
        with self._lock:
            return self._lim.copy()

    def enforced_limits(self) -> Limits:
        """The limits the monitor checks right now (wider than ``limits()`` only in a transition)."""
        with self._lock:
            return self._monitor.enforced.copy()

    def stop_bound_s(self) -> float:
        """The longest a controlled stop can take now (controller seconds): a stop may use
        what the monitor allows, and the robot moves within it."""
        with self._lock:
            lim = self._monitor.enforced
            return stop_s(lim.vmax, lim.amax, lim.jmax)

    def stopping(self) -> Motion | None:
        """The stop in progress (completes at rest), or None."""
        with self._lock:
            return self._stop_motion

    @property
    def feed(self) -> float:
        """The pace the plan runs at now, plan seconds per controller second: a trajectory's
        feed, the share of its speed limits Alter plans with; 1 for anything else."""
        if self._mode == "trajectory":
            return self._feed
        if self._mode == "alter" and self._gen is not None:
            return self._alter_feed
        return 1.0

    def speed_share(self) -> float:
        """How fast the setpoint moved in the last cycle, as a share of the speed limits
        (the largest joint's)."""
        with self._lock:
            return float(np.max(np.abs(self._v_fd) / np.maximum(self._monitor.enforced.vmax, MIN_LIMIT)))

    @property
    def held_back_s(self) -> float:
        """Controller seconds the running (or last) trajectory has taken beyond its plan."""
        return self._held_back

    def set_feed(self, target: float) -> None:
        """Run the plan at ``target`` (0..1, clipped) of its pace from now on: a trajectory
        gets there as fast as the acceleration limits allow, Alter at its next plan."""
        self._feed_target = min(1.0, max(0.0, float(target)))

    # ------------------------------------------------------------------ events
    def _event(self, **event: Any) -> None:
        if self.on_event is not None:
            event.setdefault("t", self.t)
            event.setdefault("cycle", self._cycle)
            cb = self.on_event
            self._deferred.append(lambda: cb(event))

    def _violation(self, kind: str, joint: int, value: float, limit: float, source: str, message: str) -> None:
        v = Violation(self.t, self._cycle, kind, joint, float(value), float(limit), source, message)
        self.violations.append(v)
        self.violation_count += 1
        if kind == "zone":  # a stream aimed at a zone stops again and again: one event a second
            if self.t - self._zone_events_at < ZONE_EVENT_PERIOD_S:
                self._zone_events_quiet += 1
                return
            if self._zone_events_quiet:
                message += f" ({self._zone_events_quiet} more since the last report)"
            self._zone_events_at, self._zone_events_quiet = self.t, 0
        self._event(type="violation", kind=kind, joint=joint, value=float(value),
                    limit=float(limit), source=source, message=message)

    def _run_deferred(self) -> None:
        with self._lock:
            todo, self._deferred = self._deferred, []
        for fn in todo:
            try:
                fn()
            except Exception:  # a callback must never stop the controller
                log.exception("motion core callback failed")

    # ------------------------------------------------------------------ the plant
    @property
    def offline_reason(self) -> str:
        """Why the plant cannot be reached right now ("" when it can)."""
        return self._offline

    def offline(self, reason: str) -> None:
        """The plant cannot be reached: every motion ends at once (``ok`` False, ``error`` =
        ``reason``) and motion commands are refused until ``online``. No cycle runs
        meanwhile (the link owns the clock); the last setpoint stays."""
        with self._lock:
            self._offline = reason
            self._abort(reason)
        self._run_deferred()

    def online(self, q_actual: npt.ArrayLike, reason: str = "resynchronized with the robot") -> None:
        """The plant answers again: continue from ``q_actual`` (deg), at rest, never from
        where an interrupted motion would have been. A motion still running (the plant
        restarted under it) ends with ``reason``. Alter mode stays on, holding here."""
        q = _six(q_actual)
        with self._lock:
            self._abort(self._offline or reason)
            self._q = q.copy()
            self._target = q.copy()
            self._offline = ""
            self._zone_blocked = None
        if self._zones is not None and (where := self._zones.observe(q)):
            log.warning("cell: the robot is back at a pose where %s", where)
            self._event(type="zone_way_out", message=where)
        self._run_deferred()

    def _abort(self, reason: str) -> None:
        """End every motion now (lock held) and hold still: no brake ramp, the plant has
        already stopped (or is unreachable)."""
        self._samples = self._samples_qd = self._samples_qdd = None
        self._gen, self._ebrake, self._resync, self._target_pending = None, False, False, False
        self._qd[:] = 0.0
        self._qdd[:] = 0.0
        self._v_fd[:] = 0.0
        self._target = self._q.copy()
        self._mode = "alter" if self._alter else "idle"
        self._monitor.reset(self._lim)  # at rest: the monitor takes the current limits
        state = self._state()
        for motion in (self._motion, self._stop_motion):
            if motion is not None:
                self._deferred += motion._finish(False, reason, state, error=reason)
        self._motion = self._stop_motion = None

    # ------------------------------------------------------------------ limits
    def set_limits(self, turn_min: npt.ArrayLike | None = None, turn_max: npt.ArrayLike | None = None,
                   max_speed: Sequence[float] | None = None, max_accel: Sequence[float] | None = None,
                   max_change: npt.ArrayLike | None = None) -> tuple[bool, str]:
        """New limits (protocol units; None = unchanged). See the module doc for changes in motion."""
        with self._lock:
            new = self._lim.copy()
            try:
                if turn_min is not None:
                    new.turn_min = _six(turn_min)
                if turn_max is not None:
                    new.turn_max = _six(turn_max)
                if max_speed is not None:
                    new.vmax = np.array(speed_si(_six(max_speed)))
                if max_accel is not None:
                    a = accel_si(_six(max_accel))
                    new.amax, new.jmax = np.array(a), np.array(jerk_si(a))
                if max_change is not None:
                    new.max_change = _six(max_change)
            except ValueError as exc:
                return False, str(exc)
            if np.any(new.vmax < 0) or np.any(new.amax < 0):
                return False, "negative speed or acceleration limit"
            self._apply_limits(self._within_plant(new))
        self._run_deferred()
        return True, ""

    def restrict(self, lo: npt.ArrayLike, hi: npt.ArrayLike) -> None:
        """The plant's own joint range (deg): the turn limits never reach beyond it, whatever
        limits are set later, so a motion leaving it is refused before it starts."""
        with self._lock:
            self._plant = (_six(lo), _six(hi))
            self._apply_limits(self._within_plant(self._lim.copy()))
        self._run_deferred()

    def _within_plant(self, new: Limits) -> Limits:
        if self._plant is not None:
            new.turn_min = np.maximum(new.turn_min, self._plant[0])
            new.turn_max = np.minimum(new.turn_max, self._plant[1])
        return new

    def _apply_limits(self, new: Limits) -> None:
        self._lim = new
        self._lim_version += 1
        if not self._moving():
            self._monitor.reset(new)
            return
        self._monitor.loosen(new)  # wider until the robot is within the new limits
        self._on_turn_change_in_motion(new)
        if self._gen is not None and self._gen_kind == "alter":
            self._target_pending = True  # replan with the new limits
        elif self._mode == "stopping":
            self._resync = True  # re-plan the stop with the new limits

    def _on_turn_change_in_motion(self, new: Limits) -> None:
        lo, hi = new.turn_min, new.turn_max
        future = self._future_extrema()
        if future is None or within(future[0], future[1], lo, hi, self._q):
            self._monitor.take_turn(lo, hi)
            return
        # the current motion would cross the new limits: stop, widened just enough
        self._begin_stop("turn limits changed while moving", force=True)
        fmin, fmax = self._future_extrema() or (self._q, self._q)
        joint = self._monitor.widen_turn(lo, hi, fmin, fmax, self._q)
        self._violation("limits_changed", joint, float(self._q[joint - 1]),
                        float(hi[joint - 1]), "limits",
                        "turn limits changed under a motion that crosses them: stopping; "
                        "monitor bounds widened to contain the stop")

    def _future_extrema(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(min, max) per joint of the rest of the current motion, or None at rest."""
        if self._mode == "trajectory" and self._samples is not None:
            rest = self._samples[int(self._pos) + 1:]
            if len(rest) == 0:
                return None
            rest = np.vstack([self._q, rest])
            return rest.min(axis=0), rest.max(axis=0)
        if isinstance(self._gen, LineBrake):
            lo, hi = self._gen.extrema()
            return np.minimum(self._q, lo), np.maximum(self._q, hi)
        if self._gen is not None:
            lo, hi = trajectory_extrema(self._gen, self._gen_t)
            return np.minimum(self._q, lo), np.maximum(self._q, hi)
        if self._ebrake:
            v = self._v_fd
            amax = np.maximum(self._monitor.enforced.amax, MIN_LIMIT)
            reach = v * v / (2 * amax) + np.abs(v) * self.dt
            end = self._q + np.sign(v) * reach
            return np.minimum(self._q, end), np.maximum(self._q, end)
        return None

    # ------------------------------------------------------------------ trajectory mode
    def execute(self, q: npt.ArrayLike, dt: float | None = None, qd: npt.ArrayLike | None = None,
                qdd: npt.ArrayLike | None = None, *, check: bool = True) -> Motion:
        """Run a sampled trajectory (rows = cycles, row 0 = the current position).

        Returns a Motion at once; it completes when the last sample is reached, or with
        ``ok=False`` if refused (reason) or stopped. ``qd``/``qdd`` (deg/s, deg/s^2) are
        optional: with them a stop starts from the exact state, without them from
        finite-difference estimates. The whole trajectory is checked against the
        monitor's limits before the first cycle (and again sample by sample).
        In dummy mode the robot jumps to the last sample at once. ``check=False`` skips
        the up-front limit check (the per-cycle monitor still applies; for tests of the
        monitor and for streamed trajectories).
        """
        motion = Motion("trajectory")
        # the cell's check of every pose runs before the core's lock is taken: the cycle goes
        # on meanwhile (a long path's check takes milliseconds, an RSI cycle is 4)
        zone = self._zone_trajectory(q) if check else None
        with self._lock:
            reason = self._check_execute(q, dt, qd, qdd, check) or (zone or "")
            if self._offline:
                self._deferred += motion._finish(False, self._offline, self._state(), error=self._offline)
            elif reason:
                self._deferred += motion._finish(False, reason, self._state())
            elif self.dummy:
                self._q = np.asarray(q, float)[-1].copy()
                self._qd[:] = 0.0
                self._qdd[:] = 0.0
                self._v_fd[:] = 0.0
                self._deferred += motion._finish(True, "", self._state())
            else:
                arr = np.asarray(q, float)
                self._samples = arr
                # a brake on a straight trajectory stays on its poses, which the cell checked
                self._along = arr[-1] if check and self._zones is not None and straight(arr) else None
                self._samples_qd = None if qd is None else np.asarray(qd, float)
                self._samples_qdd = None if qdd is None else np.asarray(qdd, float)
                self._pos = 0.0
                self._held_back = 0.0
                self._motion = motion
                motion.started = True
                self._mode = "trajectory"
                if len(arr) <= 1:
                    self._finish_trajectory(True, "")
        self._run_deferred()
        return motion

    def _zone_trajectory(self, q: npt.ArrayLike) -> ZoneReason | None:
        """The cell's word on a trajectory's poses (``ZoneGuard.trajectory``), when it is one."""
        if self._zones is None:
            return None
        try:
            arr = np.asarray(q, float)
        except (TypeError, ValueError):
            return None  # _check_execute says why
        if arr.ndim != 2 or arr.shape[1] != N_JOINTS or len(arr) == 0 or not np.all(np.isfinite(arr)):
            return None
        return self._zones.trajectory(arr, self.dt)

    def _check_execute(self, q: npt.ArrayLike, dt: float | None, qd: npt.ArrayLike | None,
                       qdd: npt.ArrayLike | None, check: bool = True) -> str:
        if self._mode != "idle" or self._alter or self._gen is not None:
            return f"robot busy ({'alter mode' if self._alter else self._mode})"
        if dt is not None and abs(float(dt) - self.dt) > 1e-12:
            return f"trajectory sample time {dt} differs from the controller cycle {self.dt}"
        try:
            arr = np.asarray(q, float)
        except (TypeError, ValueError):
            return "malformed trajectory"
        if arr.ndim != 2 or arr.shape[1] != N_JOINTS or len(arr) == 0:
            return "malformed trajectory (expected N x 6 positions)"
        if not np.all(np.isfinite(arr)):
            return "trajectory contains non-finite values"
        for extra, name in ((qd, "qd"), (qdd, "qdd")):
            if extra is not None and np.shape(extra) != arr.shape:
                return f"{name} does not match the positions"
        if np.abs(arr[0] - self._q).max() > START_TOL_DEG:
            return "trajectory does not start at the current position"
        if not check:
            return ""
        return self._monitor.check_trajectory(arr, self._q, self._v_fd, dynamics=not self.dummy)

    def _finish_trajectory(self, ok: bool, reason: str) -> None:
        motion, self._motion = self._motion, None
        self._samples = self._samples_qd = self._samples_qdd = None
        self._mode = "alter" if self._alter else "idle"
        if motion is not None:
            self._deferred += motion._finish(ok, reason, self._state())

    # ------------------------------------------------------------------ alter mode
    def enable_alter(self, synchronized: bool | None = None, timeout_s: float | None = None) -> tuple[bool, str]:
        """Enter Alter (real-time target) mode; only at rest (idempotent when enabled).
        Raises ``Offline`` while the plant cannot be reached."""
        with self._lock:
            if self._offline:
                raise Offline(self._offline)
            if self._alter and self._mode == "alter":
                if timeout_s is not None:
                    self.alter_timeout_s = float(timeout_s)
                if synchronized is not None:
                    self._sync = bool(synchronized)
                return True, ""
            if self._mode != "idle" or self._gen is not None:
                return False, f"robot busy ({self._mode})"
            if timeout_s is not None:
                self.alter_timeout_s = float(timeout_s)
            if synchronized is not None:
                self._sync = bool(synchronized)
            self._alter = True
            self._mode = "alter"
            self._target = self._q.copy()
            self._target_pending = False
            self._last_heard = self._plan_t
            self._watchdog_fired = False
            return True, ""

    def disable_alter(self) -> Motion:
        """Leave Alter mode; a moving robot first stops (the returned Motion completes at rest)."""
        with self._lock:
            self._alter = False
            motion = self._begin_stop("alter mode disabled")
            if self._mode == "alter":
                self._mode = "idle"
        self._run_deferred()
        return motion

    def set_target(self, q: npt.ArrayLike, synchronized: bool | None = None, relative: bool = False) -> tuple[bool, str]:
        """New Alter target (deg), any time; refused outside strict turn limits or further
        than max change from where the robot is. ``relative``: ``q`` is an offset from there.

        ``synchronized``: RTSpeedControl 0 -> True (axes arrive together), 1 -> False
        (every axis ramps on its own as fast as its limits allow). Any call counts as a
        heartbeat for the watchdog. Raises ``Offline`` while the plant cannot be reached.
        """
        with self._lock:
            if self._offline:
                raise Offline(self._offline)
            if not self._alter:
                return False, "alter mode is not enabled"
            self._last_heard = self._plan_t
            checked, reason = _check_target(q, self._q.tolist(), relative, self._lim)
            if checked is None:
                return False, reason
            target = np.array(checked)
            refused = self._zone_refusal(target)
            if refused:
                return False, refused
            if synchronized is not None:
                self._sync = bool(synchronized)
            self._watchdog_fired = False
            if self.dummy:
                self._q = target.copy()
                self._target = target
                return True, ""
            self._target = target
            self._target_pending = True  # planned by the next step()
            return True, ""

    def _zone_refusal(self, target: np.ndarray) -> ZoneReason | None:
        """Why the cell refuses an Alter target (lock held): the pose is in its way, or the
        guard stopped the arm on the way to this same target (the refusal stays, with the same
        reason, until the target changes: no true/ERROR for ever on a stream aimed at a zone)."""
        if self._zones is None:
            return None
        if self._zone_blocked is not None and np.array_equal(self._zone_blocked[0], target):
            return self._zone_blocked[1]
        self._zone_blocked = None
        if self._zone_stop is not None:  # the stop is told once, with the next target
            why, self._zone_stop = self._zone_stop, None
            if self._target is not None and np.array_equal(self._target, target):
                self._zone_blocked = (target, why)
            return why
        refused = self._zones.target(target)
        if refused is not None:
            self._zone_blocked = (target, refused)
        return refused

    def heartbeat(self) -> None:
        """The client is alive (keeps the Alter watchdog quiet without a new target)."""
        with self._lock:
            self._last_heard = self._plan_t

    # ------------------------------------------------------------------ stop
    def stop(self, reason: str = "stopped") -> Motion:
        """Controlled stop of whatever runs (client gone): ramps to rest within the limits,
        leaves Alter mode. The returned Motion completes at rest (``ok=False``, reason)."""
        with self._lock:
            self._alter = False
            motion = self._begin_stop(reason)
            if self._mode == "alter":
                self._mode = "idle"
        self._run_deferred()
        return motion

    def _begin_stop(self, reason: str, force: bool = False) -> Motion:
        """Start a controlled stop (lock held). Returns a Motion completing at rest.

        Jerk-limited Ruckig brake from the current state when its future stays inside
        the turn limits; otherwise (rare: limits changed under the motion) an
        acceleration-limited emergency brake, which has the shortest stopping distance.
        """
        if self._stop_motion is not None and not force:
            return self._stop_motion
        motion = self._stop_motion or Motion("stop")
        self._stop_reason = reason
        self._target_pending = False
        if not self._moving():
            self._target = self._q.copy()
            self._gen = None
            self._ebrake = False
            if self._mode in ("trajectory", "stopping"):
                self._mode = "alter" if self._alter else "idle"
            self._stop_motion = motion
            self._finish_stop_if_any()
            return motion
        along = self._along if self._mode == "trajectory" else None
        self._samples = None  # a trajectory in progress is abandoned
        brake = self._plan_stop(along)
        if brake is None:
            self._gen = None
            self._ebrake = True
            self._event(type="emergency_brake", reason=reason)
        else:
            self._gen, self._gen_t, self._gen_kind = brake, 0.0, "stop"
            self._ebrake = False
        self._mode = "stopping"
        self._stop_motion = motion
        return motion

    # ------------------------------------------------------------------ generator
    def _gen_input(self, lim: Limits, target: np.ndarray | None) -> ruckig.InputParameter:
        """Ruckig input from the exact current state; axes that may not move are held."""
        inp = self._inp
        q, v, a = self._q, self._qd, self._qdd
        vmax, amax = lim.vmax, lim.amax  # replaced, never changed in place
        # while the monitor still allows the old limits (transition), keep the old (higher)
        # jerk: a state from the old limits may need it to get within the new ones
        mon = self._monitor.enforced
        jmax = np.maximum(lim.jmax, mon.jmax)
        frozen = ~((vmax > MIN_LIMIT) & (amax > MIN_LIMIT))
        if frozen.any():
            # an axis with a zero limit may not move: held exactly if at rest, else braked
            # with the monitor's (old) limits
            held = frozen & (np.abs(v) <= 1e-9) & (np.abs(a) <= 1e-6)
            v = np.where(held, 0.0, v)
            a = np.where(held, 0.0, a)
            vmax = np.where(held, 1.0, np.where(frozen, np.maximum(mon.vmax, 1e-6), vmax))
            amax = np.where(held, 1.0, np.where(frozen, np.maximum(mon.amax, 1e-6), amax))
            jmax = np.where(held, 1.0, np.where(frozen, np.maximum(mon.jmax, 1e-6), jmax))
            if target is not None:
                target = np.where(frozen, q, target)
        # an estimated state may be inconsistent; the monitor's limits are the reachable ones
        v, a = _consistent_state(v, a, np.maximum(mon.vmax, vmax), np.maximum(mon.amax, amax),
                                 np.maximum(mon.jmax, jmax))
        inp.current_position = q.tolist()
        inp.current_velocity = v.tolist()
        inp.current_acceleration = a.tolist()
        inp.max_velocity = vmax.tolist()
        inp.max_acceleration = amax.tolist()
        inp.max_jerk = jmax.tolist()
        inp.target_velocity = [0.0] * N_JOINTS
        inp.target_acceleration = [0.0] * N_JOINTS
        if target is None:
            inp.control_interface = ruckig.ControlInterface.Velocity
            inp.target_position = q.tolist()
        else:
            inp.control_interface = ruckig.ControlInterface.Position
            inp.target_position = target.tolist()
        return inp

    def _calculate(self, inp: ruckig.InputParameter) -> ruckig.Trajectory | None:
        traj = ruckig.Trajectory(N_JOINTS)
        try:
            result = self._otg.calculate(inp, traj)
        except Exception:
            return None
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            return None
        return traj

    def _safe(self, traj: ruckig.Trajectory, *lims: Limits) -> bool:
        """Does the whole future of ``traj`` stay inside the turn limits of ``lims``?"""
        # cheap bound first: no joint can get further than (max speed x duration); in plain
        # floats, as it runs every cycle of an Alter stream
        d = traj.duration
        reach = [1.01 * (m if m >= s or m != m else s) * d + 1e-9  # np.maximum's, NaN included
                 for m, s in zip(self._monitor.enforced.vmax.tolist(), map(abs, self._qd.tolist()), strict=True)]
        q = self._q.tolist()
        low, high = [x - r for x, r in zip(q, reach, strict=True)], [x + r for x, r in zip(q, reach, strict=True)]
        if all(within(low, high, lim.turn_min, lim.turn_max, self._q) for lim in lims):
            return True
        lo, hi = trajectory_extrema(traj, 0.0)
        return all(within(lo, hi, lim.turn_min, lim.turn_max, self._q) for lim in lims)

    def _plan_stop(self, along: np.ndarray | None = None) -> ruckig.Trajectory | LineBrake | None:
        # a stop may use everything the monitor allows (the old limits during a
        # transition): the shortest stop is the safest. On a straight trajectory it runs
        # along the path (whose poses the cell checked), when it fits on it
        mon = self._monitor.enforced
        if along is not None:
            brake = line_brake(self._q, self._qd, self._qdd, along, mon.vmax, mon.amax, mon.jmax)
            if brake is not None:
                return brake
        for sync in (ruckig.Synchronization.Phase, ruckig.Synchronization.No):
            inp = self._gen_input(mon, None)
            inp.synchronization = sync
            traj = self._calculate(inp)
            if traj is not None and self._safe(traj, mon):
                return traj
        return None

    def _alter_pace(self) -> float:
        pace = max(ALTER_FEED_MIN, self._feed_target)
        if self._zones is not None and self._zones.escaping:  # a way out is slow (ZoneGuard.escape_share)
            pace = min(pace, self._zones.escape_share(self._q, self._lim.vmax))
        return pace

    def _plan_target(self) -> ruckig.Trajectory | None:
        pace = self._alter_pace()
        lim = self._lim
        if pace < 1.0:
            lim = lim.copy()
            lim.vmax = lim.vmax * pace
        inp = self._gen_input(lim, self._target)
        inp.synchronization = ruckig.Synchronization.Time if self._sync else ruckig.Synchronization.No
        traj = self._calculate(inp)
        if traj is not None and self._safe(traj, self._lim, self._monitor.enforced):
            self._gen_version = self._lim_version
            self._alter_feed = pace
            return traj
        return None

    # ------------------------------------------------------------------ the cycle
    def step(self) -> CoreState:
        """Advance one controller cycle; returns the new state."""
        with self._lock:
            self._cycle += 1
            self._plan_t += self.feed * self.dt
            if self._mode == "trajectory":
                self._step_trajectory()
            else:
                self._step_generator()
            moving = self._moving()  # once: the monitor's update changes none of its inputs
            self._update_monitor(moving)
            state = self._state(moving)
        self._run_deferred()
        return state

    def _apply(self, qn: np.ndarray, qd: np.ndarray | None, qdd: np.ndarray | None) -> None:
        v = (qn - self._q) / self.dt
        a = (v - self._v_fd) / self.dt
        self._q = qn.copy()
        self._v_fd = v
        self._qd = v.copy() if qd is None else np.asarray(qd, float).copy()
        self._qdd = a if qdd is None else np.asarray(qdd, float).copy()

    def _hold(self) -> None:
        if self._v_fd.any() or self._qd.any() or self._qdd.any():  # else held already: nothing changes
            self._apply(self._q.copy(), np.zeros(N_JOINTS), np.zeros(N_JOINTS))

    def _command(self, qn: np.ndarray, qd: np.ndarray | None, qdd: np.ndarray | None) -> Breach | None:
        """The one way a trajectory or generated sample becomes the setpoint: applied only if
        the limit monitor admits it; otherwise nothing changes and the breach is returned.
        (Only holding still and the monitor's own last resorts, ``clamp`` and ``brake``,
        are applied without it.)"""
        breach = self._monitor.check(qn, self._q, self._v_fd)
        if breach is None:
            self._apply(qn, qd, qdd)
        return breach

    def _step_trajectory(self) -> None:
        samples = self._samples
        assert samples is not None  # following a trajectory
        wanted = self._next_feed(samples)
        for feed in dict.fromkeys((wanted, (wanted + self._feed) / 2, self._feed)):  # the monitor decides
            qn, qd, qdd = self._sample_at(samples, self._pos + feed, feed)
            why = self._zone_check(qn, qd, qdd, self._along)
            if why is not None:  # the cell's guard: stop from here, the setpoint is not commanded
                self._violation("zone", 0, 0.0, 0.0, "trajectory", f"trajectory at sample {self._pos + feed:g}: {why}")
                self._begin_stop(why, force=True)
                self._step_generator()
                return
            bad = self._command(qn, qd, qdd)
            if bad is None:
                break
        if bad is not None:
            kind, j, value, limit = bad
            at = min(self._pos + feed, len(samples) - 1.0)
            self._violation(kind, j + 1, value, limit, "trajectory",
                            f"trajectory sample {at:g}: joint {j + 1} {kind} {value:.6g} beyond {limit:.6g}; stopping")
            self._begin_stop(f"limit violation ({kind}, joint {j + 1})", force=True)
            self._step_generator()
            return
        self._held_back += (1.0 - feed) * self.dt
        self._feed = feed
        self._pos = min(self._pos + feed, len(samples) - 1.0)
        if self._pos >= len(samples) - 1:
            self._finish_trajectory(True, "")
            self._finish_stop_if_any()

    def _sample_at(self, samples: np.ndarray, pos: float,
                   feed: float) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The setpoint ``pos`` samples along the trajectory (linear between two samples),
        with the samples' own velocity and acceleration when it is one of them, run at
        full pace."""
        last = len(samples) - 1
        k = min(int(pos), last)
        frac = pos - k if k < last else 0.0
        if frac < 1e-9 or frac > 1.0 - 1e-9:
            k, frac = min(k + (frac > 0.5), last), 0.0
        if frac:
            q: np.ndarray = samples[k] + frac * (samples[k + 1] - samples[k])
            return q, None, None
        exact = feed == 1.0 and self._feed == 1.0
        qd = self._samples_qd[k] if exact and self._samples_qd is not None else None
        qdd = self._samples_qdd[k] if exact and self._samples_qdd is not None else None
        return samples[k], qd, qdd

    def _next_feed(self, samples: np.ndarray) -> float:
        """The feed of this cycle: towards the target, by as much as the acceleration limits
        leave room for. Along the path (velocity ``v``, acceleration ``a`` in plan time) the
        commanded acceleration at the new feed ``f = feed + df`` is ``df v / dt`` plus the
        path's own, between ``f**2 a`` (a smooth path) and ``f a`` (its samples joined by
        straight lines): each joint's stays within ``FEED_ACCEL_SHARE`` of its limit (or no
        further beyond it than the path alone already is); ``df`` is halved until it does."""
        feed, target = self._feed, self._feed_target
        if target == feed:
            return feed
        k = min(int(self._pos), len(samples) - 2)
        if k < 1:
            return target  # at the start the path is at rest: any pace fits
        dt = self.dt
        v = (samples[k + 1] - samples[k]) / dt
        a = (samples[k + 1] - 2.0 * samples[k] + samples[k - 1]) / dt**2
        room = np.maximum(self._monitor.enforced.amax * FEED_ACCEL_SHARE, np.abs(feed * a))
        df = target - feed
        for _ in range(FEED_HALVINGS):
            f = feed + df
            push = df * v / dt
            if (np.abs(f * a + push) <= room).all() and (np.abs(f * f * a + push) <= room).all():
                return f
            df /= 2
        return feed

    def _step_generator(self) -> None:
        if self._alter and self._mode == "alter":
            # watchdog
            if (not self._watchdog_fired and self._plan_t - self._last_heard > self.alter_timeout_s
                    and (self._gen is not None or self._target_pending)):
                self._watchdog_fired = True
                self._event(type="watchdog", timeout_s=self.alter_timeout_s)
                self._begin_stop("alter watchdog: no target within timeout")
                self._stop_motion = None  # nobody waits for a watchdog stop
            else:
                if (self._gen is not None and self._gen_kind == "alter"
                        and abs(self._alter_pace() - self._alter_feed) >= ALTER_FEED_STEP):
                    self._target_pending = True  # slower or faster: replan what runs
                if self._target_pending:
                    traj = self._plan_target()
                    if traj is not None:
                        self._gen, self._gen_t, self._gen_kind = traj, 0.0, "alter"
                        self._target_pending = False
                    # else: keep the current (checked) motion; retry next cycle
        elif self._resync and self._mode == "stopping" and not self._ebrake:
            brake = self._plan_stop()
            if brake is not None:
                self._gen, self._gen_t, self._gen_kind = brake, 0.0, "stop"
            else:
                self._gen, self._ebrake = None, True
        self._resync = False
        if self._ebrake:
            self._step_ebrake()
            return
        if self._gen is None:
            self._hold()
            if self._mode == "stopping":
                self._mode = "alter" if self._alter else "idle"
                self._finish_stop_if_any()
            return
        self._gen_t += self.dt
        pos, vel, acc = self._gen.at_time(self._gen_t)
        qn = np.asarray(pos, float)
        if self._gen_kind == "alter" and (why := self._zone_check(qn, vel, acc)) is not None:
            self._gen_t -= self.dt
            self._violation("zone", 0, 0.0, 0.0, "alter", why)
            self._zone_stop = why
            self._begin_stop(why, force=True)
            self._step_generator()
            return
        bad = self._command(qn, np.asarray(vel, float), np.asarray(acc, float))
        if bad is not None:
            self._apply_clamped(qn, bad, self._gen_kind or "alter")
        if self._gen is not None and self._gen_t >= self._gen.duration - 1e-12:
            self._gen = None
            if self._mode == "stopping":
                self._mode = "alter" if self._alter else "idle"
                if self._alter and not self._target_pending:
                    self._target = self._q.copy()
            self._finish_stop_if_any()

    def _zone_check(self, qn: np.ndarray, qd: npt.ArrayLike | None, qdd: npt.ArrayLike | None,
                    along: np.ndarray | None = None) -> ZoneReason | None:
        """The cell's word on the next setpoint (``ZoneGuard.setpoint``): why it may not be
        commanded, or None. Without ``qd``/``qdd`` (a trajectory without them) the finite
        differences from the last setpoint stand in."""
        if self._zones is None:
            return None
        v = (qn - self._q) / self.dt if qd is None else np.asarray(qd, float)
        a = (v - self._v_fd) / self.dt if qdd is None else np.asarray(qdd, float)
        return self._zones.setpoint(qn, v, a, self._monitor.enforced, along=along, prev=self._q)

    def _apply_clamped(self, qn: np.ndarray, breach: Breach, source: str) -> None:
        """Apply the admissible sample closest to qn (the monitor's last resort), then stop."""
        kind, j, value, limit = breach
        self._violation(kind, j + 1, value, limit, source,
                        f"generated sample clamped: joint {j + 1} {kind} {value:.6g} beyond {limit:.6g}")
        self._apply(self._monitor.clamp(qn, self._q, self._v_fd), None, None)
        if self._mode != "stopping":
            self._begin_stop(f"limit violation ({kind}, joint {j + 1})", force=True)
        self._resync = True

    def _step_ebrake(self) -> None:
        """Emergency brake: every joint decelerates at the monitor's max acceleration."""
        q_new, v = self._monitor.brake(self._q, self._v_fd)
        j = self._monitor.outside_turn(q_new, self._q)
        if j is not None:
            self._violation("unavoidable", j + 1, q_new[j], 0.0, "stop",
                            "emergency brake cannot stay inside the turn limits")
        a = (v - self._v_fd) / self.dt
        self._apply(q_new, v, a)
        if not np.any(v):
            self._ebrake = False
            self._mode = "alter" if self._alter else "idle"
            if self._alter:
                self._target = self._q.copy()
            self._finish_stop_if_any()

    def _finish_stop_if_any(self) -> None:
        if self._gen is not None:
            return
        motion, self._stop_motion = self._stop_motion, None
        reason = getattr(self, "_stop_reason", "stopped")
        if self._motion is not None:  # a trajectory was stopped
            m, self._motion = self._motion, None
            self._deferred += m._finish(False, reason, self._state())
        if motion is not None:
            self._deferred += motion._finish(False, reason, self._state())

    def _update_monitor(self, moving: bool) -> None:
        """Let the monitor close transitional limits (``LimitMonitor.update``): in Alter
        motion the state counts once it follows a plan made with the current limits;
        trajectories and stops keep the wider limits until rest."""
        on_current_plan = (self._mode == "alter" and self._gen is not None and self._gen_kind == "alter"
                           and self._gen_version == self._lim_version and not self._target_pending)
        self._monitor.update(self._lim, moving, on_current_plan, self._v_fd, self._qd, self._qdd)

    # ------------------------------------------------------------------ fast-forward helpers
    def run(self, cycles: int) -> list[CoreState]:
        return [self.step() for _ in range(cycles)]

    def run_until_idle(self, max_cycles: int = 1_000_000) -> list[CoreState]:
        """Step until nothing moves (fast-forward; for tests and dummy use)."""
        states = []
        for _ in range(max_cycles):
            states.append(self.step())
            with self._lock:
                if not self._moving() and not self._target_pending:
                    break
        return states


# ====================================================================== helpers
def _six(values: npt.ArrayLike) -> np.ndarray:
    arr = np.asarray(values, float).reshape(-1)
    if arr.shape != (N_JOINTS,) or not np.all(np.isfinite(arr)):
        raise ValueError("expected 6 finite values")
    return arr


def _check_target(q: npt.ArrayLike, current: list[float], relative: bool,
                  lim: Limits) -> tuple[list[float] | None, str]:
    """An Alter target ``q`` (``relative``: an offset from ``current``) checked against the
    strict turn limits and the max change from ``current``: ``(target, "")``, or ``(None,
    why)`` when it is refused.

    Plain floats, not numpy: it runs for every target on the real-time path, where each
    numpy call on six values costs microseconds (docs/PERFORMANCE.md, "Python run cold")."""
    try:  # the bus's list of six numbers without numpy; anything else as numpy reads it
        values = [float(v) for v in q] if isinstance(q, list) and len(q) == N_JOINTS else _six(q).tolist()
    except (TypeError, ValueError):
        values = []
    if len(values) != N_JOINTS or not all(map(math.isfinite, values)):
        return None, "expected 6 finite values"
    target = [v + c for v, c in zip(values, current, strict=True)] if relative else values
    lo, hi = lim.turn_min.tolist(), lim.turn_max.tolist()
    for j, t in enumerate(target):
        if not lo[j] < t < hi[j]:  # NaN and inf too
            return None, f"joint {j + 1} target {t:.6f} outside turn limits ({lo[j]:g}, {hi[j]:g})"
    max_change = lim.max_change.tolist()
    for j, t in enumerate(target):
        step = abs(t - current[j])
        if step > max_change[j]:
            return None, (f"joint {j + 1} target {t:.6f} is {step:.6f} deg away, "
                          f"beyond the max change {max_change[j]:g}")
    return target, ""


def _consistent_state(v: np.ndarray, a: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
                      jmax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Velocity/acceleration made reachable within the limits (for estimated states).

    |v| <= vmax, |a| <= amax, and ramping the acceleration to 0 at max jerk must not
    carry the velocity beyond vmax (otherwise Ruckig would start with a brake phase
    that overshoots the limits). A no-op (to rounding) for states of a valid trajectory.
    """
    v = np.minimum(np.maximum(v, -vmax), vmax)  # np.clip's, without its wrappers' cost every cycle
    a = np.minimum(np.maximum(a, -amax), amax)
    room = np.maximum(vmax - v * np.sign(a), 0.0)
    a_lim = np.sqrt(2.0 * jmax * room)
    a = np.sign(a) * np.minimum(np.abs(a), a_lim)
    return v, a


def trajectory_extrema(traj: ruckig.Trajectory, t_from: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Exact (min, max) per joint of a Ruckig trajectory's positions from ``t_from`` on.

    Evaluates every constant-jerk segment (brake phase included) at its ends and at its
    velocity zeros; after the end the joint holds its final position. (Ruckig's own
    ``position_extrema`` is not reliable for our inputs: zero-duration trajectories and
    brake phases.)
    """
    profiles = traj.profiles[0]
    dofs = len(profiles)
    rows = []  # per DoF: 9 segments (2 brake + 7 profile) x (duration, p, v, a, j)
    for prof in profiles:
        brake = prof.brake
        if brake.duration > 0.0:
            head = (brake.t, brake.p[:2], brake.v[:2], brake.a[:2], brake.j[:2])
        else:
            head = ([0.0, 0.0],) * 5
        body = (prof.t, prof.p[:7], prof.v[:7], prof.a[:7], prof.j)
        rows.append([list(h) + list(b) for h, b in zip(head, body, strict=True)])
    seg = np.array(rows)  # (dofs, 5, 9)
    dur, p, v, a, j = np.moveaxis(seg, 1, 0)
    ts = np.zeros_like(dur)
    np.cumsum(dur[:, :-1], axis=1, out=ts[:, 1:])
    valid = (dur > 0) & (ts + dur >= t_from)
    tau0 = np.clip(t_from - ts, 0.0, dur)

    def pos(tau: np.ndarray) -> np.ndarray:
        at: np.ndarray = p + tau * (v + tau * (a * 0.5 + tau * j / 6.0))
        return at

    cands = [np.where(valid, pos(tau0), np.nan), np.where(valid, pos(dur), np.nan)]
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = a * a - 2.0 * j * v
        sq = np.sqrt(np.maximum(disc, 0.0))
        r1 = np.where(j != 0, (-a + sq) / j, np.where(a != 0, -v / a, np.nan))
        r2 = np.where(j != 0, (-a - sq) / j, np.nan)
    for r in (r1, r2):
        ok = valid & (disc >= 0) & np.isfinite(r) & (r >= tau0) & (r <= dur)
        cands.append(np.where(ok, pos(np.where(ok, r, 0.0)), np.nan))
    now = np.asarray(traj.at_time(t_from)[0], float)
    end = np.asarray(traj.at_time(max(traj.duration, t_from))[0], float)
    allc = np.concatenate([np.stack(cands, axis=1).reshape(dofs, -1), now[:, None], end[:, None]], axis=1)
    return np.nanmin(allc, axis=1), np.nanmax(allc, axis=1)
