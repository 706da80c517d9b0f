"""Inspection of recordings: per-session command statistics and CSV export.

Works on finished and unfinished files (it reads with ``reader.RecordingReader``).
"""

from __future__ import annotations

import csv
import datetime as _dt
import os
import re
from collections import Counter, defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rob6_recorder_native import STATUS_TOPIC

from .reader import Record, RecordingReader

_SESSION_TOPIC = re.compile(r"^/session/([^/]+)/(client_in|client_out|event)$")


def iso(ns: int) -> str:
    return _dt.datetime.fromtimestamp(ns / 1e9, _dt.UTC).isoformat(
        timespec="microseconds").replace("+00:00", "Z")


def command_word(text: str) -> str:
    """The protocol's command word: the first whitespace-delimited token."""
    text = text.split("\0", 1)[0]
    parts = text.split()
    return parts[0] if parts else "(empty)"


def reply_is_error(text: str) -> bool:
    return any(line.startswith("ERROR:") for line in text.split("\n"))


def reply_is_false(text: str) -> bool:
    lines = [line for line in text.split("\n") if line != ""]
    return bool(lines) and lines[-1].strip() == "false"


@dataclass
class SessionSummary:
    session: str
    start_ns: int = 0
    end_ns: int = 0
    lines: int = 0
    replies: int = 0
    commands: Counter[str] = field(default_factory=Counter)
    errors: int = 0  # replies with an ``ERROR:`` line
    false: int = 0  # replies ending in ``false``
    no_reply: int = 0  # lines that got nothing back
    failures: list[dict[str, Any]] = field(default_factory=list)  # first few error/false exchanges
    latencies_ms: list[float] = field(default_factory=list)
    events: list[str] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9 if self.end_ns else 0.0

    def as_dict(self) -> dict[str, Any]:
        lat = sorted(self.latencies_ms)
        return {
            "session": self.session, "start": iso(self.start_ns) if self.start_ns else None,
            "end": iso(self.end_ns) if self.end_ns else None,
            "duration_s": round(self.duration_s, 6), "lines": self.lines,
            "replies": self.replies, "commands": dict(self.commands.most_common()),
            "errors": self.errors, "false": self.false, "no_reply": self.no_reply,
            "failures": self.failures, "events": self.events,
            "latency_ms": {
                "mean": round(sum(lat) / len(lat), 3) if lat else None,
                "p50": round(lat[len(lat) // 2], 3) if lat else None,
                "max": round(lat[-1], 3) if lat else None,
            },
        }


@dataclass
class Summary:
    path: str
    complete: bool = False
    truncated_error: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[str] = field(default_factory=list)
    records: int = 0
    topics: Counter[str] = field(default_factory=Counter)
    schemas: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    sessions: dict[str, SessionSummary] = field(default_factory=dict)
    dropped: int = 0

    @property
    def robot(self) -> str:
        return self.metadata.get("rob6", {}).get("robot", "")

    @property
    def robot_id(self) -> str:
        return self.metadata.get("rob6", {}).get("robot_id", "")

    def as_dict(self) -> dict[str, Any]:
        return {
            "file": self.path, "complete": self.complete,
            "unfinished_reason": None if self.complete else self.truncated_error,
            "robot": self.robot, "robot_id": self.robot_id,
            "kind": self.metadata.get("rob6", {}).get("kind", ""),
            "start": iso(self.start_ns) if self.records else None,
            "end": iso(self.end_ns) if self.records else None,
            "duration_s": round((self.end_ns - self.start_ns) / 1e9, 6) if self.records else 0,
            "records": self.records, "topics": dict(sorted(self.topics.items())),
            "schemas": self.schemas, "attachments": self.attachments,
            "dropped_by_recorder": self.dropped,
            "metadata": self.metadata,
            "sessions": [s.as_dict() for s in self.sessions.values()],
        }


def summarize(path: str | os.PathLike[str], max_failures: int = 20) -> Summary:
    reader = RecordingReader(path)
    summary = Summary(path=str(path))
    pending: dict[tuple[str, str], tuple[int, str]] = {}  # (session, cid) -> (t, text)
    last_in: dict[str, tuple[str, int, str]] = {}  # session -> (cid, t, text) of the last line
    answered: set[tuple[str, str]] = set()
    for rec in reader.records():
        summary.records += 1
        summary.topics[rec.topic] += 1
        summary.schemas.setdefault(rec.topic, rec.schema)
        if summary.records == 1:
            summary.start_ns = summary.end_ns = rec.log_time
        summary.start_ns = min(summary.start_ns, rec.log_time)
        summary.end_ns = max(summary.end_ns, rec.log_time)
        if rec.topic == STATUS_TOPIC and isinstance(rec.data, dict):
            summary.dropped = max(summary.dropped, int(rec.data.get("dropped", 0) or 0))
        m = _SESSION_TOPIC.match(rec.topic)
        if not m or not isinstance(rec.data, dict):
            continue
        sid, kind = m.group(1), m.group(2)
        s = summary.sessions.get(sid)
        if s is None:
            s = summary.sessions[sid] = SessionSummary(session=sid, start_ns=rec.log_time)
        s.start_ns = min(s.start_ns, rec.log_time)
        s.end_ns = max(s.end_ns, rec.log_time)
        data = rec.data
        cid = str(data.get("cid", "") or "")
        text = str(data.get("text", ""))
        if kind == "event":
            s.events.append(f"{iso(rec.log_time)} {data.get('event', '')}"
                            + (f" ({data['reason']})" if data.get("reason") else ""))
        elif kind == "client_in":
            s.lines += 1
            s.commands[command_word(text)] += 1
            key = cid or f"#{s.lines}"
            pending[(sid, key)] = (rec.log_time, text)
            last_in[sid] = (key, rec.log_time, text)
        else:  # client_out
            if data.get("kind") == "greeting":
                continue
            s.replies += 1
            key = cid or (last_in.get(sid, ("", 0, ""))[0])
            sent = pending.get((sid, key))
            if sent is not None and (sid, key) not in answered:
                answered.add((sid, key))
                s.latencies_ms.append((rec.log_time - sent[0]) / 1e6)
            is_err, is_false = reply_is_error(text), reply_is_false(text)
            s.errors += is_err
            s.false += is_false
            if (is_err or is_false) and len(s.failures) < max_failures:
                s.failures.append({"time": iso(rec.log_time), "cid": cid,
                                   "sent": sent[1] if sent else None, "reply": text})
    for s in summary.sessions.values():
        s.no_reply = sum(1 for (sid, key) in pending if sid == s.session
                         and (sid, key) not in answered)
    summary.complete = reader.report.complete
    summary.truncated_error = reader.report.error
    summary.metadata = reader.metadata
    summary.attachments = [f"{a.name} ({a.media_type}, {len(a.data)} bytes)"
                           for a in reader.attachments]
    return summary


def format_summary(summary: Summary) -> str:
    d = summary.as_dict()
    out = [f"file:      {d['file']}",
           f"state:     {'complete' if d['complete'] else 'UNFINISHED: ' + str(d['unfinished_reason'])}",
           f"robot:     {d['robot'] or '?'} (id {d['robot_id'] or '?'}), {d['kind'] or '?'} recording",
           f"time:      {d['start']} .. {d['end']} ({d['duration_s']:.3f} s)",
           f"records:   {d['records']}" + (f"  (recorder dropped {d['dropped_by_recorder']})"
                                            if d["dropped_by_recorder"] else "")]
    if d["attachments"]:
        out.append(f"attached:  {', '.join(d['attachments'])}")
    out.append("topics:")
    width = max((len(t) for t in d["topics"]), default=0)
    for topic, n in d["topics"].items():
        out.append(f"  {topic:<{width}}  {n:>9}  {d['schemas'].get(topic, '')}")
    for s in d["sessions"]:
        lat = s["latency_ms"]
        out.append(f"session {s['session']}: {s['start']} .. {s['end']} ({s['duration_s']:.3f} s), "
                   f"{s['lines']} lines, {s['replies']} replies, {s['errors']} ERROR, "
                   f"{s['false']} false, {s['no_reply']} without reply"
                   + (f", latency mean {lat['mean']} ms / max {lat['max']} ms"
                      if lat["mean"] is not None else ""))
        for word, n in s["commands"].items():
            out.append(f"    {word:<32} {n:>7}")
        for ev in s["events"]:
            out.append(f"    event {ev}")
        for f in s["failures"]:
            out.append(f"    ! {f['time']} {(f['sent'] or '?').rstrip()!r} -> {f['reply'].rstrip()!r}")
    return "\n".join(out)


# --------------------------------------------------------------------------- export
def _strip_nl(text: str) -> str:
    return text[:-1] if text.endswith("\n") else text


def export_csv(path: str | os.PathLike[str], outdir: str | os.PathLike[str]) -> dict[str, int]:
    """Write ``commands.csv``, ``joint_states.csv`` and ``log.csv`` into ``outdir``.

    commands.csv: time (ISO UTC), log_time_ns, session, direction (in|out), cid,
    command, text (the line or reply, one trailing newline removed; a multi-line reply
    stays one CSV field). joint_states.csv: time, log_time_ns, t, cycle, q1..q6,
    qd1..qd6, moving, mode. Returns the rows written per file.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    counts = {"commands.csv": 0, "joint_states.csv": 0, "log.csv": 0}
    with open(out / "commands.csv", "w", newline="", encoding="utf-8") as fc, \
            open(out / "joint_states.csv", "w", newline="", encoding="utf-8") as fj, \
            open(out / "log.csv", "w", newline="", encoding="utf-8") as fl:
        wc, wj, wl = csv.writer(fc), csv.writer(fj), csv.writer(fl)
        wc.writerow(["time", "log_time_ns", "session", "direction", "cid", "command", "text"])
        wj.writerow(["time", "log_time_ns", "t", "cycle", *[f"q{i}" for i in range(1, 7)],
                     *[f"qd{i}" for i in range(1, 7)], "moving", "mode"])
        wl.writerow(["time", "log_time_ns", "level", "name", "message"])
        for rec in _records(path):
            data = rec.data if isinstance(rec.data, dict) else {}
            m = _SESSION_TOPIC.match(rec.topic)
            if m and m.group(2) != "event":
                text = str(data.get("text", ""))
                direction = "in" if m.group(2) == "client_in" else "out"
                wc.writerow([iso(rec.log_time), rec.log_time, m.group(1), direction,
                             data.get("cid", ""),
                             command_word(text) if direction == "in" else "",
                             _strip_nl(text)])
                counts["commands.csv"] += 1
            elif rec.topic == "/driver/joint_state":
                q = list(data.get("q") or [])[:6]
                qd = list(data.get("qd") or [])[:6]
                q += [""] * (6 - len(q))
                qd += [""] * (6 - len(qd))
                wj.writerow([iso(rec.log_time), rec.log_time, data.get("t", ""),
                             data.get("cycle", ""), *q, *qd, data.get("moving", ""),
                             data.get("mode", "")])
                counts["joint_states.csv"] += 1
            elif rec.topic == "/log":
                wl.writerow([iso(rec.log_time), rec.log_time, data.get("level", ""),
                             data.get("name", ""), data.get("message", "")])
                counts["log.csv"] += 1
    return counts


def _records(path: str | os.PathLike[str]) -> Iterator[Record]:
    yield from RecordingReader(path).records()


def session_topics(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """Sessions found in a recording -> counts of lines (used by replay)."""
    found: dict[str, dict[str, Any]] = defaultdict(lambda: {"lines": 0})
    for rec in RecordingReader(path).records():
        m = _SESSION_TOPIC.match(rec.topic)
        if m and m.group(2) == "client_in":
            found[m.group(1)]["lines"] += 1
    return dict(found)
