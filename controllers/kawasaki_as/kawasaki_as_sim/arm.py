"""The FS03N: the motions its robot program's JMOVEs plan, followed in real time.

A JMOVE becomes a segment of the commanded path: a joint-space straight line from where
the previous one ends, lasting its SPEED ... S time (never less than the slowest axis
needs at its rated speed), both stretched by the monitor speed (at 10 % ten times
longer). The controller plans one motion ahead: while a segment runs, the next JMOVE is
taken and starts when it ends; a further JMOVE waits until that one has started
(``room``). The next segment starts once the arm is within the segment's accuracy of its
target (ACCURACY, in mm, taken as joint degrees at the FS03N's reach), or at rest there
when the segment ends at rest: CP OFF or FINE at its JMOVE, no segment planned after it,
or a next one the program reached past a branch or a wait (motion type 1, no look-ahead).
Towards a target it must leave at a lower speed, or at rest, each joint slows at its
acceleration limit, so a stop costs the time to brake and start again.

The joints follow the commanded path like servos with the FS03N's speed and acceleration
limits (they accelerate and brake at their limits and round the corners between
segments). A stop (E-stop, motor power off, teach mode, an error) brakes every joint at
its stopping deceleration where it is and drops the plan. Everything is in the
controller's joint convention, degrees, driven by the caller's clock.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

N = 6
#: the FS03N's motion range (Kawasaki's data sheet), controller's convention, deg
RANGE_MIN = (-160.0, -60.0, -150.0, -360.0, -135.0, -360.0)
RANGE_MAX = (160.0, 150.0, 120.0, 360.0, 135.0, 360.0)
#: rated axis speeds, deg/s
RATED_SPEED = (360.0, 250.0, 225.0, 540.0, 225.0, 540.0)
#: the simulator's acceleration limits: rated speed in 0.25 s (deg/s²)
MAX_ACCEL = tuple(v * 4.0 for v in RATED_SPEED)
#: braking at a stop (E-stop, motor power off): twice that
STOP_DECEL = tuple(a * 2.0 for a in MAX_ACCEL)
DT = 0.002  # integration step, s
KP = 50.0  # 1/s: how firmly the joints close the last bit of a gap
BRAKE_MARGIN = 0.9
SETTLE_DEG = 1e-6
#: the FS03N's reach (mm, robots.md): an accuracy of this many mm is one radian of a joint
REACH_MM = 620.0
MAX_CATCH_UP_S = 1.0


@dataclass(frozen=True)
class Segment:
    q: tuple[float, ...]
    seconds: float  # as planned, before the monitor speed
    accuracy_mm: float = 1.0  # the next segment starts once the arm is this close to q
    stop: bool = False  # ends at rest (CP OFF, FINE)
    after_rest: bool = False  # starts only once the arm is at rest at the previous target

    @property
    def accuracy_deg(self) -> float:
        return math.degrees(self.accuracy_mm / REACH_MM)


def outside_range(q: tuple[float, ...]) -> str:
    for j in range(N):
        if not RANGE_MIN[j] <= q[j] <= RANGE_MAX[j]:
            return f"JT{j + 1} {q[j]:.3f} outside {RANGE_MIN[j]:g} .. {RANGE_MAX[j]:g}"
    return ""


class Arm:
    def __init__(self, q0: tuple[float, ...], now: float):
        self.q = [float(x) for x in q0]
        self.v = [0.0] * N
        self.ref = list(self.q)
        self.plan: deque[Segment] = deque()
        self.monitor_speed = 100.0  # percent
        self.t = now
        self.executed = 0
        self.max_speed_ratio = 0.0  # the fastest any joint moved, as a fraction of its rated speed
        self._seg: tuple[list[float], Segment, float, float] | None = None  # start, segment, t0, seconds
        self._braking = False

    # ---- the robot program's view ---------------------------------------------
    def room(self) -> bool:
        return not self.plan

    def move(self, seg: Segment) -> None:
        self.plan.append(seg)

    def stop(self) -> None:
        """Brake where it is (a stop category 1): the plan is gone."""
        self.plan.clear()
        self._seg = None
        if any(self.v):
            self._braking = True
        else:
            self.ref = list(self.q)

    @property
    def moving(self) -> bool:
        """The arm moves or has somewhere to go (a motion to where it stands is no move)."""
        if self._braking or any(self.v) or self.q != self.ref:
            return True
        planned = [self._seg[1], *self.plan] if self._seg is not None else list(self.plan)
        return any(list(seg.q) != self.ref for seg in planned)

    @property
    def _active(self) -> bool:
        return self._seg is not None or bool(self.plan) or self._braking or any(self.v) or self.q != self.ref

    # ---- time --------------------------------------------------------------------
    def advance(self, now: float) -> None:
        if not self._active:
            self.t = max(self.t, now)
            return
        if now - self.t > MAX_CATCH_UP_S:
            self.t = now - MAX_CATCH_UP_S
        while self.t + DT <= now:
            self._step(self.t)
            self.t += DT

    def _path(self, t0: float, t: float) -> list[float] | None:
        """Move the commanded path on to time t; its joint velocities, or None when it stands."""
        start = t0
        while True:
            if self._seg is None:
                if not self.plan:
                    return None
                seg = self.plan.popleft()
                stretch = 100.0 / self.monitor_speed
                seconds = max(seg.seconds, *(abs(b - a) / v for a, b, v in
                                             zip(self.ref, seg.q, RATED_SPEED, strict=True))) * stretch
                self._seg = (list(self.ref), seg, start, seconds)
            r0, cur, ts, seconds = self._seg
            q = cur.q
            if t < ts + seconds:
                f = (t - ts) / seconds
                self.ref = [a + (b - a) * f for a, b in zip(r0, q, strict=True)]
                return [(b - a) / seconds for a, b in zip(r0, q, strict=True)]
            self.ref = list(q)
            if self.plan and not self._may_go_on(cur, self.plan[0]):
                return None  # the path waits at the target for the arm
            self._seg = None
            self.executed += 1
            start = max(ts + seconds, t0)
            if not self.plan:
                return None

    def _may_go_on(self, cur: Segment, nxt: Segment) -> bool:
        if cur.stop or nxt.after_rest:
            return not any(self.v) and all(abs(a - b) < SETTLE_DEG for a, b in zip(self.q, cur.q, strict=True))
        return all(abs(a - b) <= cur.accuracy_deg for a, b in zip(self.q, cur.q, strict=True))

    def _end_speeds(self) -> list[float] | None:
        """Per joint, the speed at which the arm may reach the current segment's target (None: no
        segment runs): the part of its motion the next segment continues, 0 where it ends at rest."""
        if self._seg is None:
            return None
        r0, cur, _, seconds = self._seg
        nxt = self.plan[0] if self.plan else None
        if nxt is None or cur.stop or nxt.after_rest or nxt.seconds <= 0:
            return [0.0] * N
        out = []
        for i in range(N):
            vc, vn = (cur.q[i] - r0[i]) / seconds, (nxt.q[i] - cur.q[i]) / nxt.seconds
            out.append(min(abs(vc), abs(vn)) if vc * vn > 0 else 0.0)
        return out

    def _step(self, t0: float) -> None:
        if self._braking:
            for i in range(N):
                a = STOP_DECEL[i] * DT
                self.v[i] -= max(-a, min(a, self.v[i]))
                self.q[i] += self.v[i] * DT
            if not any(self.v):
                self._braking = False
                self.ref = list(self.q)
            return
        rdot = self._path(t0, t0 + DT)
        scale = self.monitor_speed / 100.0
        ends = self._end_speeds()
        for i in range(N):
            e = self.ref[i] - self.q[i]
            a = MAX_ACCEL[i] * scale * scale  # the motion stretched in time: speed by scale, acceleration by its square
            # the position loop's last approach is the servo's, which no monitor speed slows
            speed = min(RATED_SPEED[i] * scale, math.sqrt(2.0 * BRAKE_MARGIN * MAX_ACCEL[i] * abs(e)),
                        (abs(rdot[i]) if rdot else 0.0) + KP * abs(e))
            if ends is not None and self._seg is not None:
                # brake towards the target in time to reach it at the speed the next segment takes on
                ahead = (self._seg[1].q[i] - self.q[i]) * math.copysign(1.0, e)
                speed = min(speed, math.sqrt(ends[i] ** 2 + 2.0 * BRAKE_MARGIN * a * max(ahead, 0.0)))
            dv = math.copysign(speed, e) - self.v[i]
            self.v[i] += max(-a * DT, min(a * DT, dv))
            self.q[i] += self.v[i] * DT
            self.max_speed_ratio = max(self.max_speed_ratio, abs(self.v[i]) / RATED_SPEED[i])
        if not any(rdot or ()) and all(abs(r - q) < SETTLE_DEG and abs(v) < KP * SETTLE_DEG * 10
                                for r, q, v in zip(self.ref, self.q, self.v, strict=True)):
            self.q = list(self.ref)
            self.v = [0.0] * N
