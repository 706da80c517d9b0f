"""The simulated arm: the MOVEs the V+ program issues, planned at 100 % and played at the monitor speed.

Each ``MOVE`` (``adept_ros.v2`` line 599) is a joint-interpolated segment from the
previous point, planned with what ``SPEED 100 ALWAYS`` and ``ACCEL (1) 100, 100`` give
(lines 546-547): the joints together along a straight line in joint space, the slowest
joint at its rated speed, no shorter than the minimum time of a motion; the point's
velocity and duration play no part. V+ plans a MOVE behind the running motion and returns
from it when it begins (forward processing), so at most one MOVE waits beyond the one
running (``room``). The issued segments form the path, run at a feed that ramps with the
acceleration and always leaves room to stop at the path's last point (a MOVE is done when
the path has passed its end); the joints follow it like servos, at most at their speed and
acceleration, never past the point the path stops at, and round the corner to the next
segment when it was issued before the running one ended (continuous path). When it came
later, the arm stops at the point first and then goes (an underrun, when it happens within
a stream). So the arm stays on the issued path: what it runs after its last MOVE is the
rest of that path, never a lag behind it.

The monitor speed is time scaling (V+ Operating System Reference, monitor command SPEED):
the same motion, every part of it lasting 1/s as long, so speeds fall with s and
accelerations with s². The arm runs on a plan clock that advances s times as fast as the
caller's (``rate``; changed at once by ``set_monitor_speed``); a controller stop (E-stop,
drives off) brakes on the caller's clock. Everything is in the controller's joint
convention, degrees.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from .convention import ACCEL_TIME_S, MAX_SPEED_DEG_S, N_JOINTS

DT = 0.002  # integration step, s
KP = 50.0  # 1/s: how firmly the joints close the last bit of a gap
BRAKE_MARGIN = 0.9  # the path's ramps and the servos' braking use 90 % of the acceleration, the rest closes the lag
#: stopped at a point, for a MOVE that came late: this close (deg) and (nearly) at rest
STOPPED_DEG = 1e-3
MAX_CATCH_UP_S = 1.0  # a stalled process does not replay more than this
#: MOVEs issued beyond the one running (V+'s forward processing: the next one is planned)
AHEAD = 1


@dataclass(frozen=True)
class Move:
    q: tuple[float, ...]  # controller joints, degrees
    arrived_t: float  # when its point arrived on the motion connection (the caller's clock)


class Arm:
    def __init__(self, q0: Sequence[float], now: float, *, monitor_speed: float = 100.0,
                 accel_time_s: float = ACCEL_TIME_S, min_move_s: float = 0.0) -> None:
        # the 100 % profile: rated speeds, full speed in accel_time_s
        self.vcap = list(MAX_SPEED_DEG_S)
        self.acap = [v / accel_time_s for v in MAX_SPEED_DEG_S]
        self.min_move_s = min_move_s  # V+'s shortest joint motion (plan seconds)
        self.rate = monitor_speed / 100.0  # plan seconds per second of the caller's clock
        self.accel_time_s = accel_time_s
        self._feed = 0.0  # the path's pace: the share of its segments' full speed
        self.q = [float(x) for x in q0]
        self.v = [0.0] * N_JOINTS
        self.ref = list(self.q)  # where the commanded path is now
        self.queue: deque[Move] = deque()
        self.open = False  # a stream is under way: running dry is an underrun
        self.executed = 0
        self.underruns = 0
        self.longest_segment_s = 0.0  # the longest segment's time at full speed, at the monitor speed
        self.longest_segment_deg = [0.0] * N_JOINTS  # each joint's largest travel in one MOVE
        self.ran_on_s = 0.0  # from the arrival of the last point (or stop) to rest, the last time
        self.max_ran_on_s = 0.0
        self.peak_speed = [0.0] * N_JOINTS  # the largest |velocity| each joint reached, deg/s
        self.peak_accel = [0.0] * N_JOINTS  # ... and |acceleration| outside a controller stop, deg/s²
        self.t = now
        self._seg: tuple[list[float], Move, float, float] | None = None  # (from, move, done share, T)
        self._ran_dry = False  # the path reached its last point with nothing issued after it
        self._decel: tuple[float, ...] | None = None  # braking to rest, per joint (E-stop, drives off)
        self._last_word_t: float | None = None  # arrival of the last point or stop before rest
        self._started_t: float | None = None  # when the arm last left rest (the caller's clock)
        self.last_motion_s = 0.0  # from leaving rest to rest, the last time (the caller's clock)
        self.ran_on_deg = 0.0  # the largest joint travel from the last point's arrival to rest, the last time
        self.max_ran_on_deg = 0.0
        self._word_q: list[float] | None = None  # where the arm was when the last point arrived

    # ---- commands --------------------------------------------------------
    @property
    def room(self) -> bool:
        """A MOVE may be issued now (none waits behind the running one)."""
        return len(self.queue) < AHEAD

    def issue(self, move: Move) -> None:
        self.queue.append(move)
        self.open = True
        self._last_word_t = move.arrived_t

    def heard(self, arrived_t: float) -> None:
        """A point that moves nothing arrived (a stop): the arm runs on from here."""
        self._last_word_t = arrived_t

    def bytes_came(self) -> None:
        """Bytes arrived on the motion connection now (the arm advanced to now): the run-on
        in degrees is counted from where the arm is."""
        self._word_q = list(self.q)

    def set_monitor_speed(self, monitor_speed: float, now: float) -> None:
        """The pendant's monitor speed changes: it takes effect at once (V+ SPEED)."""
        self.advance(now)
        self.rate = monitor_speed / 100.0

    def brake(self, decel: Iterable[float], now: float) -> int:
        """The controller's own stop (E-stop, drives off) at ``now``: every issued MOVE dropped,
        the joints braked to rest with these decelerations (deg/s²) from where they are; how
        many were dropped."""
        self.advance(now)
        dropped = len(self.queue) + (self._seg is not None)
        self.queue.clear()
        self._seg = None
        self._feed = 0.0
        self.open = False
        if not any(self.v):  # already at rest: nothing to brake, it stays where it is
            self._decel = None
            self.ref = list(self.q)
            return dropped
        if self._decel is not None:  # already braking (say for an E-stop): never softer
            decel = map(max, self._decel, decel)
        self._decel = tuple(decel)
        return dropped

    def close_stream(self) -> None:
        """The client went away: what is issued still runs, but running dry is no underrun."""
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

    def segment_time(self, start: Sequence[float], target: Sequence[float]) -> float:
        """How long the path takes from start to target at 100 % (the slowest joint's time,
        at least the minimum time of a motion), plan seconds."""
        travel = max(abs(b - a) / v for a, b, v in zip(start, target, self.vcap, strict=True))
        return max(travel, self.min_move_s) if travel > 0 else 0.0

    # ---- time ----------------------------------------------------------------
    def advance(self, now: float) -> None:
        if not self.in_motion:  # at rest: nothing to integrate
            self.t = max(self.t, now)
            return
        if now - self.t > MAX_CATCH_UP_S:
            self.t = now - MAX_CATCH_UP_S
        while True:
            # a step of DT on the plan's clock lasts DT / rate on the caller's: the monitor speed
            # stretches time, the motion stays the same; a controller stop brakes on the caller's
            braking = self._decel is not None
            wall = DT if braking else DT / self.rate
            if self.t + wall > now:
                return
            if self._started_t is None:
                self._started_t = self.t
            if braking:
                self._brake_step(DT)
            else:
                self._step(DT)
            self.t += wall
            if not self.in_motion:
                self._rested(self.t)
                self.t = max(self.t, now)
                return

    def _rested(self, t: float) -> None:
        if self._last_word_t is not None:
            self.ran_on_s = max(0.0, t - self._last_word_t)
            self.max_ran_on_s = max(self.max_ran_on_s, self.ran_on_s)
            self._last_word_t = None
        if self._word_q is not None:
            self.ran_on_deg = max(abs(a - b) for a, b in zip(self.q, self._word_q, strict=True))
            self.max_ran_on_deg = max(self.max_ran_on_deg, self.ran_on_deg)
            self._word_q = None
        if self._started_t is not None:
            self.last_motion_s = t - self._started_t
            self._started_t = None
        self._ran_dry = False

    def _stopped_at_point(self) -> bool:
        """At rest at the end of the path, as V+ would call a motion done (within a small
        tolerance, not the servo's last exponential approach)."""
        return all(abs(v) <= a * DT and abs(r - q) <= STOPPED_DEG
                   for v, a, r, q in zip(self.v, self.acap, self.ref, self.q, strict=True))

    def _remaining_s(self) -> float:
        """The path still to run at full feed: the rest of the running segment and the issued ones."""
        left = 0.0
        at = self.ref
        if self._seg is not None:
            r0, move, u, duration = self._seg
            left, at = (1.0 - u) * duration, list(move.q)
        for m in self.queue:
            left += self.segment_time(at, m.q)
            at = list(m.q)
        return left

    def _play(self, dt: float) -> list[float] | None:
        """Move the commanded path on by dt plan seconds; its joint velocities, or None at rest.

        The path is the issued segments one after the other, run at a feed (the share of each
        segment's full speed) that rises and falls at most 1 / accel_time per second (the
        limiting joint at its acceleration) and always leaves room to stop at the path's end:
        the arm stays on the path, never behind it by more than its servo's lag."""
        while self._seg is None:
            if not self.queue:
                self._feed = 0.0
                return None
            if self._ran_dry:  # issued after the path had ended: the arm stops first, then goes
                if not self._stopped_at_point():
                    return None
                self._ran_dry = False
            move = self.queue.popleft()
            duration = self._count(move)
            if duration <= 0:  # nowhere to go: done at once
                self.executed += 1
                self._ended()
                continue
            self._seg = (list(self.ref), move, 0.0, duration)
        alpha = BRAKE_MARGIN / self.accel_time_s  # the servo keeps some acceleration to close its lag
        brake = math.sqrt(2.0 * alpha * self._remaining_s())
        self._feed = max(min(1.0, self._feed + alpha * dt, brake), min(brake, alpha * dt))
        advance = self._feed * dt  # seconds of the path at full feed
        while self._seg is not None:
            r0, move, u, duration = self._seg
            left = (1.0 - u) * duration
            if advance < left:
                u += advance / duration
                self._seg = (r0, move, u, duration)
                self.ref = [a + (b - a) * u for a, b in zip(r0, move.q, strict=True)]
                return [(b - a) / duration * self._feed for a, b in zip(r0, move.q, strict=True)]
            advance -= left
            self.ref = list(move.q)
            self._seg = None
            self.executed += 1
            if not self.queue:
                self._ended()
                return None
            move = self.queue.popleft()  # the next MOVE continues where this one ended
            duration = self._count(move)
            if duration > 0:
                self._seg = (list(self.ref), move, 0.0, duration)
            else:
                self.executed += 1
        return None

    def _count(self, move: Move) -> float:
        """A MOVE begins from where the path is: its time at 100 % (the longest segments noted)."""
        duration = self.segment_time(self.ref, move.q)
        self.longest_segment_s = max(self.longest_segment_s, duration / self.rate)
        self.longest_segment_deg = [max(m, abs(b - a)) for m, a, b in
                                    zip(self.longest_segment_deg, self.ref, move.q, strict=True)]
        return duration

    def _ended(self) -> None:
        """The path reached its last issued point."""
        self._feed = 0.0
        if not self.queue:
            self._ran_dry = True
            if self.open:
                self.underruns += 1

    def _brake_step(self, dt: float) -> None:
        """One step of a controller stop: every joint braked at its deceleration (velocities
        kept in plan terms: the wall's velocity is v * rate)."""
        assert self._decel is not None
        for i in range(N_JOINTS):
            a = self._decel[i] * dt / self.rate
            self.v[i] -= max(-a, min(a, self.v[i]))
            self.q[i] += self.v[i] * self.rate * dt
        if not any(self.v):
            self._decel = None
            self.ref = list(self.q)

    def _step(self, dt: float) -> None:
        """One step of the plan clock (dt plan seconds): the path played on, the joints following."""
        rdot = self._play(dt)
        end = self.queue[-1].q if self.queue else self._seg[1].q if self._seg is not None else self.ref
        last_leg = not self.queue  # the path's last segment, or its end: it stops at `end`
        before = list(self.q)
        for i in range(N_JOINTS):
            e = self.ref[i] - self.q[i]
            a = self.acap[i]
            speed = min(
                self.vcap[i],
                (abs(rdot[i]) if rdot else 0.0) + KP * abs(e),
                math.sqrt(2.0 * BRAKE_MARGIN * a * abs(end[i] - self.q[i])),  # never past the point the path stops at
            )
            dv = max(-a * dt, min(a * dt, math.copysign(speed, e) - self.v[i]))
            self.v[i] += dv
            self.q[i] += self.v[i] * dt
            if last_leg and (end[i] - self.q[i]) * (end[i] - before[i]) < 0:  # never past where the path stops
                self.q[i], self.v[i] = end[i], 0.0
            # as the caller's clock sees them: speeds times the rate, accelerations times its square
            self.peak_speed[i] = max(self.peak_speed[i], abs(self.v[i]) * self.rate)
            self.peak_accel[i] = max(self.peak_accel[i], abs(dv) / dt * self.rate**2)
        if rdot is None and self._stopped_at_point():  # the servo's last bit: at the point
            self.q = list(self.ref)
            self.v = [0.0] * N_JOINTS
