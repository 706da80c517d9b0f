"""The FS03N and its robot program: the point queue executed with JMOVE and blending, in real time.

The robot program (``rob6_motion`` in deploy/kawasaki/rob6.as) starts a motion when the
queue holds ``START_POINTS`` points or a final one, then takes point after point: each becomes a segment of the
commanded path (joint-space straight line from the previous point, lasting the point's
time, never less than the slowest axis needs at its rated speed). Blended points (CP ON,
coarse ACCURACY) flow into the next; a final point is reached exactly (fine ACCURACY)
and the arm stops. When the queue runs dry before a final point the program waits (an
underrun): the arm stops at the last point and goes on when points come again.

The joints follow the commanded path like servos with the FS03N's speed and acceleration
limits (they accelerate and brake at their limits and round the corners between points
that follow each other in time). A stop (E-stop, motor power off, teach mode, an error)
brakes every joint at its stopping deceleration where it is. Everything is in the
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
#: the program refuses a point whose slowest axis would have to exceed its rated speed by more than this
SPEED_TOLERANCE = 1.05
#: a motion starts when the queue holds this many points (or a final one): while the arm runs
#: the first, the client has two periods to deliver the next before the queue runs dry
START_POINTS = 3

DT = 0.002  # integration step, s
KP = 50.0  # 1/s: how firmly the joints close the last bit of a gap
BRAKE_MARGIN = 0.9
SETTLE_DEG = 1e-6
MAX_CATCH_UP_S = 1.0


@dataclass(frozen=True)
class Target:
    q: tuple[float, ...]
    seconds: float
    final: bool
    sequence: int


def outside_range(q: tuple[float, ...]) -> str:
    for j in range(N):
        if not RANGE_MIN[j] <= q[j] <= RANGE_MAX[j]:
            return f"JT{j + 1} {q[j]:.3f} outside {RANGE_MIN[j]:g} .. {RANGE_MAX[j]:g}"
    return ""


def too_fast(start: tuple[float, ...] | list[float], q: tuple[float, ...], seconds: float) -> str:
    for j in range(N):
        speed = abs(q[j] - start[j]) / seconds
        if speed > RATED_SPEED[j] * SPEED_TOLERANCE:
            return f"JT{j + 1} would move at {speed:.1f} deg/s, rated {RATED_SPEED[j]:g}"
    return ""


class Arm:
    def __init__(self, q0: tuple[float, ...], now: float, capacity: int):
        self.q = [float(x) for x in q0]
        self.v = [0.0] * N
        self.ref = list(self.q)
        self.queue: deque[Target] = deque()
        self.capacity = capacity
        self.t = now
        self.running = False  # the robot program is executing a motion (not waiting for points)
        self.done = 0  # sequence of the last point the program took from the queue
        self.executed = 0
        self.underruns = 0
        self.max_speed_ratio = 0.0  # the fastest any joint moved, as a fraction of its rated speed
        self._seg: tuple[list[float], Target, float, float] | None = None
        self._braking = False

    # ---- the program's view ----------------------------------------------------
    def last_queued(self) -> list[float]:
        """Where the next point starts from: the last queued point, or the path's end."""
        if self.queue:
            return list(self.queue[-1].q)
        if self._seg is not None:
            return list(self._seg[1].q)
        return list(self.ref)

    def enqueue(self, target: Target) -> None:
        self.queue.append(target)

    def cancel(self) -> None:
        """Drop the queue; the segment under way (an issued JMOVE) runs out and the arm stops there."""
        self.queue.clear()
        self.running = False

    def stop(self) -> None:
        """Brake where it is (a stop category 1): the queue and the path are gone."""
        self.queue.clear()
        self._seg = None
        self.running = False
        if any(self.v):
            self._braking = True
        else:
            self.ref = list(self.q)

    @property
    def moving(self) -> bool:
        return (self._seg is not None or self._braking or any(self.v) or self.q != self.ref
                or (self.running and bool(self.queue)))

    # ---- time --------------------------------------------------------------------
    def advance(self, now: float) -> None:
        if not self.moving and not self._can_start():
            self.t = max(self.t, now)
            return
        if now - self.t > MAX_CATCH_UP_S:
            self.t = now - MAX_CATCH_UP_S
        while self.t + DT <= now:
            self._step(self.t)
            self.t += DT

    def _can_start(self) -> bool:
        return len(self.queue) >= START_POINTS or any(p.final for p in self.queue)

    def _path(self, t0: float, t: float) -> list[float] | None:
        """Move the commanded path on to time t; its joint velocities, or None when it stands."""
        start = t0
        while True:
            if self._seg is None:
                if not self.running:
                    if not self._can_start():
                        return None
                    self.running = True
                if not self.queue:  # ran dry before a final point: the program waits
                    self.underruns += 1
                    self.running = False
                    return None
                target = self.queue.popleft()
                seconds = max(target.seconds, *(abs(b - a) / v for a, b, v in
                                                zip(self.ref, target.q, RATED_SPEED, strict=True)))
                self._seg = (list(self.ref), target, start, seconds)
                self.done = target.sequence  # the robot program has taken it (its JMOVE began)
            r0, target, ts, seconds = self._seg
            if t < ts + seconds:
                f = (t - ts) / seconds
                self.ref = [a + (b - a) * f for a, b in zip(r0, target.q, strict=True)]
                return [(b - a) / seconds for a, b in zip(r0, target.q, strict=True)]
            self.ref = list(target.q)
            self._seg = None
            self.executed += 1
            start = ts + seconds
            if target.final:
                self.running = False
                return None
            if not self.queue:
                if self.running:  # not after a cancel: then stopping here is what was asked
                    self.underruns += 1
                self.running = False
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
        for i in range(N):
            e = self.ref[i] - self.q[i]
            a = MAX_ACCEL[i]
            speed = min(RATED_SPEED[i], math.sqrt(2.0 * BRAKE_MARGIN * a * abs(e)),
                        (abs(rdot[i]) if rdot else 0.0) + KP * abs(e))
            dv = math.copysign(speed, e) - self.v[i]
            self.v[i] += max(-a * DT, min(a * DT, dv))
            self.q[i] += self.v[i] * DT
            self.max_speed_ratio = max(self.max_speed_ratio, abs(self.v[i]) / RATED_SPEED[i])
        if rdot is None and all(abs(r - q) < SETTLE_DEG and abs(v) < KP * SETTLE_DEG * 10
                                for r, q, v in zip(self.ref, self.q, self.v, strict=True)):
            self.q = list(self.ref)
            self.v = [0.0] * N
