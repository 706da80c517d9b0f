"""The ROS 2 interface types rob6 speaks, their field layouts and RIHS01 type hashes.

Each message type is a list of ``(field, type)`` with ``type`` in the .msg spelling:
a primitive (``float64``, ``string``...), a nested type ``pkg/msg/Name``, and a suffix
``[]`` (unbounded sequence), ``[<=N]`` (bounded sequence) or ``[N]`` (array). The
layouts are those of ROS 2 Jazzy (common_interfaces, rcl_interfaces, control_msgs 5):
``cdr`` serialises from them, and ``type_hash`` computes the RIHS01 hash that rmw_zenoh
puts in every key expression (REP 2011: SHA-256 of the type description, the type and
every type it references, as JSON without default values).

Services and actions follow rosidl's generated types: a service ``S`` is the messages
``S_Request``, ``S_Response`` and ``S_Event`` plus the service type itself (fields
``request_message``, ``response_message``, ``event_message``); an action ``A`` adds
``A_Goal``, ``A_Result``, ``A_Feedback``, the services ``A_SendGoal`` and ``A_GetResult``
and the message ``A_FeedbackMessage``.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass

#: the type ids of type_description_interfaces/FieldType
PRIMITIVE_IDS = {
    "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7, "int64": 8, "uint64": 9,
    "float32": 10, "float64": 11, "char": 3, "bool": 15, "byte": 16, "string": 17,
}
NESTED_ID = 1
ARRAY_OFFSET, BOUNDED_SEQUENCE_OFFSET, SEQUENCE_OFFSET = 48, 96, 144

Fields = list[tuple[str, str]]

MESSAGES: dict[str, Fields] = {
    "builtin_interfaces/msg/Time": [("sec", "int32"), ("nanosec", "uint32")],
    "builtin_interfaces/msg/Duration": [("sec", "int32"), ("nanosec", "uint32")],
    "std_msgs/msg/Header": [("stamp", "builtin_interfaces/msg/Time"), ("frame_id", "string")],
    "std_msgs/msg/String": [("data", "string")],
    "sensor_msgs/msg/JointState": [
        ("header", "std_msgs/msg/Header"), ("name", "string[]"), ("position", "float64[]"),
        ("velocity", "float64[]"), ("effort", "float64[]")],
    "unique_identifier_msgs/msg/UUID": [("uuid", "uint8[16]")],
    "service_msgs/msg/ServiceEventInfo": [
        ("event_type", "uint8"), ("stamp", "builtin_interfaces/msg/Time"), ("client_gid", "char[16]"),
        ("sequence_number", "int64")],
    "geometry_msgs/msg/Vector3": [("x", "float64"), ("y", "float64"), ("z", "float64")],
    "geometry_msgs/msg/Quaternion": [("x", "float64"), ("y", "float64"), ("z", "float64"), ("w", "float64")],
    "geometry_msgs/msg/Transform": [
        ("translation", "geometry_msgs/msg/Vector3"), ("rotation", "geometry_msgs/msg/Quaternion")],
    "geometry_msgs/msg/Twist": [("linear", "geometry_msgs/msg/Vector3"), ("angular", "geometry_msgs/msg/Vector3")],
    "trajectory_msgs/msg/JointTrajectoryPoint": [
        ("positions", "float64[]"), ("velocities", "float64[]"), ("accelerations", "float64[]"),
        ("effort", "float64[]"), ("time_from_start", "builtin_interfaces/msg/Duration")],
    "trajectory_msgs/msg/JointTrajectory": [
        ("header", "std_msgs/msg/Header"), ("joint_names", "string[]"),
        ("points", "trajectory_msgs/msg/JointTrajectoryPoint[]")],
    "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint": [
        ("transforms", "geometry_msgs/msg/Transform[]"), ("velocities", "geometry_msgs/msg/Twist[]"),
        ("accelerations", "geometry_msgs/msg/Twist[]"), ("time_from_start", "builtin_interfaces/msg/Duration")],
    "trajectory_msgs/msg/MultiDOFJointTrajectory": [
        ("header", "std_msgs/msg/Header"), ("joint_names", "string[]"),
        ("points", "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint[]")],
    "control_msgs/msg/JointTolerance": [
        ("name", "string"), ("position", "float64"), ("velocity", "float64"), ("acceleration", "float64")],
    "control_msgs/msg/JointComponentTolerance": [
        ("joint_name", "string"), ("component", "uint16"), ("position", "float64"), ("velocity", "float64"),
        ("acceleration", "float64")],
    "action_msgs/msg/GoalInfo": [("goal_id", "unique_identifier_msgs/msg/UUID"), ("stamp", "builtin_interfaces/msg/Time")],
    "action_msgs/msg/GoalStatus": [("goal_info", "action_msgs/msg/GoalInfo"), ("status", "int8")],
    "action_msgs/msg/GoalStatusArray": [("status_list", "action_msgs/msg/GoalStatus[]")],
}

#: services: name -> (request fields, response fields)
SERVICES: dict[str, tuple[Fields, Fields]] = {
    "action_msgs/srv/CancelGoal": (
        [("goal_info", "action_msgs/msg/GoalInfo")],
        [("return_code", "int8"), ("goals_canceling", "action_msgs/msg/GoalInfo[]")]),
}

#: actions: name -> (goal, result, feedback fields)
ACTIONS: dict[str, tuple[Fields, Fields, Fields]] = {
    "control_msgs/action/FollowJointTrajectory": (
        [("trajectory", "trajectory_msgs/msg/JointTrajectory"),
         ("multi_dof_trajectory", "trajectory_msgs/msg/MultiDOFJointTrajectory"),
         ("path_tolerance", "control_msgs/msg/JointTolerance[]"),
         ("component_path_tolerance", "control_msgs/msg/JointComponentTolerance[]"),
         ("goal_tolerance", "control_msgs/msg/JointTolerance[]"),
         ("component_goal_tolerance", "control_msgs/msg/JointComponentTolerance[]"),
         ("goal_time_tolerance", "builtin_interfaces/msg/Duration")],
        [("error_code", "int32"), ("error_string", "string")],
        [("header", "std_msgs/msg/Header"), ("joint_names", "string[]"),
         ("desired", "trajectory_msgs/msg/JointTrajectoryPoint"),
         ("actual", "trajectory_msgs/msg/JointTrajectoryPoint"),
         ("error", "trajectory_msgs/msg/JointTrajectoryPoint"),
         ("multi_dof_joint_names", "string[]"),
         ("multi_dof_desired", "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint"),
         ("multi_dof_actual", "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint"),
         ("multi_dof_error", "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint")]),
}


def _add_service(name: str, request: Fields, response: Fields) -> None:
    MESSAGES[f"{name}_Request"] = request
    MESSAGES[f"{name}_Response"] = response
    MESSAGES[f"{name}_Event"] = [("info", "service_msgs/msg/ServiceEventInfo"),
                                 ("request", f"{name}_Request[<=1]"), ("response", f"{name}_Response[<=1]")]
    MESSAGES[name] = [("request_message", f"{name}_Request"), ("response_message", f"{name}_Response"),
                      ("event_message", f"{name}_Event")]


for _name, (_request, _response) in SERVICES.items():
    _add_service(_name, _request, _response)
for _name, (_goal, _result, _feedback) in ACTIONS.items():
    MESSAGES[f"{_name}_Goal"] = _goal
    MESSAGES[f"{_name}_Result"] = _result
    MESSAGES[f"{_name}_Feedback"] = _feedback
    _add_service(f"{_name}_SendGoal", [("goal_id", "unique_identifier_msgs/msg/UUID"), ("goal", f"{_name}_Goal")],
                 [("accepted", "bool"), ("stamp", "builtin_interfaces/msg/Time")])
    _add_service(f"{_name}_GetResult", [("goal_id", "unique_identifier_msgs/msg/UUID")],
                 [("status", "int8"), ("result", f"{_name}_Result")])
    MESSAGES[f"{_name}_FeedbackMessage"] = [("goal_id", "unique_identifier_msgs/msg/UUID"),
                                            ("feedback", f"{_name}_Feedback")]

_SPEC = re.compile(r"^(?P<base>[A-Za-z0-9_/]+)(?:\[(?P<bound><=)?(?P<size>\d*)\])?$")


@dataclass(frozen=True)
class FieldType:
    """A parsed field type: its base (primitive or message name) and how many."""

    base: str
    kind: str  # "single" | "array" | "bounded" | "sequence"
    size: int = 0  # the array's length or the sequence's bound

    @property
    def nested(self) -> bool:
        return self.base not in PRIMITIVE_IDS


def parse(spec: str) -> FieldType:
    match = _SPEC.match(spec)
    if not match:
        raise ValueError(f"bad field type {spec!r}")
    base, bound, size = match["base"], match["bound"], match["size"]
    if "[" not in spec:
        kind = "single"
    elif bound:
        kind = "bounded"
    elif size:
        kind = "array"
    else:
        kind = "sequence"
    if base not in PRIMITIVE_IDS and base not in MESSAGES:
        raise ValueError(f"unknown type {base!r} in {spec!r}")
    return FieldType(base, kind, int(size) if size else 0)


def dds_name(type_name: str) -> str:
    """The type's name as rmw_zenoh's key expressions carry it: ``pkg::msg::dds_::Name_``."""
    package, kind, name = type_name.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def _field_description(name: str, spec: str) -> dict[str, object]:
    ftype = parse(spec)
    type_id = NESTED_ID if ftype.nested else PRIMITIVE_IDS[ftype.base]
    type_id += {"single": 0, "array": ARRAY_OFFSET, "bounded": BOUNDED_SEQUENCE_OFFSET,
                "sequence": SEQUENCE_OFFSET}[ftype.kind]
    return {"name": name, "type": {"type_id": type_id, "capacity": ftype.size, "string_capacity": 0,
                                   "nested_type_name": ftype.base if ftype.nested else ""}}


def _referenced(type_name: str, seen: set[str]) -> None:
    for _field, spec in MESSAGES[type_name]:
        ftype = parse(spec)
        if ftype.nested and ftype.base not in seen:
            seen.add(ftype.base)
            _referenced(ftype.base, seen)


def type_description(type_name: str) -> dict[str, object]:
    """The type description REP 2011 hashes (default values left out, as for the hash)."""
    seen: set[str] = set()
    _referenced(type_name, seen)
    seen.discard(type_name)

    def describe(name: str) -> dict[str, object]:
        return {"type_name": name, "fields": [_field_description(f, s) for f, s in MESSAGES[name]]}

    return {"type_description": describe(type_name),
            "referenced_type_descriptions": [describe(name) for name in sorted(seen)]}


def type_hash(type_name: str) -> str:
    """RIHS01: ``RIHS01_`` and the SHA-256 (hex) of the type description's JSON."""
    text = json.dumps(type_description(type_name), separators=(", ", ": "), ensure_ascii=True)
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()
