"""A recording played back at its recorded pace: into the live view, or its joint states.

``rob6-log play FILE`` (``Player``): into the live view, seekable from Foxglove. The file's records go out on the same channels as live (``live.LiveView``), at their
recorded pace divided by the speed, so a Foxglove layout made for the live robot plays the
recording: the 3D panel moves the arm (``/tf`` as recorded, or derived from the joint states
when the file has none), the Log panel shows ``/commands`` and ``/log``. The server offers
Foxglove's playback control (``playback_time_range``): play, pause, speed and seeking on
the app's timeline. After a seek the last state before the new position (URDF, ``/tf``,
joint state, gripper, link, the cell and its clearance) is sent at once, so the picture is
right before the next record.

Works on unfinished files (``reader.scan``): a recording cut by a crash plays up to its
last complete chunk.

``rob6-log replay-joints FILE`` (``replay_joints``): the recorded joint states, one by one
at the recorded pace, to a callback.
"""

from __future__ import annotations

import bisect
import json
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from foxglove.websocket import PlaybackCommand, PlaybackControlRequest, PlaybackState, PlaybackStatus

from rob6.config import DEFAULT_LIVE_PORT
from rob6_recorder_native import ROBOT_DESCRIPTION_TOPIC

from .derived_channels import TF_TOPIC, JointStateDerivation
from .live import COMMANDS_TOPIC, LATCHED, OWN_LATCHED, LiveView
from .reader import RecordingReader
from .writer import JOINT_STATE_TOPIC

log = logging.getLogger("rob6.recorder.play")

#: how often the app's clock is updated while playing (s)
TIME_PERIOD = 0.05


@dataclass(frozen=True)
class Item:
    topic: str
    log_time: int
    payload: bytes


def load(path: str | Path) -> tuple[list[Item], str | None]:
    """The records of a recording in log-time order (JSON payloads as recorded) and its URDF.
    Without ``/tf`` in the file but with a URDF, ``/tf`` is derived from the joint states."""
    reader = RecordingReader(path)
    items = [Item(r.topic, r.log_time, bytes(r.data)) for r in reader.records(decode=False)]
    urdf = next((bytes(a.data).decode() for a in reader.attachments if a.name == "robot.urdf"), None)
    if urdf is None:
        for item in items:
            if item.topic == ROBOT_DESCRIPTION_TOPIC:
                urdf = json.loads(item.payload).get("data")
                break
    items = [i for i in items if i.topic != ROBOT_DESCRIPTION_TOPIC]  # the view publishes its own
    if urdf and not any(i.topic == TF_TOPIC for i in items):
        derive = JointStateDerivation(urdf, None)
        derived: list[Item] = []
        for item in items:
            derived.append(item)
            if item.topic == JOINT_STATE_TOPIC:
                derived += [Item(t, item.log_time, p) for t, p in derive.derive(item.payload, item.log_time)]
        items = derived
    items.sort(key=lambda i: i.log_time)  # stable: write order among equal times
    return items, urdf


class Player:
    """Plays ``items`` into a ``LiveView`` it starts; ``run()`` until stopped (or the end)."""

    def __init__(self, items: list[Item], urdf: str | None, *, host: str = "127.0.0.1", port: int = DEFAULT_LIVE_PORT,
                 speed: float = 1.0, paused: bool = False, loop: bool = False, name: str = "rob6 playback",
                 clock: Callable[[], float] = time.monotonic):
        if not items:
            raise ValueError("nothing to play: the recording has no messages")
        self.items = items
        self.times = [i.log_time for i in items]
        self.start_ns, self.end_ns = self.times[0], self.times[-1]
        self.speed = speed
        self.loop = loop
        self.clock = clock
        self.index = 0
        self.playing = not paused
        self.ended = False
        self._cond = threading.Condition()
        self._stop = False
        self._anchor: tuple[float, int] = (clock(), self.start_ns)  # wall clock <-> log time
        self._pending_seek: int | None = None  # the latched state is to be sent for a seek
        self._seek_time: int | None = None  # where a seek put the playback, until the next record
        self.view = LiveView(host=host, port=port, urdf=urdf, name=name,
                             playback_time_range=(self.start_ns, self.end_ns),
                             playback_handler=self.on_control, clock=lambda: self.start_ns)
        topics = list(dict.fromkeys(i.topic for i in items))
        if any(t.startswith("/session/") for t in topics):
            topics.append(COMMANDS_TOPIC)
        self.view.advertise(topics)  # all of them at once: a paused playback has its channels too

    # ---------------------------------------------------------------- control (server thread)
    def on_control(self, request: PlaybackControlRequest) -> PlaybackState:
        with self._cond:
            did_seek = request.seek_time is not None
            if request.playback_speed > 0:
                self.speed = float(request.playback_speed)
            if request.seek_time is not None:
                self._seek(int(request.seek_time))
            self.playing = request.playback_command == PlaybackCommand.Play
            if self.playing and self.ended:  # play at the end: from the start again
                self._seek(self.start_ns)
            self._anchor = (self.clock(), self.current_ns())
            self._cond.notify_all()
            return self._state(did_seek, request.request_id)

    def _seek(self, t: int) -> None:
        t = min(max(t, self.start_ns), self.end_ns)
        self.index = bisect.bisect_left(self.times, t)
        self.ended = False
        self._pending_seek = t
        self._seek_time = t

    def current_ns(self) -> int:
        if self._seek_time is not None:
            return self._seek_time
        if self.index < len(self.times):
            return self.times[self.index]
        return self.end_ns

    def _state(self, did_seek: bool = False, request_id: str | None = None) -> PlaybackState:
        status = (PlaybackStatus.Ended if self.ended else
                  PlaybackStatus.Playing if self.playing else PlaybackStatus.Paused)
        return PlaybackState(status=status, current_time=self.current_ns(), playback_speed=self.speed,
                             did_seek=did_seek, request_id=request_id)

    def stop(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()

    # ---------------------------------------------------------------- playing (own thread)
    def run(self, exit_at_end: bool = False) -> None:
        """Play until ``stop()`` (or, with ``exit_at_end``, the end of the recording)."""
        last_time = 0.0
        try:
            while True:
                with self._cond:
                    if self._stop:
                        return
                    if self._pending_seek is not None:
                        self._publish_state_before(self.index)
                        self._pending_seek = None
                    if not self.playing or self.ended:
                        self._cond.wait(0.1)
                        continue
                    if self.index >= len(self.items):
                        if self.loop:
                            self._seek(self.start_ns)
                            self._anchor = (self.clock(), self.start_ns)
                            continue
                        self.ended = True
                        self.view.server.broadcast_playback_state(self._state())
                        if exit_at_end:
                            return
                        continue
                    item = self.items[self.index]
                    wall0, log0 = self._anchor
                    due = wall0 + (item.log_time - log0) / 1e9 / self.speed
                    wait = due - self.clock()
                    if wait > 0:
                        self._cond.wait(min(wait, TIME_PERIOD))  # a control request wakes it
                        if self.clock() - last_time >= TIME_PERIOD:
                            last_time = self.clock()
                            self.view.broadcast_time(self._now_ns())
                        continue
                    self._seek_time = None
                    self.index += 1
                self.view.publish(item.topic, item.log_time, item.payload, item.payload)
                if self.clock() - last_time >= TIME_PERIOD:
                    last_time = self.clock()
                    self.view.broadcast_time(item.log_time)
        finally:
            self.view.close()

    def _now_ns(self) -> int:
        wall0, log0 = self._anchor
        return min(self.end_ns, int(log0 + (self.clock() - wall0) * 1e9 * self.speed))

    def _publish_state_before(self, index: int) -> None:
        """The last message of each latched topic before ``index`` (after a seek)."""
        self.view.clear_latched()
        found: dict[str, Item] = {}
        for item in reversed(self.items[:index]):
            if item.topic in LATCHED and item.topic not in found:
                found[item.topic] = item
                if len(found) == len(LATCHED - OWN_LATCHED):
                    break
        for item in sorted(found.values(), key=lambda i: i.log_time):
            self.view.publish(item.topic, item.log_time, item.payload, item.payload)
        self.view.broadcast_time(self.current_ns())


def play(path: str | Path, **options: Any) -> Player:
    """A ``Player`` serving the recording at ``path`` (not started: call ``run()``)."""
    items, urdf = load(path)
    return Player(items, urdf, name=f"rob6 playback {Path(path).name}", **options)


# --------------------------------------------------------------------------- joint states
def replay_joints(path: str | os.PathLike[str], publish: Callable[[dict[str, Any]], Any], *,
                  speed: float | None = 1.0, topic: str = "/driver/joint_state",
                  stop: Callable[[], bool] | None = None,
                  sleep: Callable[[float], Any] = time.sleep,
                  clock: Callable[[], float] = time.monotonic) -> int:
    """Call ``publish(state)`` for every recorded joint state, paced like the recording
    (``speed`` 2.0 = twice as fast, ``None``/0 = as fast as possible). Returns the count.
    ``stop()`` returning True ends it early."""
    count = 0
    t0 = None
    start = clock()
    for rec in RecordingReader(path).records([topic]):
        if stop is not None and stop():
            break
        if t0 is None:
            t0 = rec.log_time
        if speed:
            delay = start + (rec.log_time - t0) / 1e9 / speed - clock()
            if delay > 0:
                sleep(delay)
        publish(rec.data)
        count += 1
    return count
