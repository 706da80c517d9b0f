"""The recorder service: everything on the robot's bus into MCAP files.

It subscribes to what is published live (``rob6.bus.LIVE_TOPICS``: control messages, the
planner's settings) and to the trace batches. Services publish a copy of each request/reply they
served (``trace/<service>/<op>``), the gateway a copy of each client line and reply
(``trace/gateway/session``) and of each session's start and end, in batches
(``trace/<service>``, see ``rob6.bus``), and so do the driver and the gripper with each
state they publish (``Bus.publish_state``). ``Recorder.submit`` never blocks, so the
Zenoh callback stays short.

What the robot is made of is recorded too: when a driver appears the recorder asks it for
its cell (the safety zones, ``rob6.cell``) and records it on ``/cell``, latched: at the start
of every file opened later as well, as the URDF is (``Recorder.submit``).

With ``live_port`` (not 0) the recorder also feeds the live view (``live.LiveView``, a
Foxglove WebSocket server): the same records, as they are queued for the files.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from typing import Any

from rob6.bus import LIVE_TOPICS, Bus, BusError
from rob6.messages import Cell, Empty
from rob6.robots import RobotModel

from .live import LiveView, start_live
from .writer import CELL_TOPIC, CLEARANCE_TOPIC, JOINT_STATE_TOPIC, Recorder

log = logging.getLogger("rob6.recorder")


# bus key (after rob6/<id>/) -> recording topic, for the streams recorded as they are; they
# are recorded from the trace batches (``Bus.publish_state``, ``Bus.trace``), never from their
# live copies, which are dropped under congestion and not kept for a recorder that was away
TOPICS = {"driver/state": JOINT_STATE_TOPIC, "driver/link": "/driver/link", "gripper/state": "/gripper/state",
          "driver/clearance": CLEARANCE_TOPIC}


class RecorderService:
    def __init__(self, bus: Bus, robot: RobotModel, directory: str, *, live_port: int = 0,
                 live_bind: str = "0.0.0.0", live_tls: tuple[str | None, str | None] = (None, None),
                 **options: Any) -> None:
        self.bus = bus
        urdf = robot.urdf
        self.live: LiveView | None = start_live(
            urdf, port=live_port, bind=live_bind, settings=bus.settings, tls_cert=live_tls[0],
            tls_key=live_tls[1], name=f"rob6 {robot.name} {bus.settings.robot_id}")
        self.recorder = Recorder(directory, robot.name, bus.settings.robot_id, urdf=urdf,
                                 live=self.live.publish if self.live is not None else None, **options)
        self._prefix = len(bus.prefix) + 1
        self._cell: Cell | None = None  # the last one recorded
        self._cell_lock = threading.Lock()

    def start(self) -> None:
        self.recorder.start()
        self._subscribers = [self.bus.subscribe(suffix, self.on_sample)
                             for suffix in sorted(LIVE_TOPICS - TOPICS.keys())]
        self.bus.on_liveliness(self._on_liveliness)
        if self.bus.instances("driver"):  # up before the recorder: its liveliness came before the listener
            self._on_liveliness("driver", "", True)
        self.bus.announce()
        # trace batches with what their publishers kept for a recorder that was away
        # (partitioned, restarted): a separate, advanced subscriber; the live topics' get the rest
        self._traces = self.bus.subscribe_traces(self.on_traces, self.recorder.report_missed)

    def stop(self) -> None:
        """Stop listening first, then write out what is queued (nothing arrives after the
        close), and say in one line that the recordings are closed: the line a user sees
        when rob6 stops."""
        self._traces.undeclare()
        for subscriber in self._subscribers:
            subscriber.undeclare()
        finished = self.recorder.close()
        if self.live is not None:
            self.live.close()
        stats = self.recorder.stats()
        if finished:  # the writer said what it could not finish, at ERROR
            lost = f", {stats.dropped} records dropped" if stats.dropped else ""
            print(f"rob6-recorder: recordings closed: {stats.written} records in {len(stats.files)} files "
                  f"in {self.recorder.directory}{lost}", file=sys.stderr, flush=True)

    def _on_liveliness(self, service: str, _instance: str, alive: bool) -> None:
        if service == "driver" and alive:  # not on Zenoh's thread: the request waits for a reply
            threading.Thread(target=self._driver_appeared, name="recorder-cell", daemon=True).start()

    def _driver_appeared(self) -> None:
        """Ask the driver for its cell and record it on ``/cell`` (latched) when it is new."""
        try:
            cell: Cell = self.bus.request("driver", "cell", Empty())
        except BusError as exc:
            log.warning("could not get the driver's cell (safety zones) for the recording: %s", exc.message)
            return
        with self._cell_lock:
            if cell == self._cell:
                return
            self._cell = cell
            self.recorder.submit(CELL_TOPIC, time.time_ns(), cell, latched=True)
        log.info("recording the cell %s: %d zones, %d tool shapes, sha256 %s", cell.source, len(cell.zones),
                 len(cell.tool), cell.sha256 or "(none)")

    def on_sample(self, key: str, payload: bytes) -> None:
        """A live publication (a control message, the planner's settings)."""
        self._record(key[self._prefix:], payload, time.time_ns())

    def on_traces(self, key: str, payload: bytes) -> None:
        """One ``trace/<service>`` batch of records: client lines and replies, session events
        and bus traces are split and queued natively (``Recorder.submit_batch``), the rest
        here."""
        now = time.time_ns()
        try:
            others = self.recorder.submit_batch(payload, now)
        except ValueError:
            log.warning("malformed trace batch on %s (%d bytes) kept as it is", key, len(payload))
            self.recorder.submit("/" + key[self._prefix:], now, payload)
            return
        for record_suffix, record in others:
            try:
                self._record(record_suffix, record, now)
            except Exception:  # one bad record must not cost the rest of its batch
                log.exception("could not record %s", record_suffix)

    def _record(self, suffix: str, payload: bytes, now: int) -> None:
        submit = self.recorder.submit
        topic = TOPICS.get(suffix)
        if topic:
            submit(topic, now, payload)
        elif suffix.startswith("log/"):
            submit("/log", now, payload)
        else:  # control messages, the planner's settings: kept as they are
            submit("/" + suffix, now, payload)
