"""Physical simulation of the Adept's serial parallel gripper.

The model (one coordinate: the opening ``w`` between the jaws, m; ``v = dw/dt``)
---------------------------------------------------------------------------------
Figures are those of a small Schunk electric parallel gripper of the PG 70 class
(the kind driven over RS232 with the Schunk Motion Protocol):

=======================  ==============  =============================================
stroke                   0 ... 0.070 m   PG 70: 2 x 35 mm jaw stroke; the public ROS
                                         driver (SmartRoboticSystems/schunk_grippers,
                                         ``pg70_rs232_control.h``) accepts 0-69 mm
home (reference)         0.040 m         protocol text 3.4: "Referenzposition (etwa
                                         4 cm weit offen)"
max speed                0.082 m/s       same driver: velocity limit 0-83 mm/s
max acceleration         0.32 m/s^2      same driver: acceleration limit 320 mm/s^2
force constant K_F       40 N/A          gripping force F = K_F * |I|; 5 A -> 200 N,
                                         the PG 70's maximum gripping force
max current              5 A             larger |amps| is rejected, not clipped
Coulomb friction F_c     8 N             breakaway current F_c / K_F = 0.2 A
viscous damping b        1000 N s/m      spindle + gear reflected to the jaws
position-mode current    3 A             current limit of position moves (120 N if
                                         they run into an object)
=======================  ==============  =============================================

*Move by current* (``GripperMove amp``): the drive applies force ``K_F*I``; against
friction and damping the jaws run at the terminal speed
``v_t = min(v_max, (K_F*|I| - F_c) / b)`` (I = 1 A -> 0.032 m/s), reached with the
acceleration limit ``a_max``.  They stop dead on contact with the object (rigid,
configurable width; it only blocks closing, and only if the jaws were at least that
wide when the motion started) or at the stroke end.  On the object the mode becomes
``gripping``; the squeeze force is ``K_F*|I|`` and the current stays applied.  At
the stroke end the mode is ``idle``.  ``|I| <= F_c/K_F`` cannot move the jaws:
rejected with a clear error.

Time to close from home (0.040 m) onto a 0.030 m object at -1 A: accelerate
0.1 s over 1.6 mm to 0.032 m/s, then 8.4 mm at 0.032 m/s = 0.2625 s; 0.3625 s total.

*Move to position* / *go home*: trapezoidal profile with ``v_max``/``a_max`` (a
triangle for short moves); exact arrival at the target.  Running into the object
stops the jaws there (mode ``gripping`` at the position-mode current) and the move
fails ("blocked").  A target outside the stroke is rejected.

*Stop*: braking at ``a_max`` to rest, then ``idle`` with no current (a motion still
waiting ends as "stopped").  A new command while moving first brakes to rest
(position moves) or changes speed at ``a_max`` (current moves).

Time: :class:`GripperModel` is driven by explicit :meth:`GripperModel.advance` calls
and is exact (piecewise-constant acceleration, contact times solved analytically), so
tests can step or fast-forward it.  :class:`SimGripper` (the backend) advances it
from a clock: :class:`~rob6_gripper.backend.RealClock` for the service,
:class:`~rob6_gripper.backend.VirtualClock` to fast-forward in tests.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from rob6.errors import RefusedError

from .backend import (
    DEFAULT_TIMEOUT,
    ERROR,
    GRIPPING,
    IDLE,
    MOVING,
    Clock,
    GripperBackend,
    GripperStatus,
    RealClock,
    Result,
    VirtualClock,
    check_number,
    check_timeout,
    fail,
)

__all__ = ["GripperParams", "GripperModel", "GripperError", "Outcome", "SimGripper",
           "RealClock", "VirtualClock"]

EPS = 1e-9  # m; positions closer than this are equal


@dataclass(frozen=True)
class GripperParams:
    stroke_min: float = 0.0  # m
    stroke_max: float = 0.070  # m
    home_position: float = 0.040  # m
    max_velocity: float = 0.082  # m/s
    max_acceleration: float = 0.32  # m/s^2
    force_constant: float = 40.0  # N/A
    friction_force: float = 8.0  # N
    damping: float = 1000.0  # N s/m
    max_current: float = 5.0  # A
    position_current: float = 3.0  # A

    def terminal_velocity(self, amps: float) -> float:
        """Steady speed (m/s, >= 0) of a current move with ``amps``."""
        drive = self.force_constant * abs(amps) - self.friction_force
        return min(self.max_velocity, max(0.0, drive / self.damping))

    def force(self, amps: float) -> float:
        """Gripping force (N) at motor current ``amps``."""
        return self.force_constant * abs(amps)

    @property
    def breakaway_current(self) -> float:
        return self.friction_force / self.force_constant

    def in_stroke(self, w: float) -> bool:
        return self.stroke_min - EPS <= w <= self.stroke_max + EPS


class GripperError(RefusedError):
    """A command the model refuses (the message is the user-facing reason)."""


@dataclass(frozen=True)
class Outcome:
    """How a motion ended."""

    status: str  # reached | gripping | end_stop | blocked | stopped | error
    position: float
    message: str = ""

    @property
    def ok(self) -> bool:
        return self.status in ("reached", "gripping", "end_stop")


@dataclass
class _Seg:
    w0: float
    v0: float
    a: float
    T: float

    def at(self, tau: float) -> tuple[float, float]:
        return self.w0 + self.v0 * tau + 0.5 * self.a * tau * tau, self.v0 + self.a * tau


@dataclass
class _Motion:
    id: int
    kind: str  # position | home | current | stop
    segs: list[_Seg] = field(default_factory=list)
    target: float | None = None
    amps: float = 0.0
    lower: float = 0.0  # barriers (m) fixed when the motion starts
    upper: float = 0.0
    lower_is_object: bool = False
    contact: float | None = None  # the plan ends on this barrier (set by truncation)


def _first_crossing(seg: _Seg, x: float, downward: bool) -> float | None:
    """Earliest tau in [0, seg.T] at which the segment runs into barrier ``x``: from
    above (``downward``) or from below.  None if it does not."""
    # g(tau) >= 0 means "at or beyond the barrier"
    sgn = -1.0 if downward else 1.0
    A, B, C = sgn * 0.5 * seg.a, sgn * seg.v0, sgn * (seg.w0 - x)
    if C >= -EPS and (C > EPS or B > 1e-12 or (abs(B) <= 1e-12 and A > 0)):  # starts on (or beyond) the barrier
        return 0.0
    roots: list[float] = []
    if abs(A) < 1e-15:
        if abs(B) > 1e-15:
            roots.append(-C / B)
    else:
        disc = B * B - 4 * A * C
        if disc >= 0:
            sq = math.sqrt(disc)
            roots += [(-B - sq) / (2 * A), (-B + sq) / (2 * A)]
    for r in sorted(roots):
        if 1e-15 < r <= seg.T + 1e-12 and 2 * A * r + B >= 0:
            return min(r, seg.T)
    return None


class GripperModel:
    """The steppable physics.  Not thread-safe; :class:`SimGripper` locks around it."""

    def __init__(self, params: GripperParams | None = None, *, position: float | None = None,
                 object_width: float | None = None, referenced: bool = True) -> None:
        self.p = params or GripperParams()
        self.w = self.p.home_position if position is None else float(position)
        if not self.p.in_stroke(self.w):
            raise ValueError(f"start position {self.w} m outside the stroke")
        self.v = 0.0
        self.a = 0.0
        self.current = 0.0
        self.mode = IDLE
        self.error = ""
        self.referenced = referenced
        self.object_width: float | None = None
        self.time = 0.0
        self._motion: _Motion | None = None
        self._seg_i = 0
        self._tau = 0.0
        self._next_id = 1
        self._outcomes: dict[int, Outcome] = {}
        self.set_object(object_width)

    # ------------------------------------------------------------ observation
    @property
    def force(self) -> float:
        """Squeeze force on the object (N); 0 unless gripping."""
        return self.p.force(self.current) if self.mode == GRIPPING else 0.0

    @property
    def moving(self) -> bool:
        return self._motion is not None

    def status(self) -> GripperStatus:
        return GripperStatus(self.w, self.v, self.current, self.mode, self.error)

    def outcome(self, motion_id: int) -> Outcome | None:
        """How motion ``motion_id`` ended, or None while it runs."""
        return self._outcomes.get(motion_id)

    def time_to_completion(self) -> float:
        """Exact time until the running motion ends (contacts included); 0 if none."""
        m = self._motion
        if m is None:
            return 0.0
        return (m.segs[self._seg_i].T - self._tau) + sum(s.T for s in m.segs[self._seg_i + 1:])

    # ------------------------------------------------------------ commands
    def set_object(self, width: float | None) -> None:
        """Put an object of ``width`` m between the jaws (None: remove it)."""
        if self._motion is not None:
            raise ValueError("cannot change the object while the jaws move")
        if width is not None and not (self.p.stroke_min <= width <= self.p.stroke_max):
            raise ValueError(f"object width {width} m outside the stroke")
        self.object_width = width
        if width is None and self.mode == GRIPPING:
            self.mode = IDLE  # taken out of the jaws: they stand where they are

    def command_position(self, target: float, *, home: bool = False) -> int:
        """Start a position move (``home``: the reference run); returns its id."""
        self._check_ready()
        p = self.p
        if not home:
            if not math.isfinite(target) or not p.in_stroke(target):
                raise GripperError(
                    f"position {target:.4f} m is outside the stroke "
                    f"{p.stroke_min:.3f}..{p.stroke_max:.3f} m")
            if not self.referenced:
                raise GripperError("gripper not referenced: run GripperGoHome first")
        target = min(max(target, p.stroke_min), p.stroke_max)
        segs = self._brake_segments()
        w = segs[-1].at(segs[-1].T)[0] if segs else self.w
        d = target - w
        dist = abs(d)
        if dist > EPS:
            s = 1.0 if d > 0 else -1.0
            a = p.max_acceleration
            vp = min(p.max_velocity, math.sqrt(dist * a))
            ta = vp / a
            da = vp * vp / (2 * a)
            tc = max(0.0, dist - 2 * da) / vp
            segs.append(_Seg(w, 0.0, s * a, ta))
            if tc > 0:
                segs.append(_Seg(w + s * da, s * vp, 0.0, tc))
            segs.append(_Seg(target - s * da, s * vp, -s * a, ta))
        return self._start(_Motion(0, "home" if home else "position", segs, target=target))

    def command_current(self, amps: float) -> int:
        """Start a current move (negative closes); returns its id."""
        self._check_ready()
        p = self.p
        if not math.isfinite(amps):
            raise GripperError(f"invalid current {amps!r} A")
        if abs(amps) > p.max_current + 1e-12:
            raise GripperError(
                f"current {amps:.3f} A exceeds the gripper's maximum of {p.max_current:.3f} A")
        vt = p.terminal_velocity(amps)
        if vt <= 0:
            raise GripperError(
                f"current {amps:.3f} A gives {p.force(amps):.1f} N, not more than the "
                f"{p.friction_force:.1f} N friction: the jaws cannot move "
                f"(need |I| > {p.breakaway_current:.3f} A)")
        vt = math.copysign(vt, amps)
        dv = vt - self.v
        segs = []
        w1 = self.w
        if abs(dv) > 1e-15:
            ta = abs(dv) / p.max_acceleration
            segs.append(_Seg(self.w, self.v, math.copysign(p.max_acceleration, dv), ta))
            w1 = segs[0].at(ta)[0]
        # cruise; long enough to cross the whole stroke, truncated at the barrier
        span = p.stroke_max - p.stroke_min
        segs.append(_Seg(w1, vt, 0.0, (2 * span + abs(w1 - self.w)) / abs(vt)))
        return self._start(_Motion(0, "current", segs, amps=amps))

    def command_stop(self) -> int:
        """Brake to rest; supersedes any running motion (which ends as 'stopped')."""
        if self.mode == ERROR:
            return 0
        return self._start(_Motion(0, "stop", self._brake_segments()))

    def fault(self, message: str) -> None:
        """Inject a device error: motor off at once, mode 'error' until acknowledged."""
        self._supersede("error", f"gripper error: {message}")
        self.v = self.a = self.current = 0.0
        self.mode = ERROR
        self.error = message

    def acknowledge(self) -> None:
        if self.mode == ERROR:
            self.mode = IDLE
            self.error = ""

    # ------------------------------------------------------------ time
    def advance(self, dt: float) -> None:
        """Let ``dt`` seconds of simulated time pass."""
        if dt < 0:
            raise ValueError("time runs forward")
        self.time += dt
        while self._motion is not None:
            m = self._motion
            seg = m.segs[self._seg_i]
            t_end = self._tau + dt
            if t_end >= seg.T - 1e-12:  # absorb rounding of summed segment times
                t_end = seg.T
            dt = max(0.0, dt - (t_end - self._tau))
            self._tau = t_end
            self.w, self.v = seg.at(t_end)
            self.a = seg.a
            if m.kind in ("position", "home"):
                self.current = self._position_current()
            if t_end < seg.T:
                break  # time used up inside this segment
            self._seg_i += 1
            self._tau = 0.0
            if self._seg_i >= len(m.segs):
                self._finish(m)

    # ------------------------------------------------------------ internals
    def _check_ready(self) -> None:
        if self.mode == ERROR:
            raise GripperError(f"gripper error: {self.error} (acknowledge it first)")

    def _brake_segments(self) -> list[_Seg]:
        if abs(self.v) < 1e-15:
            return []
        a = self.p.max_acceleration
        return [_Seg(self.w, self.v, -math.copysign(a, self.v), abs(self.v) / a)]

    def _start(self, m: _Motion) -> int:
        self._supersede("stopped", "stopped by a stop command" if m.kind == "stop"
                        else "interrupted by a new command")
        m.id = self._next_id
        self._next_id += 1
        obj = self.object_width
        # the object only blocks closing, and only if it is between the jaws
        if obj is not None and self.w >= obj - EPS:
            m.lower, m.lower_is_object = obj, True
        else:
            m.lower = self.p.stroke_min
        m.upper = self.p.stroke_max
        # truncate the plan at the first barrier it runs into
        for i, seg in enumerate(m.segs):
            hits = []
            for barrier, downward in ((m.lower, True), (m.upper, False)):
                if m.target is not None and abs(m.target - barrier) <= EPS:
                    continue  # a planned arrival on the barrier is not a collision
                tau = _first_crossing(seg, barrier, downward)
                if tau is not None:
                    hits.append((tau, barrier))
            if hits:
                tau, barrier = min(hits)
                seg.T = tau
                del m.segs[i + 1:]
                m.contact = barrier
                break
        if m.kind == "current":
            self.current = m.amps
        elif m.kind == "stop":
            self.current = 0.0
        self._seg_i = 0
        self._tau = 0.0
        if sum(s.T for s in m.segs) <= 0.0:
            self._finish(m)  # nothing to travel
        else:
            self._motion = m
            self.mode = MOVING
            if m.kind in ("position", "home"):
                self.a = m.segs[0].a
                self.current = self._position_current()
        return m.id

    def _position_current(self) -> float:
        """Motor current of a position move: friction + damping, within the limit."""
        p = self.p
        direction = self.v if abs(self.v) > 1e-12 else self.a
        if direction == 0:
            return 0.0
        i = (math.copysign(p.friction_force, direction) + p.damping * self.v) / p.force_constant
        return max(-p.position_current, min(p.position_current, i))

    def _finish(self, m: _Motion) -> None:
        self._motion = None
        self._seg_i = 0
        self._tau = 0.0
        self.v = self.a = 0.0
        p = self.p
        if m.contact is not None:
            self.w = m.contact
            on_object = m.lower_is_object and m.contact == m.lower
            if m.kind == "current":
                self.current = m.amps
                if on_object:
                    self.mode = GRIPPING
                    out = Outcome("gripping", self.w, f"gripping an object at {self.w:.4f} m "
                                                      f"with {p.force(m.amps):.1f} N")
                else:
                    self.mode = IDLE
                    out = Outcome("end_stop", self.w, f"at the stroke end {self.w:.4f} m")
            elif m.kind == "stop":
                self.current = 0.0
                self.mode = IDLE
                out = Outcome("stopped", self.w, f"stopped at {self.w:.4f} m")
            else:
                self.current = -p.position_current if on_object else 0.0
                self.mode = GRIPPING if on_object else IDLE
                what = "an object" if on_object else "the stroke end"
                out = Outcome("blocked", self.w, f"blocked by {what} at {self.w:.4f} m "
                                                 f"before reaching {m.target:.4f} m")
        elif m.kind in ("position", "home"):
            assert m.target is not None  # position and home motions have one
            self.w = m.target
            self.current = 0.0
            self.mode = IDLE
            if m.kind == "home":
                self.referenced = True
            out = Outcome("reached", self.w, f"at {self.w:.4f} m")
        else:  # stop (a current move always ends on a barrier)
            self.current = 0.0
            self.mode = IDLE
            out = Outcome("stopped", self.w, f"stopped at {self.w:.4f} m")
        self._outcomes[m.id] = out

    def _supersede(self, status: str, message: str) -> None:
        m = self._motion
        if m is not None:
            self._outcomes[m.id] = Outcome(status, self.w, f"{message} at {self.w:.4f} m")
            self._motion = None


class SimGripper(GripperBackend):
    """The simulated gripper as a backend (thread-safe; time from ``clock``)."""

    def __init__(self, params: GripperParams | None = None, *, clock: Clock | None = None,
                 object_width: float | None = None, present: bool = True,
                 referenced: bool = True, position: float | None = None) -> None:
        self.model = GripperModel(params, position=position, object_width=object_width,
                                  referenced=referenced)
        self.clock: Clock = clock or RealClock()
        self.present = present
        self._cv = threading.Condition(threading.RLock())
        self._t = self.clock.now()

    # ---------------------------------------------------------------- helpers
    def _sync(self) -> None:
        now = self.clock.now()
        if now > self._t:
            self.model.advance(now - self._t)
        self._t = max(self._t, now)

    def set_object(self, width: float | None) -> None:
        with self._cv:
            self._sync()
            self.model.set_object(width)

    def fault(self, message: str) -> None:
        with self._cv:
            self._sync()
            self.model.fault(message)
            self._cv.notify_all()

    def _run(self, what: str, start: Callable[[], int], timeout: float) -> Result:
        err = check_timeout(timeout)
        if err:
            return fail(f"{what}: {err}")
        if not self.present:
            return fail(f"{what}: no gripper connected")
        with self._cv:
            self._sync()
            try:
                mid = start()
            except GripperError as e:
                return fail(f"{what}: {e}", self.model.w)
            self._cv.notify_all()
            deadline = self.clock.now() + timeout
            while True:
                self._sync()
                out = self.model.outcome(mid)
                if out is not None:
                    if out.ok:
                        return Result(True, "", out.position)
                    return fail(f"{what}: {out.message}", out.position)
                left = deadline - self.clock.now()
                if left <= 0:
                    self.model.command_stop()
                    self._cv.notify_all()
                    return fail(f"{what}: not finished within {timeout:.3f} s; stopped at "
                                f"{self.model.w:.4f} m", self.model.w)
                self.clock.wait(self._cv, min(left, self.model.time_to_completion() + 1e-6))

    def _at_once(self, what: str, command: Callable[[], object], *, wake: bool = False) -> Result:
        """A command the module carries out at once (stop, acknowledge): the position after it;
        ``wake``: a call waiting for its motion to end looks again."""
        if not self.present:
            return fail(f"{what}: no gripper connected")
        with self._cv:
            self._sync()
            command()
            if wake:
                self._cv.notify_all()
            return Result(True, "", self.model.w)

    # ---------------------------------------------------------------- interface
    def has_gripper(self) -> bool:
        return self.present

    def go_home(self, timeout: float = DEFAULT_TIMEOUT) -> Result:
        return self._run("GripperGoHome",
                         lambda: self.model.command_position(self.model.p.home_position, home=True),
                         timeout)

    def move_current(self, amps: float, timeout: float = DEFAULT_TIMEOUT) -> Result:
        err = check_number("current", amps, "A")
        if err:
            return fail(f"GripperMove: {err}")
        return self._run("GripperMove", lambda: self.model.command_current(float(amps)), timeout)

    def move_to_position(self, metres: float, timeout: float = DEFAULT_TIMEOUT) -> Result:
        err = check_number("position", metres, "m")
        if err:
            return fail(f"GripperMoveToPosition: {err}")
        return self._run("GripperMoveToPosition",
                         lambda: self.model.command_position(float(metres)), timeout)

    def stop(self) -> Result:
        return self._at_once("stop", self.model.command_stop, wake=True)

    def acknowledge(self) -> Result:
        return self._at_once("acknowledge", self.model.acknowledge)

    def state(self) -> GripperStatus:
        if not self.present:
            return GripperStatus(0.0, 0.0, 0.0, ERROR, "no gripper connected")
        with self._cv:
            self._sync()
            return self.model.status()

