"""An independent rmw_zenoh peer (zenoh-ros2-sdk, PyPI) sees rob6 as a ROS 2 node.

zenoh-ros2-sdk computes the type hashes, key expressions and liveliness tokens with its own
code from the .msg text and decodes CDR with rosbags: a message arrives only if rob6 got the
key expression (and so the hash) right. It subscribes to /joint_states while an old client
moves the arm over the text protocol, and reads /robot_description as a late joiner (from
the transient-local publisher's cache, the way it reads rmw_zenoh's).
"""

from __future__ import annotations

import math
import queue
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from typing import Any

import pytest

from harness.client import Client
from harness.system import System, running
from tests.ros import msgdefs

zsdk = pytest.importorskip("zenoh_ros2_sdk")
from zenoh_ros2_sdk import message_registry  # noqa: E402
from zenoh_ros2_sdk.discovery import get_topic_names_and_types  # noqa: E402
from zenoh_ros2_sdk.qos import QosDurability, QosProfile  # noqa: E402
from zenoh_ros2_sdk.session import ZenohSession  # noqa: E402

WAIT_S = 10.0  # a bound for a message to arrive, not a sleep: queue.get returns at once when it does


@pytest.fixture(scope="module")
def system(tmp_path_factory: pytest.TempPathFactory) -> Iterator[System]:
    message_registry._registry = None
    message_registry.get_registry(str(msgdefs.write(tmp_path_factory.mktemp("msg"))))
    with running("kr16", dummy=True) as system:
        ZenohSession._instance = None
        session = ZenohSession.get_instance("127.0.0.1", system.router_port)
        for dependency in ("builtin_interfaces/msg/Time", "std_msgs/msg/Header"):  # nested types first
            session.register_message_type(msgdefs.MSG[dependency], dependency)
        yield system
        ZenohSession.get_instance().close()


def _subscribe(topic: str, msg_type: str, **kwargs: Any) -> tuple[Any, queue.Queue[Any]]:
    messages: queue.Queue[Any] = queue.Queue()
    # the SDK computes the type hash itself from the .msg text (no type_hash given)
    subscriber = zsdk.ROS2Subscriber(topic, msg_type, messages.put, msg_definition=msgdefs.MSG[msg_type], **kwargs)
    return subscriber, messages


def _joint_states(messages: queue.Queue[Any], until: Any) -> Any:
    while True:
        message = messages.get(timeout=WAIT_S)
        if until(message):
            return message


def test_joint_states_follow_an_old_client(system: System) -> None:
    subscriber, messages = _subscribe("/joint_states", "sensor_msgs/msg/JointState")
    try:
        first = messages.get(timeout=WAIT_S)  # the driver's state at rest comes every 40 ms
        assert list(first.name) == [f"joint_{i}" for i in range(1, 7)]
        target = [10.0, -60.0, 80.0, 20.0, 40.0, 30.0]
        client = Client(system.port)
        try:
            assert client.ask("MovePTPJoints " + " ".join(map(str, target))) == "true\n"
            reported = [float(v) for v in client.ask("GetPositionJoints").split()]
        finally:
            client.close()
        moved = _joint_states(messages, lambda m: abs(m.position[0] - math.radians(10.0)) < 1e-9)
        assert [math.degrees(p) for p in moved.position] == pytest.approx(reported, abs=1e-6)
        assert len(moved.velocity) == 6
    finally:
        subscriber.close()


def test_robot_description_reaches_a_late_joiner(system: System) -> None:
    # the node published it once at start-up, long before this subscriber existed
    subscriber, messages = _subscribe("/robot_description", "std_msgs/msg/String",
                                      qos=QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1))
    try:
        urdf = messages.get(timeout=WAIT_S).data
    finally:
        subscriber.close()
    root = ET.fromstring(urdf)
    assert root.tag == "robot"
    assert [j.attrib["name"] for j in root.iter("joint") if j.attrib["type"] == "revolute"] == \
        [f"joint_{i}" for i in range(1, 7)]


def test_the_graph_shows_the_topics(system: System) -> None:
    topics = dict(get_topic_names_and_types(router_port=system.router_port))
    assert topics.get("/joint_states") == ["sensor_msgs/msg/JointState"]
    assert topics.get("/robot_description") == ["std_msgs/msg/String"]
