"""MCAP writing: one file per client session plus a rolling system recording.

``Recorder`` is what the recorder service feeds::

    rec = Recorder("/var/lib/rob6/recordings", robot="kr16", robot_id="robot1",
                   urdf=urdf_text, fk=kinematics_fk)        # fk optional
    rec.start()
    rec.submit("/session/3/client_in", t_ns, {"session": 3, "cid": "ab12", "text": "GetRobot\\n"})
    ...
    rec.close()

``submit`` never blocks and never raises for a full queue. It makes the record's JSON payload,
derives what a joint state gives (``/tf``, ``/flange``: ``derived_channels``), hands the live
view its copy, and queues the record for the native writer (``rob6_recorder_native.Writer``,
services/recorder/native): a thread without Python that routes each record to its files (the
session's, the system file), rotates them, and writes them as MCAP. The routing, the file
names, crash safety and the drop accounting are described there. Above ``warn_backlog`` queued
records it logs a warning (at most once a second); at ``max_backlog`` it drops the record,
counts it per topic, logs it, and the writer writes the accounting into the recordings
(``/recorder/status``) as soon as it catches up - nothing is dropped silently.

``submit_batch`` takes a whole ``trace/<service>`` batch: the native writer splits it and makes
the records of client lines and replies, session events and bus traces itself
(services/recorder/native/src/batch.rs), so the recorder's Python does nothing per request;
the rest (joint states, link events, logs) comes back for ``submit``.

Why native: the recorder's Python per record, on its writer thread, cost the other processes'
requests their tail on a two-CPU robot PC (docs/PERFORMANCE.md, "The recorder's writing,
native").
"""

from __future__ import annotations

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

from rob6_recorder_native import ROBOT_DESCRIPTION_TOPIC, STATUS_TOPIC, Writer

from . import __version__
from .derived_channels import JointStateDerivation
from .payloads import as_dict, encode
from .schemas import record_schemas, schema_for, to_foxglove_log
from .transforms import Fk

log = logging.getLogger("rob6.recorder")

JOINT_STATE_TOPIC = "/driver/joint_state"
LOG_TOPIC = "/log"
#: the driver's cell (safety zones), latched; the nearest pair while the arm moves
CELL_TOPIC = "/cell"
CLEARANCE_TOPIC = "/driver/clearance"

#: a chunk is compressed when it holds this much (or at the writer's next flush): 32 KiB
#: keeps each compression to a fraction of a millisecond, where 1 MiB took milliseconds
#: of one CPU that a request beside it could not have (docs/PERFORMANCE.md, "The
#: recorder's writing"); the files grow by about a tenth for it (more chunk indexes)
CHUNK_SIZE = 32 << 10
#: zstd's fastest level, not its default 3: the chunks are JSON records much alike, which level
#: 1 packs within a few per cent of level 3 (a recording of 6,000 requests: 2.43 against 2.36
#: MB) for a fifth less CPU per record written (docs/PERFORMANCE.md, "What a record costs the
#: recorder, and zstd's fastest level")
ZSTD_LEVEL = 1

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


class Recorder:
    """Non-blocking front end: ``submit`` from any thread, the native writer writes.

    Parameters (all keyword, all optional except the first three):
      ``urdf``: URDF text; stored as attachment ``robot.urdf`` and on
      ``/robot_description`` in every file (Foxglove's 3D panel loads it), and used to
      derive per-link ``/tf`` from ``/driver/joint_state`` (``joint_map``: per-axis
      ``(sign, offset_deg)``; ``tf_max_rate`` Hz, 0 = every joint state).
      ``fk``: callable ``fk(q_deg: list[float]) -> 12 numbers (3x4 row-wise, mm) | None``;
      gives ``/flange`` (foxglove.PosesInFrame) and a ``fk_flange`` frame on ``/tf``. It
      runs in ``submit`` of a joint state (at most ``tf_max_rate`` calls/s); if it raises,
      it is not called again (one warning).
      ``system`` / ``sessions``: write the rolling system file / per-session files.
      ``rotate_bytes`` / ``rotate_seconds``: system file rotation (0 disables).
      ``chunk_interval``: close a chunk at least this often (s); ``fsync`` after it.
      ``max_backlog``: queued records before dropping; ``warn_backlog``: warn above.
      ``session_linger``: keep a session file open this long after its close event
      so late bus traces of its last command still land in it.
      ``live``: ``live(topic, log_time, data, payload)`` is called in ``submit`` for each
      record (derived ones included): the live view (``live.LiveView.publish``). If it
      raises, it is not called again (one error).
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
        self.clock = clock
        info = {"host": socket.gethostname(), "recorder": __version__}
        info.update(metadata or {})
        self._writer = Writer(
            str(self.directory), robot, robot_id, urdf=urdf,
            urdf_record=_encoder.encode({"data": urdf}) if urdf else None,
            metadata={k: str(v) for k, v in info.items()}, system=system, sessions=sessions,
            rotate_bytes=rotate_bytes, rotate_seconds=rotate_seconds, chunk_interval=chunk_interval,
            chunk_size=chunk_size, compression=compression, zstd_level=ZSTD_LEVEL, fsync=fsync,
            max_backlog=max_backlog, warn_backlog=warn_backlog, session_linger=session_linger,
            record_schemas=record_schemas())
        self._topics: set[str] = set()  # whose schema the writer has
        self._schema(ROBOT_DESCRIPTION_TOPIC)
        self._schema(STATUS_TOPIC)
        self._lock = threading.Lock()  # the derivation and the live view: one submit at a time
        self._derived = JointStateDerivation(urdf, fk, joint_map, tf_max_rate)
        self._live = live
        self._missed = 0  # trace batches the bus reported lost on the way (report_missed)

    # ----------------------------------------------------------------- lifecycle
    def start(self) -> Recorder:
        self._writer.start()
        return self

    def __enter__(self) -> Recorder:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self, timeout: float = 30.0) -> bool:
        """Write everything queued, finish every file (summary, index) and stop; False if that
        took longer than ``timeout`` (logged). Records submitted from now on are dropped (counted)."""
        return bool(self._writer.close(timeout))

    # ----------------------------------------------------------------- hot path
    def submit(self, topic: str, log_time: int, data: Any,
               publish_time: int | None = None, *, latched: bool = False) -> bool:
        """Queue one record; never blocks. False if it had to be dropped (counted, logged).

        ``data``: a JSON-serialisable dict/list, a msgspec Struct, or JSON bytes. ``latched``:
        what the robot is made of (the cell): the latest such record of its topic is written
        again at the start of every file opened after it (a rotated system file, a session's),
        as the URDF is.
        """
        if topic == LOG_TOPIC:
            data = as_dict(data)
            if isinstance(data, dict):
                data = to_foxglove_log(data, log_time)
        payload = encode(data)
        if topic not in self._topics:
            self._schema(topic)
        accepted: bool = self._writer.submit(topic, log_time, log_time if publish_time is None else publish_time,
                                             payload, latched)
        if self._live is not None or (topic == JOINT_STATE_TOPIC and self._derived.active):
            with self._lock:
                self._after(topic, log_time, data, payload)
        return accepted

    def submit_batch(self, payload: bytes, received_ns: int) -> list[tuple[str, bytes]]:
        """Queue the records of one ``trace/<service>`` batch that the native writer makes
        itself (client lines and replies, session events, bus traces: no Python per record)
        and hand the live view its copies; never blocks. Returns the others, ``(suffix,
        record JSON)``, for ``submit`` (joint states, link events, logs). ValueError if
        ``payload`` is not a batch."""
        others, copies = self._writer.submit_batch(payload, received_ns, self._live is not None)
        if copies:
            with self._lock:
                for topic, log_time, record in copies:
                    self._after(topic, log_time, record, record)
        return others

    def _after(self, topic: str, log_time: int, data: Any, payload: bytes) -> None:
        """The live view's copy of a record, and what a joint state gives (``/tf``, ``/flange``)."""
        if self._live is not None:
            try:
                self._live(topic, log_time, data, payload)
            except Exception as exc:  # the live view must not stop the recording
                self._live = None
                log.error("live view failed (%r): no live view from now on", exc)
        if topic == JOINT_STATE_TOPIC and self._derived.active:
            for derived_topic, derived in self._derived.derive(data, log_time):
                if derived_topic not in self._topics:
                    self._schema(derived_topic)
                self._writer.submit(derived_topic, log_time, log_time, derived)
                if self._live is not None:
                    self._after(derived_topic, log_time, derived, derived)

    def _schema(self, topic: str) -> None:
        spec = schema_for(topic)
        self._writer.schema(topic, spec.name, spec.data)
        self._topics.add(topic)

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

    # ----------------------------------------------------------------- control
    def flush(self, timeout: float = 10.0) -> bool:
        """Block until every record submitted before is written and flushed to the OS."""
        return bool(self._writer.control("flush", None, timeout))

    def open_session(self, session: int | str) -> None:
        """Start a session file now (otherwise it starts with the session's first record)."""
        self._writer.control("open_session", str(session))

    def close_session(self, session: int | str) -> None:
        """Finish a session file (after ``session_linger``)."""
        self._writer.control("close_session", str(session))

    def stats(self) -> RecorderStats:
        s = self._writer.stats()
        return RecorderStats(
            submitted=s["submitted"], written=s["written"], dropped=s["dropped"], missed=self._missed,
            dropped_by_topic=dict(s["dropped_by_topic"]), backlog=s["backlog"],
            max_backlog_seen=s["max_backlog_seen"], errors=s["errors"], files=list(s["files"]))
