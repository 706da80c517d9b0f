"""The FS03N: the motions its robot program's JMOVEs plan, followed in real time.

A JMOVE becomes a segment of the commanded path: a joint-space straight line from where
the previous one ends, lasting its SPEED ... S time (never less than the slowest axis
needs at its rated speed), both stretched by the monitor speed (at 10 % ten times
longer). The controller plans one motion ahead: while a segment runs, the next JMOVE is
taken and starts when it ends (blended, the path does not stop); a further JMOVE waits
until that one has started (``room``). When no segment follows, the path stops at the
last point.

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
MAX_CATCH_UP_S = 1.0


@dataclass(frozen=True)
class Segment:
    q: tuple[float, ...]
    seconds: float  # as planned, before the monitor speed


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
        self._seg: tuple[list[float], tuple[float, ...], float, float] | None = None  # start, end, t0, seconds
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
        return self._seg is not None or bool(self.plan) or self._braking or any(self.v) or self.q != self.ref

    # ---- time --------------------------------------------------------------------
    def advance(self, now: float) -> None:
        if not self.moving:
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
                self._seg = (list(self.ref), seg.q, start, seconds)
            r0, q, ts, seconds = self._seg
            if t < ts + seconds:
                f = (t - ts) / seconds
                self.ref = [a + (b - a) * f for a, b in zip(r0, q, strict=True)]
                return [(b - a) / seconds for a, b in zip(r0, q, strict=True)]
            self.ref = list(q)
            self._seg = None
            self.executed += 1
            start = ts + seconds
            if not self.plan:
                return None

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
        for i in range(N):
            e = self.ref[i] - self.q[i]
            a = MAX_ACCEL[i] * scale * scale  # the motion stretched in time: speed by scale, acceleration by its square
            # the position loop's last approach is the servo's, which no monitor speed slows
            speed = min(RATED_SPEED[i] * scale, math.sqrt(2.0 * BRAKE_MARGIN * MAX_ACCEL[i] * abs(e)),
                        (abs(rdot[i]) if rdot else 0.0) + KP * abs(e))
            dv = math.copysign(speed, e) - self.v[i]
            self.v[i] += max(-a * DT, min(a * DT, dv))
            self.q[i] += self.v[i] * DT
            self.max_speed_ratio = max(self.max_speed_ratio, abs(self.v[i]) / RATED_SPEED[i])
        if rdot is None and all(abs(r - q) < SETTLE_DEG and abs(v) < KP * SETTLE_DEG * 10
                                for r, q, v in zip(self.ref, self.q, self.v, strict=True)):
            self.q = list(self.ref)
            self.v = [0.0] * N
