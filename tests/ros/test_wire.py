"""rob6's ROS 2 wire format against implementations nobody here wrote.

* rosbags (PyPI) is the oracle for the CDR bytes and the RIHS01 hash of every message type
  rob6 uses (its own serialiser and type-description hashing, from the .msg text registered
  as rob6 declares it);
* published hashes: sensor_msgs/JointState and std_msgs/String (ROS 2 Jazzy, as rmw_zenoh's
  key expressions show them) and action_msgs/GoalStatusArray;
* the rmw_zenoh format facts (attachment, QoS in tokens, names) from ros2/rmw_zenoh.
"""

from __future__ import annotations

import hashlib
import json
import math
import random
from typing import Any

import numpy as np
import pytest

from rob6_ros import cdr, idl, rmw
from tests.ros import msgdefs

rosbags_typesys = pytest.importorskip("rosbags.typesys")

PUBLISHED = {
    "sensor_msgs/msg/JointState": "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "action_msgs/msg/GoalStatusArray": "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
    # rosidl turns .msg's ``char`` into uint8 before hashing; rosbags 0.11.9 hashes it as
    # FIELD_TYPE_CHAR and so differs for this type (and every _Event that contains it)
    "service_msgs/msg/ServiceEventInfo": "RIHS01_41bcbbe07a75c9b52bc96bfd5c24d7f0fc0a08c0cb7921b3373c5732345a6f45",
}
#: message types (not the service-level types: rosbags has no service type descriptions);
#: rosbags files a service's messages under ``pkg/srv/msg/...``, so their hashes (which hash
#: the name) are compared through the service's action counterparts only
MESSAGE_TYPES = sorted(name for name in idl.MESSAGES
                       if not any(name == s for s in idl.SERVICES)
                       and not name.endswith(("_SendGoal", "_GetResult")))


HASHED_BY_ROSBAGS = [name for name in MESSAGE_TYPES if "/srv/" not in name and not name.endswith("_Event")
                     and name != "service_msgs/msg/ServiceEventInfo"]


def _rosbags_name(name: str) -> str:
    return name.replace("/srv/", "/srv/msg/")


def _msg_text(fields: idl.Fields) -> str:
    lines = []
    for name, spec in fields:
        ftype = idl.parse(spec)
        base = ftype.base
        if ftype.nested:
            package, _kind, message = base.split("/")
            base = f"{package}/{message}" if _kind == "msg" else _rosbags_name(base)
        suffix = {"single": "", "array": f"[{ftype.size}]", "bounded": f"[<={ftype.size}]", "sequence": "[]"}[ftype.kind]
        lines.append(f"{base}{suffix} {name}")
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def store() -> Any:
    typestore = rosbags_typesys.get_typestore(rosbags_typesys.Stores.EMPTY)
    types: dict[str, Any] = {}
    for name in idl.MESSAGES:
        if name in idl.SERVICES or name.endswith(("_SendGoal", "_GetResult")) or name.count("/") != 2:
            continue
        types.update(rosbags_typesys.get_types_from_msg(_msg_text(idl.MESSAGES[name]), _rosbags_name(name)))
    typestore.register(types)
    return typestore


@pytest.mark.parametrize("type_name", HASHED_BY_ROSBAGS)
def test_hash_matches_rosbags(store: Any, type_name: str) -> None:
    assert idl.type_hash(type_name) == store.hash_rihs01(type_name)


@pytest.mark.parametrize("type_name", sorted(PUBLISHED))
def test_hash_matches_the_published_one(type_name: str) -> None:
    assert idl.type_hash(type_name) == PUBLISHED[type_name]


def _random_value(store: Any, type_name: str, rng: random.Random, depth: int = 0) -> dict[str, Any]:
    value: dict[str, Any] = {}
    for name, spec in idl.MESSAGES[type_name]:
        ftype = idl.parse(spec)
        count = {"single": 1, "array": ftype.size, "bounded": rng.randint(0, ftype.size),
                 "sequence": rng.randint(0, 3 if depth < 3 else 0)}[ftype.kind]
        items = [_random_scalar(store, ftype.base, rng, depth) for _ in range(count)]
        value[name] = items[0] if ftype.kind == "single" else items
    return value


def _random_scalar(store: Any, base: str, rng: random.Random, depth: int) -> Any:
    if base == "string":
        return rng.choice(["", "joint_1", "ä ü", "x" * rng.randint(0, 9)])
    if base == "bool":
        return rng.random() < 0.5
    if base.startswith("float"):
        return rng.uniform(-1e3, 1e3)
    if base in ("int8", "int16", "int32", "int64"):
        bits = int(base[3:])
        return rng.randint(-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    if base in ("uint8", "char", "byte", "uint16", "uint32", "uint64"):
        bits = 8 if base in ("char", "byte") else int(base[4:])
        return rng.randint(0, 2 ** bits - 1)
    return _random_value(store, base, rng, depth + 1)


def _to_rosbags(store: Any, type_name: str, value: dict[str, Any]) -> Any:
    cls = store.types[_rosbags_name(type_name)]
    kwargs: dict[str, Any] = {}
    for name, spec in idl.MESSAGES[type_name]:
        ftype = idl.parse(spec)
        item = value[name]
        if ftype.kind == "single":
            kwargs[name] = _to_rosbags(store, ftype.base, item) if ftype.nested else item
        elif ftype.nested:
            kwargs[name] = [_to_rosbags(store, ftype.base, v) for v in item]
        elif ftype.base == "string":
            kwargs[name] = list(item)
        else:
            dtype = {"float64": np.float64, "float32": np.float32, "bool": np.bool_, "int8": np.int8,
                     "uint8": np.uint8, "char": np.uint8, "int16": np.int16, "uint16": np.uint16,
                     "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64}[ftype.base]
            kwargs[name] = np.array(item, dtype=dtype)
    return cls(**kwargs)


@pytest.mark.parametrize("type_name", MESSAGE_TYPES)
def test_cdr_bytes_match_rosbags(store: Any, type_name: str) -> None:
    rng = random.Random(type_name)
    for _ in range(20):
        value = _random_value(store, type_name, rng)
        ours = cdr.serialize(type_name, value)
        theirs = bytes(store.serialize_cdr(_to_rosbags(store, type_name, value), _rosbags_name(type_name)))
        assert ours == theirs
        # and back: ours reads what rosbags wrote
        assert cdr.serialize(type_name, cdr.deserialize(type_name, theirs)) == theirs


def test_key_expression_and_token_shapes() -> None:
    assert idl.dds_name("sensor_msgs/msg/JointState") == "sensor_msgs::msg::dds_::JointState_"
    assert idl.dds_name("control_msgs/action/FollowJointTrajectory_SendGoal") == \
        "control_msgs::action::dds_::FollowJointTrajectory_SendGoal_"
    assert rmw.Qos().keyexpr() == "::,10:,:,:,,"
    assert rmw.LATCHED_QOS.keyexpr() == ":1:,1:,:,:,,"
    assert rmw.mangle("/arm/joint_states") == "%arm%joint_states" and rmw.mangle("") == "%"
    gid = bytes(range(16))
    data = rmw.attachment(7, gid, timestamp_ns=123)
    assert len(data) == 33 and data[16] == 0x10
    assert rmw.parse_attachment(data) == (7, 123, gid)


def test_cdr_refuses_what_is_not_cdr() -> None:
    with pytest.raises(ValueError, match="encapsulation"):
        cdr.deserialize("std_msgs/msg/String", b"{}")
    with pytest.raises(ValueError):
        cdr.deserialize("std_msgs/msg/String", cdr.HEADER + b"\xff\xff\xff\x7f")
    assert math.isclose(cdr.deserialize("builtin_interfaces/msg/Time", cdr.serialize(
        "builtin_interfaces/msg/Time", {"sec": -1, "nanosec": 5}))["nanosec"], 5)


#: hashes in rosidl-generated C headers of control_msgs (FollowJointTrajectory) and action_msgs
#: (CancelGoal) found in a public build: that build's generator joined the JSON with "," where
#: rosidl_generator_type_description (and every ROS 2 distro's published hash, e.g. JointState's)
#: uses ", ". Same separator, same description: rob6's type descriptions of the action's parts are
#: exactly rosidl's, field for field, names and nesting included.
GENERATED_WITH_COMMA = {
    "control_msgs/action/FollowJointTrajectory_Goal":
        "2c7e5ca862c004e8b4b7cc4ba7b66140c479335ee08f89cde024c4fec3516aca",
    "control_msgs/action/FollowJointTrajectory_Result":
        "5bafa91d6ff126027f0fcd3028f40839ad694400bb74c5777bfd1f09cb6a8e82",
    "control_msgs/action/FollowJointTrajectory_SendGoal":
        "4915b9909747df962256f0fe9a7dc832ba6e7ec2c5e827c5ba239b7b451d52aa",
    "control_msgs/action/FollowJointTrajectory_GetResult":
        "a42b878fc686578b092e626c27ba796dab419d9d5f3275920e4eca7769062539",
    "control_msgs/action/FollowJointTrajectory_FeedbackMessage":
        "88e16acd364ad5bc90b661a4f77fec9ab40874e8eeaaf4673e9cd78e41038b99",
    "action_msgs/srv/CancelGoal": "6a5f062d4e445bb8f6dfeb28d8ba83845efc58238741896b43c9dc8e1cffb775",
}


@pytest.mark.parametrize("type_name", sorted(GENERATED_WITH_COMMA))
def test_type_description_matches_rosidl_generated_headers(type_name: str) -> None:
    text = json.dumps(idl.type_description(type_name), separators=(",", ": "))
    assert hashlib.sha256(text.encode()).hexdigest() == GENERATED_WITH_COMMA[type_name]


def test_service_hash_matches_zenoh_ros2_sdk() -> None:
    """The SDK's own service-hash code (it knows ``pkg/srv/...`` services, not an action's parts)."""
    utils = pytest.importorskip("zenoh_ros2_sdk.utils")
    request, response = msgdefs.CANCEL_GOAL
    theirs = utils.compute_service_type_hash("action_msgs/srv/CancelGoal", request_definition=request,
                                             response_definition=response, dependencies=dict(msgdefs.MSG))
    assert idl.type_hash("action_msgs/srv/CancelGoal") == theirs


@pytest.mark.parametrize("type_name", ["sensor_msgs/msg/JointState", "std_msgs/msg/String",
                                       "control_msgs/action/FollowJointTrajectory_FeedbackMessage",
                                       "action_msgs/msg/GoalStatusArray"])
def test_message_hash_matches_zenoh_ros2_sdk(type_name: str) -> None:
    utils = pytest.importorskip("zenoh_ros2_sdk.utils")
    theirs = utils.get_type_hash(type_name, msg_definition=msgdefs.MSG[type_name], dependencies=dict(msgdefs.MSG))
    assert idl.type_hash(type_name) == theirs
