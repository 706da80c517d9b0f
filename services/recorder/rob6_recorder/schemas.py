"""JSON schemas of the recorded channels and the topic -> schema mapping.

Every channel of a rob6 recording has ``message_encoding="json"`` and a registered
``jsonschema`` schema (never schemaless). Foxglove recognises its well-known schemas
by *name* (``foxglove.Log``, ``foxglove.FrameTransforms``, ``foxglove.PosesInFrame``);
the rob6 ones (``rob6.*``) are plain JSON that the Plot / Raw Messages / State
Transitions panels read directly (e.g. plot ``/driver/joint_state.q[0]``).

``/robot_description`` uses the name ``std_msgs/String`` with ``{"data": <urdf>}``:
Foxglove's 3D panel loads a URDF published on that topic (and a custom URDF layer
with source "Topic" accepts schema ``std_msgs/String``).

The topic layout is documented in ``services/recorder/README.md``.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Any

import msgspec

from rob6.messages import Cell, Clearance, GripperState, JointState, LinkEvent

_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}
_VEC3 = {
    "type": "object",
    "title": "foxglove.Vector3",
    "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}},
}
_QUAT = {
    "type": "object",
    "title": "foxglove.Quaternion",
    "properties": {"x": {"type": "number"}, "y": {"type": "number"},
                   "z": {"type": "number"}, "w": {"type": "number"}},
}

FOXGLOVE_LOG = {
    "title": "foxglove.Log",
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "level": {"title": "foxglove.LogLevel", "description": "Log level", "oneOf": [
            {"title": "UNKNOWN", "const": 0}, {"title": "DEBUG", "const": 1},
            {"title": "INFO", "const": 2}, {"title": "WARNING", "const": 3},
            {"title": "ERROR", "const": 4}, {"title": "FATAL", "const": 5}]},
        "message": {"type": "string"},
        "name": {"type": "string", "description": "service/logger"},
        "file": {"type": "string"},
        "line": {"type": "integer", "minimum": 0},
        "service": {"type": "string", "description": "rob6 extension: emitting service"},
        "instance": {"type": "string", "description": "rob6 extension: service instance"},
    },
    "required": ["timestamp", "level", "message", "name", "file", "line"],
}

FOXGLOVE_FRAME_TRANSFORM = {
    "title": "foxglove.FrameTransform",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"},
        "translation": _VEC3,
        "rotation": _QUAT,
    },
}

FOXGLOVE_FRAME_TRANSFORMS = {
    "title": "foxglove.FrameTransforms",
    "description": "An array of FrameTransform messages",
    "type": "object",
    "properties": {"transforms": {"type": "array", "items": FOXGLOVE_FRAME_TRANSFORM}},
}

FOXGLOVE_POSES_IN_FRAME = {
    "title": "foxglove.PosesInFrame",
    "description": "An array of timestamped poses for an object or reference frame in 3D space",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "poses": {"type": "array", "items": {
            "title": "foxglove.Pose", "type": "object",
            "properties": {"position": _VEC3, "orientation": _QUAT}}},
    },
}

_POSE = {"title": "foxglove.Pose", "type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}
_COLOR = {"title": "foxglove.Color", "type": "object",
          "properties": {"r": {"type": "number"}, "g": {"type": "number"}, "b": {"type": "number"},
                         "a": {"type": "number"}}}


def _primitive(title: str, **properties: Any) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": {"pose": _POSE, **properties, "color": _COLOR}}


#: the 3D panel's scene (live view: the cell's zones and tool, ``cell_scene``); the primitives rob6 draws
FOXGLOVE_SCENE_UPDATE = {
    "title": "foxglove.SceneUpdate",
    "description": "An update to the entities displayed in a 3D scene",
    "type": "object",
    "properties": {
        "deletions": {"type": "array", "items": {
            "title": "foxglove.SceneEntityDeletion", "type": "object",
            "properties": {"timestamp": _TIME, "id": {"type": "string"}, "type": {
                "title": "foxglove.SceneEntityDeletionType",
                "oneOf": [{"title": "MATCHING_ID", "const": 0}, {"title": "ALL", "const": 1}]}}}},
        "entities": {"type": "array", "items": {
            "title": "foxglove.SceneEntity", "type": "object",
            "properties": {
                "timestamp": _TIME,
                "frame_id": {"type": "string"},
                "id": {"type": "string"},
                "lifetime": {**_TIME, "title": "duration"},
                "frame_locked": {"type": "boolean"},
                "metadata": {"type": "array", "items": {
                    "title": "foxglove.KeyValuePair", "type": "object",
                    "properties": {"key": {"type": "string"}, "value": {"type": "string"}}}},
                "cubes": {"type": "array", "items": _primitive("foxglove.CubePrimitive", size=_VEC3)},
                "spheres": {"type": "array", "items": _primitive("foxglove.SpherePrimitive", size=_VEC3)},
                "cylinders": {"type": "array", "items": _primitive(
                    "foxglove.CylinderPrimitive", size=_VEC3, bottom_scale={"type": "number"},
                    top_scale={"type": "number"})},
                "lines": {"type": "array", "items": _primitive(
                    "foxglove.LinePrimitive",
                    type={"title": "foxglove.LineType", "oneOf": [
                        {"title": "LINE_STRIP", "const": 0}, {"title": "LINE_LOOP", "const": 1},
                        {"title": "LINE_LIST", "const": 2}]},
                    thickness={"type": "number"}, scale_invariant={"type": "boolean"},
                    points={"type": "array", "items": {**_VEC3, "title": "foxglove.Point3"}},
                    colors={"type": "array", "items": _COLOR},
                    indices={"type": "array", "items": {"type": "integer", "minimum": 0}})},
            }}},
    },
}

STD_STRING = {
    "title": "std_msgs/String",
    "type": "object",
    "properties": {"data": {"type": "string"}},
}

CLIENT_LINE = {
    "title": "rob6.ClientLine",
    "description": "One line received from the TCP client (exact bytes as latin-1 text, "
                   "including its terminator).",
    "type": "object",
    "properties": {
        "session": {"type": "integer"},
        "cid": {"type": "string", "description": "correlation id of the command"},
        "text": {"type": "string", "description": "raw bytes decoded as latin-1"},
        "peer": {"type": "string"},
        "seq": {"type": "integer", "description": "1, 2, ... per session: a gap is a lost record"},
    },
    "required": ["session", "cid", "text"],
}

CLIENT_REPLY = {
    "title": "rob6.ClientReply",
    "description": "Everything sent to the client for one command (or the greeting): "
                   "latin-1 text, every line ending in \\n; empty when nothing was sent.",
    "type": "object",
    "properties": {
        "session": {"type": "integer"},
        "cid": {"type": "string"},
        "text": {"type": "string"},
        "kind": {"type": "string", "enum": ["reply", "greeting", "busy", "error"]},
        "dt": {"type": "number", "description": "seconds from line received to reply sent"},
        "seq": {"type": "integer", "description": "the client_in record's seq"},
    },
    "required": ["session", "cid", "text"],
}

SESSION_EVENT = {
    "title": "rob6.SessionEvent",
    "type": "object",
    "properties": {
        "session": {"type": "integer"},
        "event": {"type": "string", "description": "open | handshake | close | ..."},
        "peer": {"type": "string"},
        "reason": {"type": "string"},
    },
    "required": ["session", "event"],
}

#: what a bus request and its reply both name: the call, the service, the operation, the instance
_BUS_CALL = {
    "cid": {"type": "string"},
    "service": {"type": "string"},
    "op": {"type": "string"},
    "instance": {"type": "string"},
}

BUS_REQUEST = {
    "title": "rob6.BusRequest",
    "type": "object",
    "properties": {
        **_BUS_CALL,
        "body": {},
    },
    "required": ["cid"],
}

BUS_REPLY = {
    "title": "rob6.BusReply",
    "type": "object",
    "properties": {
        **_BUS_CALL,
        "ok": {"type": "boolean"},
        "body": {},
        "error": {"type": ["object", "null"], "properties": {
            "code": {"type": "string"}, "message": {"type": "string"}}},
        "dt": {"type": "number", "description": "service time, seconds"},
    },
    "required": ["cid"],
}

def struct_schema(struct: type[msgspec.Struct], title: str) -> dict[str, Any]:
    """The JSON schema of a bus message recorded as it is, generated from its msgspec Struct
    (``msgspec.json.schema``), so the recording's contract cannot drift from the bus's.

    The Struct's own definition is inlined at the top (Foxglove reads a plain object
    schema); the definitions of nested Structs, if any, stay under ``$defs``.
    """
    schema = msgspec.json.schema(struct)
    defs: dict[str, Any] = schema.pop("$defs", {})
    name = schema["$ref"].rsplit("/", 1)[-1]
    out: dict[str, Any] = {**defs.pop(name), "title": title}
    if defs:
        out["$defs"] = defs
    return out


#: Driver state every cycle, at rest every 100 ms (``/driver/joint_state``); degrees and degrees/s. Plot q[0]..q[5].
#: Fields at their default are left out (link connected, late 0...).
JOINT_STATE = struct_schema(JointState, "rob6.JointState")
#: An event of the driver's link to the robot (``/driver/link``).
LINK_EVENT = struct_schema(LinkEvent, "rob6.LinkEvent")
GRIPPER_STATE = struct_schema(GripperState, "rob6.GripperState")
#: The driver's cell (``/cell``): its safety zones, tool and self-collision settings, recorded
#: when the driver appears and again at the start of every file (mm, robot base frame).
CELL = struct_schema(Cell, "rob6.Cell")
#: The nearest pair while the arm moves (``/driver/clearance``, at most 10 Hz): plot distance_mm.
CLEARANCE = struct_schema(Clearance, "rob6.Clearance")

RECORDER_STATUS = {
    "title": "rob6.RecorderStatus",
    "description": "Recorder accounting: records dropped because the writer fell behind, "
                   "and batches of records lost on the way to the recorder (missed).",
    "type": "object",
    "properties": {
        "submitted": {"type": "integer"},
        "written": {"type": "integer"},
        "dropped": {"type": "integer", "description": "total dropped so far"},
        "dropped_since_last": {"type": "object",
                               "additionalProperties": {"type": "integer"}},
        "backlog": {"type": "integer"},
        "max_backlog_seen": {"type": "integer"},
        "first_drop_ns": {"type": "integer"},
        "last_drop_ns": {"type": "integer"},
        "missed": {"type": "integer",
                   "description": "trace batches (each of one or more records) from missed_source "
                                  "the bus detected as lost and could not recover"},
        "missed_source": {"type": "string", "description": "the publisher: key and instance"},
        "missed_total": {"type": "integer", "description": "batches missed so far"},
    },
}

GENERIC = {"title": "rob6.Record", "type": "object"}


@dataclass(frozen=True)
class SchemaSpec:
    name: str
    schema: dict[str, Any]

    @property
    def data(self) -> bytes:
        return json.dumps(self.schema, separators=(",", ":")).encode()


#: (regular expression on the topic, schema). First match wins.
TOPIC_SCHEMAS: list[tuple[re.Pattern[str], SchemaSpec]] = [
    (re.compile(r"^/session/[^/]+/client_in$"), SchemaSpec("rob6.ClientLine", CLIENT_LINE)),
    (re.compile(r"^/session/[^/]+/client_out$"), SchemaSpec("rob6.ClientReply", CLIENT_REPLY)),
    (re.compile(r"^/session/[^/]+/event$"), SchemaSpec("rob6.SessionEvent", SESSION_EVENT)),
    (re.compile(r"^/bus/[^/]+/[^/]+/request$"), SchemaSpec("rob6.BusRequest", BUS_REQUEST)),
    (re.compile(r"^/bus/[^/]+/[^/]+/reply$"), SchemaSpec("rob6.BusReply", BUS_REPLY)),
    (re.compile(r"^/driver/joint_state$"), SchemaSpec("rob6.JointState", JOINT_STATE)),
    (re.compile(r"^/driver/link$"), SchemaSpec("rob6.LinkEvent", LINK_EVENT)),
    (re.compile(r"^/gripper/state$"), SchemaSpec("rob6.GripperState", GRIPPER_STATE)),
    (re.compile(r"^/driver/clearance$"), SchemaSpec("rob6.Clearance", CLEARANCE)),
    (re.compile(r"^/cell$"), SchemaSpec("rob6.Cell", CELL)),
    (re.compile(r"^/cell/scene$"), SchemaSpec("foxglove.SceneUpdate", FOXGLOVE_SCENE_UPDATE)),  # live view
    (re.compile(r"^/log$"), SchemaSpec("foxglove.Log", FOXGLOVE_LOG)),
    (re.compile(r"^/commands$"), SchemaSpec("foxglove.Log", FOXGLOVE_LOG)),  # live view: client lines, replies
    (re.compile(r"^/tf$"), SchemaSpec("foxglove.FrameTransforms", FOXGLOVE_FRAME_TRANSFORMS)),
    (re.compile(r"^/flange$"), SchemaSpec("foxglove.PosesInFrame", FOXGLOVE_POSES_IN_FRAME)),
    (re.compile(r"^/robot_description$"), SchemaSpec("std_msgs/String", STD_STRING)),
    (re.compile(r"^/recorder/status$"), SchemaSpec("rob6.RecorderStatus", RECORDER_STATUS)),
]
GENERIC_SPEC = SchemaSpec("rob6.Record", GENERIC)


def schema_for(topic: str) -> SchemaSpec:
    """The schema of a topic (``rob6.Record``, a plain object, for unknown topics)."""
    for pattern, spec in TOPIC_SCHEMAS:
        if pattern.match(topic):
            return spec
    return GENERIC_SPEC


def record_schemas() -> dict[str, tuple[str, bytes]]:
    """The schema of each kind of record the native writer makes from a trace batch
    (``rob6_recorder_native.Writer.submit_batch``), by the kind's name there."""
    examples = {"client_in": "/session/1/client_in", "client_out": "/session/1/client_out",
                "event": "/session/1/event", "request": "/bus/s/op/request", "reply": "/bus/s/op/reply"}
    return {kind: (schema_for(topic).name, schema_for(topic).data) for kind, topic in examples.items()}


# --------------------------------------------------------------------------- helpers
LOG_LEVELS = {"NOTSET": 0, "TRACE": 1, "DEBUG": 1, "INFO": 2, "WARN": 3, "WARNING": 3,
              "ERROR": 4, "CRITICAL": 5, "FATAL": 5}


def stamp(ns: int) -> dict[str, Any]:
    """A Foxglove ``time`` from nanoseconds."""
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def to_foxglove_log(record: dict[str, Any], log_time_ns: int) -> dict[str, Any]:
    """Map a rob6 log record (``level, name, message, service, time|t``) to foxglove.Log.

    Records that already look like foxglove.Log (``timestamp`` dict, int level) pass
    through. ``name`` becomes ``<service>/<logger>`` so the Log panel can filter per
    service; ``service`` and ``instance`` are kept as extra fields.
    """
    if isinstance(record.get("timestamp"), dict) and isinstance(record.get("level"), int):
        out = dict(record)
        out.setdefault("file", "")
        out.setdefault("line", 0)
        out.setdefault("name", "")
        out.setdefault("message", "")
        return out
    level = record.get("level", 0)
    if isinstance(level, str):
        level = LOG_LEVELS.get(level.upper(), 0)
    elif isinstance(level, int) and level > 5:  # a Python logging level number
        level = {10: 1, 20: 2, 30: 3, 40: 4, 50: 5}.get(level - level % 10, 5 if level > 50 else 0)
    t = record.get("time", record.get("t"))
    ns = int(round(float(t) * 1e9)) if isinstance(t, (int, float)) else log_time_ns
    service = str(record.get("service", "") or "")
    name = str(record.get("name", "") or "")
    out = {
        "timestamp": stamp(ns),
        "level": int(level),
        "message": str(record.get("message", "")),
        "name": f"{service}/{name}" if service and name else (service or name),
        "file": str(record.get("file", "") or ""),
        "line": int(record.get("line", 0) or 0),
    }
    if service:
        out["service"] = service
    if record.get("instance"):
        out["instance"] = str(record["instance"])
    return out
