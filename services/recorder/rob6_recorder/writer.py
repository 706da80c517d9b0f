"""MCAP writing: one file per client session plus a rolling system recording.

``Recorder`` is what the recorder service feeds::

    rec = Recorder("/var/lib/rob6/recordings", robot="kr16", robot_id="robot1",
                   urdf=urdf_text, fk=kinematics_fk)        # fk optional
    rec.start()
    rec.submit("/session/3/client_in", t_ns, {"session": 3, "cid": "ab12", "text": "GetRobot\\n"})
    ...
    rec.close()

``submit`` never blocks and never raises for a full queue: it appends to an
unbounded-by-type but *count-bounded* deque that a writer thread drains (in slices
while it keeps up, ``WRITE_SLICE``). Above
``warn_backlog`` queued records it logs a warning (at most once a second); at
``max_backlog`` it drops the record, counts it per topic, logs it, and the writer
thread writes the accounting into the recordings (``/recorder/status``) as soon as
it catches up - nothing is dropped silently.

Crash safety: the writer closes the open chunk every ``chunk_interval`` seconds
(default 0.5) and flushes it to the OS (plus ``fsync`` unless disabled), so after a
SIGKILL the file holds every record up to the last closed chunk (at most about
``chunk_interval`` plus the queue latency is lost). An unfinished file is readable
with ``rob6_recorder.reader`` and rebuilt into an indexed file by
``rob6_recorder.recover.recover``.

This module is the queue and its writer thread; which file a record goes to, file names
and rotation are ``files.RecordingFiles``, one file ``mcapfile.McapFile``, the derived
Foxglove channels (``/tf``, ``/flange``) ``derived_channels.JointStateDerivation``.
"""

from __future__ import annotations

import collections
import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from .derived_channels import JointStateDerivation
from .files import RecordingFiles
from .mcapfile import CHUNK_SIZE, as_dict, encode
from .schemas import to_foxglove_log
from .transforms import Fk

log = logging.getLogger("rob6.recorder")

JOINT_STATE_TOPIC = "/driver/joint_state"
LOG_TOPIC = "/log"
STATUS_TOPIC = "/recorder/status"

#: while the writer keeps up it writes this many records, then pauses, so its work comes in
#: slices of some 50 us with the CPU free between them: on this two-CPU machine a request
#: beside the writer waited for the whole of each burst (docs/PERFORMANCE.md, "The
#: recorder's writing")
WRITE_SLICE = 8
WRITE_PAUSE_S = 0.0002
#: with more than this queued (a burst, a slow disk) it writes without pausing
WRITE_PAUSE_BACKLOG = 2_000

_encoder = msgspec.json.Encoder()


@dataclass
class RecorderStats:
    submitted: int = 0
    written: int = 0  # records processed by the writer thread (one per submit)
    dropped: int = 0
    missed: int = 0  # trace batches lost on the way to the recorder (report_missed)
    dropped_by_topic: dict[str, int] = field(default_factory=dict)
    backlog: int = 0
    max_backlog_seen: int = 0
    errors: int = 0
    files: list[str] = field(default_factory=list)  # every file opened so far


_CLOSE_EVENTS = frozenset({"close", "closed", "disconnect", "disconnected", "end", "lost"})


class _Control:
    """A command for the writer thread, queued in order with the records."""

    __slots__ = ("kind", "arg", "done")

    def __init__(self, kind: str, arg: Any = None):
        self.kind = kind
        self.arg = arg
        self.done = threading.Event()


class Recorder:
    """Non-blocking front end: ``submit`` from any thread, one writer thread writes.

    Parameters (all keyword, all optional except the first three):
      ``urdf``: URDF text; stored as attachment ``robot.urdf`` and on
      ``/robot_description`` in every file (Foxglove's 3D panel loads it), and used to
      derive per-link ``/tf`` from ``/driver/joint_state`` (``joint_map``: per-axis
      ``(sign, offset_deg)``; ``tf_max_rate`` Hz, 0 = every joint state).
      ``fk``: callable ``fk(q_deg: list[float]) -> 12 numbers (3x4 row-wise, mm) | None``;
      gives ``/flange`` (foxglove.PosesInFrame) and a ``fk_flange`` frame on ``/tf``. It
      runs on the writer thread (at most ``tf_max_rate`` calls/s); if it raises, it is
      not called again (one warning).
      ``system`` / ``sessions``: write the rolling system file / per-session files.
      ``rotate_bytes`` / ``rotate_seconds``: system file rotation (0 disables).
      ``chunk_interval``: close a chunk at least this often (s); ``fsync`` after it.
      ``max_backlog``: queued records before dropping; ``warn_backlog``: warn above.
      ``session_linger``: keep a session file open this long after its close event
      so late bus traces of its last command still land in it.
      ``live``: ``live(topic, log_time, data, payload)`` is called on the writer thread
      after each record (derived ones included) went to the files: the live view
      (``live.LiveView.publish``). If it raises, it is not called again (one error).
    """

    def __init__(self, directory: str | os.PathLike[str], robot: str, robot_id: str, *,
                 urdf: str | None = None, fk: Fk | None = None,
                 joint_map: Sequence[tuple[float, float]] | None = None,
                 system: bool = True, sessions: bool = True,
                 rotate_bytes: int = 256 << 20, rotate_seconds: float = 3600.0,
                 chunk_interval: float = 0.5, chunk_size: int = CHUNK_SIZE,
                 compression: str = "zstd", fsync: bool = True,
                 max_backlog: int = 100_000, warn_backlog: int = 10_000,
                 session_linger: float = 0.5, tf_max_rate: float = 50.0,
                 metadata: dict[str, str] | None = None,
                 clock: Callable[[], int] = time.time_ns,
                 live: Callable[[str, int, Any, bytes], None] | None = None):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.chunk_interval = chunk_interval
        self.fsync = fsync
        self.max_backlog = max_backlog
        self.warn_backlog = warn_backlog
        self.clock = clock
        self._queue: collections.deque[Any] = collections.deque()
        self._wake = threading.Event()
        self._idle = False
        self._stop = False
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()  # drop accounting
        self._written = 0
        self._dropped = 0
        self._dropped_by_topic: dict[str, int] = {}
        self._drops_pending: dict[str, int] = {}
        self._first_drop_ns = 0
        self._last_drop_ns = 0
        self._missed = 0  # trace batches the bus reported lost on the way (report_missed)
        self._last_warn = 0.0
        self._last_drop_warn = 0.0
        self._max_seen = 0
        self._errors = 0
        self._last_error_log = 0.0
        # writer-thread state
        self._files = RecordingFiles(
            self.directory, robot, robot_id, urdf=urdf, system=system, sessions=sessions,
            rotate_bytes=rotate_bytes, rotate_seconds=rotate_seconds, chunk_size=chunk_size,
            compression=compression, session_linger=session_linger, metadata=dict(metadata or {}),
            clock=clock, on_error=self._error)
        self._derived = JointStateDerivation(urdf, fk, joint_map, tf_max_rate)
        self._live = live

    # ----------------------------------------------------------------- lifecycle
    def start(self) -> Recorder:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="rob6-recorder-writer",
                                            daemon=True)
            self._thread.start()
        return self

    def __enter__(self) -> Recorder:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self, timeout: float | None = 30.0) -> None:
        """Write everything queued, finish every file (summary, index) and stop."""
        if self._thread is None:
            self.start()  # write whatever was queued before start()
        self._stop = True
        self._wake.set()
        assert self._thread is not None  # started above
        self._thread.join(timeout)
        if self._thread.is_alive():
            log.error("recorder writer did not finish within %s s (%d records queued)",
                      timeout, len(self._queue))
            return
        # a submit that raced with close() may have queued after the last drain: count it
        late = [item for item in self._queue if type(item) is tuple]
        self._queue.clear()
        for topic, log_time, _, _ in late:
            self._drop(topic, log_time, 0)

    # ----------------------------------------------------------------- hot path
    def submit(self, topic: str, log_time: int, data: Any,
               publish_time: int | None = None) -> bool:
        """Queue one record; never blocks. False if it had to be dropped (counted, logged).

        ``data``: a JSON-serialisable dict/list, a msgspec Struct, or JSON bytes.
        """
        n = len(self._queue)
        if n >= self.warn_backlog or self._stop:
            if n >= self.max_backlog or self._stop:
                self._drop(topic, log_time, n)
                return False
            self._warn_backlog(n)
        self._queue.append((topic, log_time, log_time if publish_time is None else publish_time,
                            data))
        if self._idle:
            self._wake.set()
        return True

    def _drop(self, topic: str, log_time: int, n: int) -> None:
        now = time.monotonic()
        with self._lock:
            self._dropped += 1
            self._dropped_by_topic[topic] = self._dropped_by_topic.get(topic, 0) + 1
            self._drops_pending[topic] = self._drops_pending.get(topic, 0) + 1
            if not self._first_drop_ns:
                self._first_drop_ns = log_time
            self._last_drop_ns = log_time
            warn = now - self._last_drop_warn >= 1.0
            if warn:
                self._last_drop_warn = now
            total = self._dropped
        if warn:
            if self._stop:
                log.warning("recorder closed: dropping records, %d dropped so far", total)
            else:
                log.warning("recorder backlog full (%d records queued, limit %d): dropping "
                            "records, %d dropped so far", n, self.max_backlog, total)
        self._wake.set()

    def report_missed(self, source: str, count: int) -> None:
        """``count`` batches of records from ``source`` never reached this recorder (the
        bus detected the gap and could not recover them): logged, and written on
        ``/recorder/status`` in order with the records. Never blocks; any thread."""
        with self._lock:
            self._missed += count
            total = self._missed
        log.warning("recorder missed %d trace batches from %s (%d in total)", count, source, total)
        now = self.clock()
        self.submit(STATUS_TOPIC, now, {"missed": count, "missed_source": source, "missed_total": total})

    def _warn_backlog(self, n: int) -> None:
        now = time.monotonic()
        if now - self._last_warn >= 1.0:
            self._last_warn = now
            log.warning("recorder falling behind: %d records queued (drops start at %d)",
                        n, self.max_backlog)

    # ----------------------------------------------------------------- control
    def _control(self, kind: str, arg: Any = None, wait: float | None = None) -> bool:
        item = _Control(kind, arg)
        self._queue.append(item)
        self._wake.set()
        if wait is None or self._thread is None:
            return True
        return item.done.wait(wait)

    def flush(self, timeout: float = 10.0) -> bool:
        """Block until every record submitted before is written and flushed to the OS."""
        return self._control("flush", None, timeout)

    def open_session(self, session: int | str) -> None:
        """Start a session file now (otherwise it starts with the session's first record)."""
        self._control("open_session", str(session))

    def close_session(self, session: int | str) -> None:
        """Finish a session file (after ``session_linger``)."""
        self._control("close_session", str(session))

    def stats(self) -> RecorderStats:
        with self._lock:
            queued = sum(1 for item in list(self._queue) if type(item) is tuple)
            return RecorderStats(
                submitted=self._written + queued, written=self._written, dropped=self._dropped,
                missed=self._missed, dropped_by_topic=dict(self._dropped_by_topic), backlog=len(self._queue),
                max_backlog_seen=self._max_seen, errors=self._errors, files=self._files.paths())

    # ----------------------------------------------------------------- writer thread
    def _run(self) -> None:
        try:
            self._loop()
        except BaseException:  # never expected: keep the files finished and say so
            log.exception("recorder writer thread failed; finishing the files")
            self._stop = True
        finally:
            self._finish_all()

    def _loop(self) -> None:
        queue = self._queue
        last_flush = time.monotonic()
        while True:
            n = len(queue)
            self._max_seen = max(self._max_seen, n)
            if n:
                for k in range(min(n, 20_000)):
                    if k and k % WRITE_SLICE == 0 and len(queue) < WRITE_PAUSE_BACKLOG and not self._stop:
                        time.sleep(WRITE_PAUSE_S)
                    item = queue.popleft()
                    if type(item) is tuple:
                        try:
                            self._write_record(*item)
                        except Exception as exc:
                            self._error("writing a record on %s failed: %r", item[0], exc)
                        self._written += 1
                    else:
                        self._handle_control(item)
                    if time.monotonic() - last_flush >= self.chunk_interval:
                        break
            if self._drops_pending:
                self._write_drop_status()
            now = time.monotonic()
            if now - last_flush >= self.chunk_interval:
                self._files.flush(self.fsync)
                try:
                    self._files.housekeeping(now, self._dropped)
                except Exception as exc:
                    self._error("recorder housekeeping failed: %r", exc)
                last_flush = time.monotonic()
            if not queue:
                if self._stop:
                    break
                self._wake.clear()
                self._idle = True
                if not queue:
                    self._wake.wait(min(self.chunk_interval, 0.25))
                self._idle = False

    def _error(self, fmt: str, *args: object) -> None:
        self._errors += 1
        now = time.monotonic()
        if now - self._last_error_log >= 1.0:
            self._last_error_log = now
            log.error(fmt, *args)

    def _write_record(self, topic: str, log_time: int, publish_time: int, data: Any) -> None:
        if topic == LOG_TOPIC:
            data = as_dict(data)
            if isinstance(data, dict):
                data = to_foxglove_log(data, log_time)
        closing = False
        if topic.endswith("/event") and self._files.session_of(topic) is not None:
            ev = as_dict(data)
            closing = isinstance(ev, dict) and str(ev.get("event", "")).lower() in _CLOSE_EVENTS
        payload = encode(data)
        self._files.write(topic, log_time, publish_time, payload, closing=closing)
        if self._live is not None:
            try:
                self._live(topic, log_time, data, payload)
            except Exception as exc:  # the live view must not stop the recording
                self._live = None
                self._error("live view failed (%r): no live view from now on", exc)
        if topic == JOINT_STATE_TOPIC and self._derived.active:
            for derived_topic, payload in self._derived.derive(data, log_time):
                self._write_record(derived_topic, log_time, log_time, payload)

    def _write_drop_status(self) -> None:
        with self._lock:
            pending, self._drops_pending = self._drops_pending, {}
            status = {"submitted": self._written + len(self._queue), "written": self._written,
                      "dropped": self._dropped, "dropped_since_last": pending,
                      "backlog": len(self._queue), "max_backlog_seen": self._max_seen,
                      "first_drop_ns": self._first_drop_ns, "last_drop_ns": self._last_drop_ns}
        log.warning("recorder dropped %d records (%s); %d in total",
                    sum(pending.values()), ", ".join(f"{t}: {c}" for t, c in pending.items()),
                    status["dropped"])
        now = self.clock()
        try:
            self._write_record(STATUS_TOPIC, now, now, _encoder.encode(status))
        except Exception as exc:
            self._error("writing the drop status failed: %r", exc)

    def _handle_control(self, item: _Control) -> None:
        try:
            if item.kind == "flush":
                self._files.flush(self.fsync)
            elif item.kind == "open_session":
                self._files.open_session(item.arg)
            elif item.kind == "close_session":
                self._files.close_session(item.arg)
        except Exception as exc:
            self._error("recorder control %s failed: %r", item.kind, exc)
        finally:
            item.done.set()

    def _finish_all(self) -> None:
        if self._drops_pending:
            self._write_drop_status()
        self._files.finish(self._dropped)
