"""MCAP writing: one file per client session plus a rolling system recording.

``Recorder`` is what the recorder service feeds::

    rec = Recorder("/var/lib/rob6/recordings", robot="kr16", robot_id="robot1",
                   urdf=urdf_text, fk=kinematics_fk)        # fk optional
    rec.start()
    rec.submit("/session/3/client_in", t_ns, {"session": 3, "cid": "ab12", "text": "GetRobot\\n"})
    ...
    rec.close()

``submit`` never blocks and never raises for a full queue: it appends to an
unbounded-by-type but *count-bounded* deque that a writer thread drains. Above
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

File names: ``<UTC start %Y%m%dT%H%M%SZ>_<robot>_<robot_id>_session<n>.mcap`` and
``..._system_<part>.mcap`` (part 001, 002, ... counts the rotations of this recorder
run; a ``-2``, ``-3`` suffix if the name exists anyway). The system file is rotated
when it is ``rotate_seconds`` old or ``rotate_bytes`` large.
"""

from __future__ import annotations

import collections
import datetime as _dt
import logging
import os
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from . import __version__
from .geometry import Fk, TfDeriver, flange_message
from .mcapwriter import LeanWriter
from .schemas import schema_for, to_foxglove_log

log = logging.getLogger("rob6.recorder")

JOINT_STATE_TOPIC = "/driver/joint_state"
LOG_TOPIC = "/log"
TF_TOPIC = "/tf"
FLANGE_TOPIC = "/flange"
STATUS_TOPIC = "/recorder/status"
ROBOT_DESCRIPTION_TOPIC = "/robot_description"
FK_FLANGE_FRAME = "fk_flange"

_encoder = msgspec.json.Encoder()
_decoder = msgspec.json.Decoder()


def utc_stamp(ns: int) -> str:
    return _dt.datetime.fromtimestamp(ns / 1e9, _dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")


def _safe(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "-" for c in str(text)) or "x"


def encode(data: Any) -> bytes:
    """JSON bytes of a record: dict/list/msgspec Struct, or bytes passed through."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        return bytes(data)
    try:
        return _encoder.encode(data)
    except (TypeError, msgspec.EncodeError):
        import json
        return json.dumps(data, default=repr).encode()


class McapFile:
    """One MCAP file: lazy channels (one JSON schema per channel type), JSON messages.

    Not thread safe: used by the recorder's writer thread (or a tool) only.
    """

    def __init__(self, path: str | os.PathLike[str], *, start_ns: int | None = None,
                 urdf: str | None = None, metadata: dict[str, dict[str, str]] | None = None,
                 chunk_size: int = 1 << 20, compression: str = "zstd"):
        self.path = Path(path)
        self.start_ns = time.time_ns() if start_ns is None else start_ns
        self.opened = time.monotonic()
        self._fh = open(self.path, "xb")
        self._w = LeanWriter(self._fh, chunk_size=chunk_size,
                             compression="" if compression == "none" else compression)
        self._w.start(profile="", library=f"rob6-recorder/{__version__}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: dict[int, int] = {}
        self.messages = 0
        self.pending = 0  # messages not yet flushed to the OS
        self.closed = False
        for name, values in (metadata or {}).items():
            self._w.add_metadata(name, {k: str(v) for k, v in values.items()})
        if urdf:
            self._w.add_attachment(create_time=self.start_ns, log_time=self.start_ns,
                                   name="robot.urdf", media_type="application/xml",
                                   data=urdf.encode())
            self.write(ROBOT_DESCRIPTION_TOPIC, self.start_ns, self.start_ns,
                       _encoder.encode({"data": urdf}))
        self.flush()

    def channel(self, topic: str) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            spec = schema_for(topic)
            sid = self._schemas.get(spec.name)
            if sid is None:
                sid = self._schemas[spec.name] = self._w.register_schema(
                    spec.name, "jsonschema", spec.data)
            ch = self._channels[topic] = self._w.register_channel(topic, "json", sid)
            self._seq[ch] = 0
        return ch

    def write(self, topic: str, log_time: int, publish_time: int, payload: bytes) -> None:
        ch = self._channels.get(topic) or self.channel(topic)
        seq = self._seq[ch] = (self._seq[ch] + 1) & 0xFFFFFFFF
        self._w.add_message(ch, log_time, payload, publish_time, seq)
        self.messages += 1
        self.pending += 1

    def add_metadata(self, name: str, values: dict[str, Any]) -> None:
        self._w.add_metadata(name, {k: str(v) for k, v in values.items()})

    def flush(self, fsync: bool = False) -> None:
        """Close the open chunk and hand everything to the OS (and the disk if fsync)."""
        self._w.flush()
        if fsync:
            os.fsync(self._fh.fileno())
        self.pending = 0

    def size(self) -> int:
        return self._w.tell()

    def close(self, metadata: dict[str, Any] | None = None) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            if metadata:
                self.add_metadata("rob6.end", metadata)
            self._w.finish()
            self._fh.flush()
            os.fsync(self._fh.fileno())
        finally:
            self._fh.close()


@dataclass
class RecorderStats:
    submitted: int = 0
    written: int = 0  # records processed by the writer thread (one per submit)
    dropped: int = 0
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
    """

    def __init__(self, directory: str | os.PathLike[str], robot: str, robot_id: str, *,
                 urdf: str | None = None, fk: Fk | None = None,
                 joint_map: Sequence[tuple[float, float]] | None = None,
                 system: bool = True, sessions: bool = True,
                 rotate_bytes: int = 256 << 20, rotate_seconds: float = 3600.0,
                 chunk_interval: float = 0.5, chunk_size: int = 1 << 20,
                 compression: str = "zstd", fsync: bool = True,
                 max_backlog: int = 100_000, warn_backlog: int = 10_000,
                 session_linger: float = 0.5, tf_max_rate: float = 50.0,
                 metadata: dict[str, str] | None = None,
                 clock: Callable[[], int] = time.time_ns):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.robot = robot
        self.robot_id = robot_id
        self.urdf = urdf
        self.fk = fk
        self.system = system
        self.sessions = sessions
        self.rotate_bytes = rotate_bytes
        self.rotate_seconds = rotate_seconds
        self.chunk_interval = chunk_interval
        self.chunk_size = chunk_size
        self.compression = compression
        self.fsync = fsync
        self.max_backlog = max_backlog
        self.warn_backlog = warn_backlog
        self.session_linger = session_linger
        self.tf_period_ns = int(1e9 / tf_max_rate) if tf_max_rate > 0 else 0
        self.extra_metadata = dict(metadata or {})
        self.clock = clock

        self._tf: TfDeriver | None = None
        if urdf:
            try:
                self._tf = TfDeriver(urdf, joint_map)
            except Exception as exc:  # a bad URDF must not stop the recording
                log.warning("URDF not usable for /tf (%s); recording without /tf", exc)
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
        self._last_warn = 0.0
        self._last_drop_warn = 0.0
        self._max_seen = 0
        self._errors = 0
        self._last_error_log = 0.0
        # writer-thread state
        self._system: McapFile | None = None
        self._sessions: dict[str, McapFile] = {}
        self._finished: collections.OrderedDict[str, None] = collections.OrderedDict()
        self._closing: dict[str, float] = {}  # session -> monotonic close time
        self._session_of_topic: dict[str, str | None] = {}
        self._last_tf_ns = -1 << 62
        self._fk_failed = False
        self._fk_pause = 0.0
        self._files: list[str] = []
        self._part = 0  # system file part number (sorts chronologically within a second)

    # ----------------------------------------------------------------- lifecycle
    def start(self) -> "Recorder":
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="rob6-recorder-writer",
                                            daemon=True)
            self._thread.start()
        return self

    def __enter__(self) -> "Recorder":
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
                dropped_by_topic=dict(self._dropped_by_topic), backlog=len(self._queue),
                max_backlog_seen=self._max_seen, errors=self._errors, files=list(self._files))

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
            if n > self._max_seen:
                self._max_seen = n
            if n:
                for _ in range(min(n, 20_000)):
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
                self._flush_all(self.fsync)
                try:
                    self._housekeeping(now)
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

    def _session_key(self, topic: str) -> str | None:
        try:
            return self._session_of_topic[topic]
        except KeyError:
            key = None
            if topic.startswith("/session/"):
                key = topic.split("/", 3)[2] or None
            self._session_of_topic[topic] = key
            return key

    def _write_record(self, topic: str, log_time: int, publish_time: int, data: Any) -> None:
        if topic == LOG_TOPIC:
            data = self._as_dict(data)
            if isinstance(data, dict):
                data = to_foxglove_log(data, log_time)
        payload = encode(data)
        session = self._session_key(topic)
        if session is not None:
            closing = False
            if topic.endswith("/event"):
                ev = self._as_dict(data)
                closing = isinstance(ev, dict) and str(ev.get("event", "")).lower() in _CLOSE_EVENTS
            f = self._sessions.get(session)
            if f is None and self.sessions and (session not in self._finished or (
                    topic.endswith("/client_in") or (topic.endswith("/event") and not closing))):
                # late records of a finished session go to the system file only; a new
                # line or open event with a reused number (gateway restarted) opens a file
                f = self._open_session(session, log_time)
            if f is not None:
                f.write(topic, log_time, publish_time, payload)
                if closing:
                    self._closing[session] = time.monotonic() + self.session_linger
        else:
            for f in self._sessions.values():
                f.write(topic, log_time, publish_time, payload)
        if self.system:
            f = self._system
            if f is None:
                f = self._system = self._open_system(log_time)
            f.write(topic, log_time, publish_time, payload)
        if topic == JOINT_STATE_TOPIC and (self._tf is not None or self.fk is not None):
            self._derive(data, log_time)

    @staticmethod
    def _as_dict(data: Any) -> Any:
        if isinstance(data, (bytes, bytearray, memoryview)):
            try:
                return _decoder.decode(data)
            except msgspec.DecodeError:
                return data
        if isinstance(data, msgspec.Struct):
            return msgspec.to_builtins(data)
        return data

    def _derive(self, data: Any, log_time: int) -> None:
        """/tf (URDF joints, plus ``fk_flange`` from the FK) and /flange from a joint state."""
        if log_time - self._last_tf_ns < self.tf_period_ns:
            return
        self._last_tf_ns = log_time
        data = self._as_dict(data)
        q = data.get("q") if isinstance(data, dict) else None
        if not q:
            return
        root = self._tf.root_frame if self._tf is not None else "base"
        tf = self._tf.transforms(q, log_time) if self._tf is not None else {"transforms": []}
        flange = None
        if self.fk is not None and not self._fk_failed and time.monotonic() >= self._fk_pause:
            began = time.monotonic()
            try:
                flange = flange_message(self.fk, q, log_time, root)
            except Exception as exc:
                self._fk_failed = True  # one warning, then no more FK calls
                log.warning("fk callable failed (%r): no /flange from now on", exc)
            took = time.monotonic() - began
            if took > 0.02:  # the writer thread must not wait on a slow FK (a remote call?)
                self._fk_pause = time.monotonic() + 5.0
                log.warning("fk callable took %.0f ms: /flange paused for 5 s", took * 1000)
            if flange is not None:
                pose = flange["poses"][0]
                tf["transforms"].append({
                    "timestamp": flange["timestamp"], "parent_frame_id": root,
                    "child_frame_id": FK_FLANGE_FRAME, "translation": pose["position"],
                    "rotation": pose["orientation"]})
        if tf["transforms"]:
            self._write_record(TF_TOPIC, log_time, log_time, _encoder.encode(tf))
        if flange is not None:
            self._write_record(FLANGE_TOPIC, log_time, log_time, _encoder.encode(flange))

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
                self._flush_all(self.fsync)
            elif item.kind == "open_session":
                if item.arg not in self._sessions and self.sessions:
                    self._open_session(item.arg, self.clock())
                self._closing.pop(item.arg, None)
            elif item.kind == "close_session":
                if item.arg in self._sessions:
                    self._closing[item.arg] = time.monotonic() + self.session_linger
        except Exception as exc:
            self._error("recorder control %s failed: %r", item.kind, exc)
        finally:
            item.done.set()

    def _flush_all(self, fsync: bool) -> None:
        for f in self._open_files():
            if f.pending:
                try:
                    f.flush(fsync)
                except Exception as exc:
                    self._error("flushing %s failed: %r", f.path, exc)

    def _open_files(self) -> list[McapFile]:
        files = list(self._sessions.values())
        if self._system is not None:
            files.append(self._system)
        return files

    def _housekeeping(self, now: float) -> None:
        for session, when in list(self._closing.items()):
            if now >= when:
                del self._closing[session]
                f = self._sessions.pop(session, None)
                if f is not None:
                    self._close_file(f)
                    self._finished[session] = None
                    while len(self._finished) > 10_000:
                        self._finished.popitem(last=False)
        f = self._system
        if f is not None and (
                (self.rotate_seconds and now - f.opened >= self.rotate_seconds)
                or (self.rotate_bytes and f.size() >= self.rotate_bytes)):
            self._close_file(f)
            self._system = None  # the next record opens the next part

    def _close_file(self, f: McapFile) -> None:
        try:
            f.close({"ended": utc_stamp(self.clock()), "messages": f.messages,
                     "dropped_total": self._dropped})
        except Exception as exc:
            self._error("closing %s failed: %r", f.path, exc)

    def _finish_all(self) -> None:
        if self._drops_pending:
            self._write_drop_status()
        for f in self._open_files():
            self._close_file(f)
        self._sessions.clear()
        self._system = None

    def _metadata(self, kind: str, start_ns: int, session: str | None) -> dict[str, Any]:
        info = {"robot": self.robot, "robot_id": self.robot_id, "kind": kind,
                "started": utc_stamp(start_ns), "start_ns": str(start_ns),
                "host": socket.gethostname(), "recorder": __version__}
        if session is not None:
            info["session"] = session
        info.update(self.extra_metadata)
        return {"rob6": info}

    def _new_path(self, start_ns: int, suffix: str) -> Path:
        base = f"{utc_stamp(start_ns)}_{_safe(self.robot)}_{_safe(self.robot_id)}_{suffix}"
        path = self.directory / f"{base}.mcap"
        n = 2
        while path.exists():
            path = self.directory / f"{base}-{n}.mcap"
            n += 1
        return path

    def _open(self, kind: str, start_ns: int, session: str | None) -> McapFile:
        if session is None:
            self._part += 1
            suffix = f"system_{self._part:03d}"
        else:
            suffix = f"session{_safe(session)}"
        path = self._new_path(start_ns, suffix)
        f = McapFile(path, start_ns=start_ns, urdf=self.urdf,
                     metadata=self._metadata(kind, start_ns, session),
                     chunk_size=self.chunk_size, compression=self.compression)
        with self._lock:
            self._files.append(str(path))
        log.info("recording %s to %s", kind if session is None else f"session {session}", path)
        return f

    def _open_session(self, session: str, start_ns: int) -> McapFile:
        self._finished.pop(session, None)
        f = self._sessions[session] = self._open("session", start_ns, session)
        return f

    def _open_system(self, start_ns: int) -> McapFile:
        return self._open("system", start_ns, None)
