"""Which file a record goes to, and when files start and end.

One file per client session (``/session/<n>/...`` records, plus everything else that
happens while it is open) and a rolling system file (everything), rotated when it is
``rotate_seconds`` old or ``rotate_bytes`` large. A session file lingers
``session_linger`` seconds after its close event, so late bus traces of its last command
still land in it; late records of a finished session go to the system file only. Early
ones are kept too: each service sends its traces in batches of its own, and two services'
batches reach the recorder in either order, so the bus trace of a session's first command
can come before the gateway's open event. The last ``SESSION_BACKLOG_S`` of records are
kept, and a session file that opens starts with those logged at or after its start.

File names: ``<UTC start %Y%m%dT%H%M%SZ>_<robot>_<robot_id>_session<n>.mcap`` and
``..._system_<part>.mcap`` (part 001, 002, ... counts the rotations of this recorder
run; a ``-2``, ``-3`` suffix if the name exists anyway).

Used by the recorder's writer thread only (``paths`` excepted).
"""

from __future__ import annotations

import collections
import datetime as _dt
import logging
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from . import __version__
from .mcapfile import McapFile

log = logging.getLogger("rob6.recorder")

#: how long records that belong to no session are kept for a session file that opens
#: later (see the module's text): far more than two services' trace batches apart (5 ms)
SESSION_BACKLOG_S = 2.0


def utc_stamp(ns: int) -> str:
    return _dt.datetime.fromtimestamp(ns / 1e9, _dt.UTC).strftime("%Y%m%dT%H%M%SZ")


def _safe(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "-" for c in str(text)) or "x"


class RecordingFiles:
    """The open files of one recorder and the routing of records to them."""

    def __init__(self, directory: Path, robot: str, robot_id: str, *, urdf: str | None,
                 system: bool, sessions: bool, rotate_bytes: int, rotate_seconds: float,
                 chunk_size: int, compression: str, session_linger: float,
                 metadata: dict[str, str], clock: Callable[[], int],
                 on_error: Callable[..., None]):
        self.directory = directory
        self.robot = robot
        self.robot_id = robot_id
        self.urdf = urdf
        self.system = system
        self.sessions = sessions
        self.rotate_bytes = rotate_bytes
        self.rotate_seconds = rotate_seconds
        self.chunk_size = chunk_size
        self.compression = compression
        self.session_linger = session_linger
        self.extra_metadata = metadata
        self.clock = clock
        self._error = on_error
        self._system: McapFile | None = None
        self._sessions: dict[str, McapFile] = {}
        self._finished: collections.OrderedDict[str, None] = collections.OrderedDict()
        self._closing: dict[str, float] = {}  # session -> monotonic close time
        self._session_of_topic: dict[str, str | None] = {}
        # (arrival, topic, log_time, publish_time, payload) of the last SESSION_BACKLOG_S
        self._recent: collections.deque[tuple[float, str, int, int, bytes]] = collections.deque()
        self._paths_lock = threading.Lock()
        self._paths: list[str] = []
        self._part = 0  # system file part number (sorts chronologically within a second)

    def paths(self) -> list[str]:
        """Every file opened so far (any thread)."""
        with self._paths_lock:
            return list(self._paths)

    def session_of(self, topic: str) -> str | None:
        """The session a topic belongs to (``/session/<n>/...``), else None."""
        try:
            return self._session_of_topic[topic]
        except KeyError:
            key = None
            if topic.startswith("/session/"):
                key = topic.split("/", 3)[2] or None
            self._session_of_topic[topic] = key
            return key

    def write(self, topic: str, log_time: int, publish_time: int, payload: bytes, *,
              closing: bool = False) -> None:
        """Write one record where it belongs; ``closing``: it is its session's close event."""
        session = self.session_of(topic)
        if session is not None:
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
            if self.sessions:
                self._remember(topic, log_time, publish_time, payload)
        if self.system:
            f = self._system
            if f is None:
                f = self._system = self._open_system(log_time)
            f.write(topic, log_time, publish_time, payload)

    def open_session(self, session: str) -> None:
        if session not in self._sessions and self.sessions:
            self._open_session(session, self.clock())
        self._closing.pop(session, None)

    def close_session(self, session: str) -> None:
        if session in self._sessions:
            self._closing[session] = time.monotonic() + self.session_linger

    def flush(self, fsync: bool) -> None:
        for f in self._open_files():
            if f.pending:
                try:
                    f.flush(fsync)
                except Exception as exc:
                    self._error("flushing %s failed: %r", f.path, exc)

    def housekeeping(self, now: float, dropped_total: int) -> None:
        """End the session files whose linger is over, rotate the system file."""
        for session, when in list(self._closing.items()):
            if now >= when:
                del self._closing[session]
                f = self._sessions.pop(session, None)
                if f is not None:
                    self._close_file(f, dropped_total)
                    self._finished[session] = None
                    while len(self._finished) > 10_000:
                        self._finished.popitem(last=False)
        f = self._system
        if f is not None and (
                (self.rotate_seconds and now - f.opened >= self.rotate_seconds)
                or (self.rotate_bytes and f.size() >= self.rotate_bytes)):
            self._close_file(f, dropped_total)
            self._system = None  # the next record opens the next part

    def finish(self, dropped_total: int) -> None:
        """Finish every open file (summary, index)."""
        for f in self._open_files():
            self._close_file(f, dropped_total)
        self._sessions.clear()
        self._system = None

    # ----------------------------------------------------------------- files
    def _open_files(self) -> list[McapFile]:
        files = list(self._sessions.values())
        if self._system is not None:
            files.append(self._system)
        return files

    def _close_file(self, f: McapFile, dropped_total: int) -> None:
        try:
            f.close({"ended": utc_stamp(self.clock()), "messages": f.messages,
                     "dropped_total": dropped_total})
        except Exception as exc:
            self._error("closing %s failed: %r", f.path, exc)

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
        with self._paths_lock:
            self._paths.append(str(path))
        log.info("recording %s to %s", kind if session is None else f"session {session}", path)
        return f

    def _open_session(self, session: str, start_ns: int) -> McapFile:
        self._finished.pop(session, None)
        f = self._sessions[session] = self._open("session", start_ns, session)
        for _, topic, log_time, publish_time, payload in self._recent:
            if log_time >= start_ns:  # came before the session's first record, logged after it
                f.write(topic, log_time, publish_time, payload)
        return f

    def _remember(self, topic: str, log_time: int, publish_time: int, payload: bytes) -> None:
        now = time.monotonic()
        recent = self._recent
        while recent and recent[0][0] < now - SESSION_BACKLOG_S:
            recent.popleft()
        recent.append((now, topic, log_time, publish_time, payload))

    def _open_system(self, start_ns: int) -> McapFile:
        return self._open("system", start_ns, None)
