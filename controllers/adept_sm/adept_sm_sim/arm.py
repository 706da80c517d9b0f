"""The simulated arm: queued joint points played out in real time.

Each accepted point becomes a segment of a commanded path (joint-space straight line
from the previous point, timed as the V+ program would move there). The joints follow
that path like servos with the Viper's speed and acceleration limits: they accelerate
and brake at their limits, never run past a point they have to stop at, and round the
corners between points that follow each other in time (V+ continuous path). Everything
is in the controller's joint convention, degrees, driven by the caller's clock.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from .codec import END_TRAJECTORY
from .convention import MAX_ACCEL_DEG_S2, MAX_SPEED_DEG_S, N_JOINTS

DT = 0.002  # integration step, s
KP = 50.0  # 1/s: how firmly the joints close the last bit of a gap
BRAKE_MARGIN = 0.9  # brake planning uses 90 % of the deceleration, the rest absorbs the step
SETTLE_DEG = 1e-6
MAX_CATCH_UP_S = 1.0  # a stalled process does not replay more than this


@dataclass(frozen=True)
class Point:
    q: tuple[float, ...]  # controller joints, degrees
    velocity: float  # fraction of the maximum speed
    duration: float  # s
    sequence: int


class Arm:
    def __init__(self, q0: Sequence[float], now: float, *, timing: str = "vplus", monitor_speed: float = 100.0) -> None:
        if timing not in ("vplus", "duration"):
            raise ValueError(f"timing must be 'vplus' or 'duration', not {timing!r}")
        self.timing = timing
        self.vcap = [v * monitor_speed / 100.0 for v in MAX_SPEED_DEG_S]
        self.q = [float(x) for x in q0]
        self.v = [0.0] * N_JOINTS
        self.ref = list(self.q)  # where the commanded path is now
        self.queue: deque[Point] = deque()
        self.open = False  # a trajectory is under way: running dry is an underrun
        self.executed = 0
        self.underruns = 0
        self.t = now
        self._seg: tuple[list[float], Point, float, float] | None = None  # (from, point, t0, T)
        self._decel: tuple[float, ...] | None = None  # braking to rest, per joint

    # ---- commands --------------------------------------------------------
    def enqueue(self, point: Point) -> None:
        self.queue.append(point)
        self.open = True

    def stop(self, decel: Iterable[float]) -> None:
        """Drop every pending point and brake to rest with these decelerations (deg/s²)."""
        self.queue.clear()
        self._seg = None
        self.open = False
        if not any(self.v):  # already at rest: nothing to brake, it stays where it is
            self._decel = None
            self.ref = list(self.q)
            return
        if self._decel is not None:  # already braking (say for an E-stop): never softer
            decel = map(max, self._decel, decel)
        self._decel = tuple(decel)

    def close_trajectory(self) -> None:
        """The client went away: what is queued still runs, but running dry is no underrun."""
        self.open = False

    # ---- state -------------------------------------------------------------
    @property
    def in_motion(self) -> bool:
        return (
            self._seg is not None
            or bool(self.queue)
            or self._decel is not None
            or any(self.v)
            or self.q != self.ref
        )

    def segment_time(self, start: Sequence[float], point: Point) -> float:
        """How long the commanded path takes from start to point."""
        full_speed = max(abs(b - a) / v for a, b, v in zip(start, point.q, self.vcap, strict=True))
        if self.timing == "vplus":  # SPEED 100 ALWAYS: velocity and duration are ignored
            return full_speed
        if point.duration > 0:
            return max(point.duration, full_speed)
        return full_speed / min(point.velocity, 1.0)

    # ---- time ----------------------------------------------------------------
    def advance(self, now: float) -> None:
        if not self.in_motion:  # at rest: nothing to integrate
            self.t = max(self.t, now)
            return
        if now - self.t > MAX_CATCH_UP_S:
            self.t = now - MAX_CATCH_UP_S
        while self.t + DT <= now:
            self._step(self.t, DT)
            self.t += DT

    def _play(self, t0: float, t: float) -> list[float] | None:
        """Move the commanded path on to time t; its joint velocities, or None at rest."""
        start = t0  # a point found waiting starts at once
        while True:
            if self._seg is None:
                if not self.queue:
                    return None
                point = self.queue.popleft()
                self._seg = (list(self.ref), point, start, self.segment_time(self.ref, point))
            r0, point, ts, T = self._seg
            if t < ts + T:
                f = (t - ts) / T
                self.ref = [a + (b - a) * f for a, b in zip(r0, point.q, strict=True)]
                return [(b - a) / T for a, b in zip(r0, point.q, strict=True)]
            self.ref = list(point.q)
            self._seg = None
            self.executed += 1
            start = ts + T  # the next point continues where this one ended
            if point.sequence == END_TRAJECTORY:
                self.open = False
            elif self.open and not self.queue:
                self.underruns += 1

    def _step(self, t0: float, dt: float) -> None:
        if self._decel is not None:
            for i in range(N_JOINTS):
                a = self._decel[i] * dt
                self.v[i] -= max(-a, min(a, self.v[i]))
                self.q[i] += self.v[i] * dt
            if not any(self.v):
                self._decel = None
                self.ref = list(self.q)
            return
        rdot = self._play(t0, t0 + dt)
        for i in range(N_JOINTS):
            e = self.ref[i] - self.q[i]
            a = MAX_ACCEL_DEG_S2[i]
            speed = min(
                self.vcap[i],
                math.sqrt(2.0 * BRAKE_MARGIN * a * abs(e)),  # can still stop at the path
                (abs(rdot[i]) if rdot else 0.0) + KP * abs(e),
            )
            dv = math.copysign(speed, e) - self.v[i]
            self.v[i] += max(-a * dt, min(a * dt, dv))
            self.q[i] += self.v[i] * dt
        if rdot is None and all(
            abs(r - q) < SETTLE_DEG and abs(v) < KP * SETTLE_DEG * 10
            for r, q, v in zip(self.ref, self.q, self.v, strict=True)
        ):
            self.q = list(self.ref)
            self.v = [0.0] * N_JOINTS
