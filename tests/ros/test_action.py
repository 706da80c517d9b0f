"""FollowJointTrajectory through an independent rmw_zenoh peer (zenoh-ros2-sdk) on a real-time kr16.

The SDK's service client sends the goal, asks for the result and cancels, with its own
attachments, key expressions and CDR (rosbags); its subscriber computes the feedback
message's type hash itself. It cannot compute the hash of an action's services (it names
their parts ``pkg/srv/...``), so those are given; tests/ros/test_wire.py checks them. The
old client on port 5005 sees what the goals do, and one robot has one motion.
"""

from __future__ import annotations

import math
import queue
import threading
import uuid
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from rob6.robots import get_robot
from rob6_ros import idl
from tests.ros import msgdefs
from tests.system import Client, System, running

zsdk = pytest.importorskip("zenoh_ros2_sdk")
from zenoh_ros2_sdk import message_registry  # noqa: E402
from zenoh_ros2_sdk.session import ZenohSession  # noqa: E402

ACTION = "control_msgs/action/FollowJointTrajectory"
JOINTS = [f"joint_{i}" for i in range(1, 7)]
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6
INVALID_GOAL, INVALID_JOINTS = -1, -2
WAIT_S = 20.0  # bounds for answers and messages, not sleeps: each returns as soon as it arrives


@pytest.fixture(scope="module")
def system(tmp_path_factory: pytest.TempPathFactory) -> Iterator[System]:
    message_registry._registry = None
    message_registry.get_registry(str(msgdefs.write(tmp_path_factory.mktemp("msg"))))
    with running("kr16", dummy=False) as system:
        ZenohSession._instance = None
        session = ZenohSession.get_instance("127.0.0.1", system.router_port)
        for name in msgdefs.ORDER:  # the SDK's type store needs nested types first
            session.register_message_type(msgdefs.MSG[name], name)
        yield system
        ZenohSession.get_instance().close()


class Peer:
    """The action's client side, as the SDK's service clients (one per action service)."""

    def __init__(self) -> None:
        def client(service: str, type_name: str, defs: tuple[str, str]) -> Any:
            return zsdk.ROS2ServiceClient(f"/follow_joint_trajectory/_action/{service}", type_name,
                                          request_definition=defs[0], response_definition=defs[1],
                                          type_hash=idl.type_hash(type_name), timeout=WAIT_S)

        self.send = client("send_goal", f"{ACTION}_SendGoal", msgdefs.SEND_GOAL)
        self.result = client("get_result", f"{ACTION}_GetResult", msgdefs.GET_RESULT)
        self.cancel = client("cancel_goal", "action_msgs/srv/CancelGoal", msgdefs.CANCEL_GOAL)
        self.types = ZenohSession.get_instance().store.types

    def close(self) -> None:
        for client in (self.send, self.result, self.cancel):
            client.close()

    def goal(self, points: list[tuple[float, list[float]]], joints: list[str] = JOINTS) -> tuple[Any, bytes]:
        """Send a goal of (seconds, degrees) points at rest (zero velocities and accelerations)."""
        T = self.types
        time_ = T["builtin_interfaces/msg/Time"]
        duration = T["builtin_interfaces/msg/Duration"]
        header = T["std_msgs/msg/Header"](stamp=time_(sec=0, nanosec=0), frame_id="")
        zeros = np.zeros(len(joints))

        def point(t: float, q: list[float]) -> Any:
            return T["trajectory_msgs/msg/JointTrajectoryPoint"](
                positions=np.radians(np.asarray(q, float)), velocities=zeros, accelerations=zeros,
                effort=np.zeros(0), time_from_start=duration(sec=int(t), nanosec=int(round((t % 1) * 1e9))))

        goal = T[f"{ACTION}_Goal"](
            trajectory=T["trajectory_msgs/msg/JointTrajectory"](
                header=header, joint_names=joints, points=[point(t, q) for t, q in points]),
            multi_dof_trajectory=T["trajectory_msgs/msg/MultiDOFJointTrajectory"](
                header=header, joint_names=[], points=[]),
            path_tolerance=[], component_path_tolerance=[], goal_tolerance=[], component_goal_tolerance=[],
            goal_time_tolerance=duration(sec=0, nanosec=0))
        goal_id = uuid.uuid4().bytes
        uuid_msg = T["unique_identifier_msgs/msg/UUID"](uuid=np.frombuffer(goal_id, np.uint8).copy())
        return self.send.call(goal_id=uuid_msg, goal=goal), goal_id

    def uuid(self, goal_id: bytes) -> Any:
        return self.types["unique_identifier_msgs/msg/UUID"](uuid=np.frombuffer(goal_id, np.uint8).copy())

    def wait_result(self, goal_id: bytes) -> Any:
        return self.result.call(goal_id=self.uuid(goal_id))


@pytest.fixture
def peer(system: System) -> Iterator[Peer]:
    peer = Peer()
    yield peer
    peer.close()


def _joints(client: Client) -> list[float]:
    return [float(v) for v in client.ask("GetPositionJoints").split()]


def test_a_goal_moves_the_arm(system: System, peer: Peer) -> None:
    client = Client(system.port)
    try:
        start = _joints(client)
        target = [start[0] + 8.0, start[1] - 5.0, *start[2:5], start[5] + 10.0]
        response, goal_id = peer.goal([(0.0, start), (1.5, target)])
        assert response.accepted
        result = peer.wait_result(goal_id)
        assert (result.status, result.result.error_code, result.result.error_string) == (SUCCEEDED, 0, "")
        assert _joints(client) == pytest.approx(target, abs=1e-4)
    finally:
        client.close()


def test_a_point_outside_the_limits_is_refused_and_nothing_moves(system: System, peer: Peer) -> None:
    client = Client(system.port)
    try:
        start = _joints(client)
        outside = [start[0], start[1], start[2], start[3], start[4], 10_000.0]
        response, goal_id = peer.goal([(0.0, start), (2.0, outside)])
        assert response.accepted  # and ended at once, with the reason
        result = peer.wait_result(goal_id)
        assert (result.status, result.result.error_code) == (ABORTED, INVALID_GOAL)
        assert "joint 6" in result.result.error_string and "turn limits" in result.result.error_string
        assert _joints(client) == start
    finally:
        client.close()


def test_wrong_joint_names_are_invalid_joints(system: System, peer: Peer) -> None:
    client = Client(system.port)
    try:
        start = _joints(client)
    finally:
        client.close()
    _response, goal_id = peer.goal([(0.0, start), (1.0, start)], joints=[*JOINTS[:5], "wrist"])
    result = peer.wait_result(goal_id)
    assert (result.status, result.result.error_code) == (ABORTED, INVALID_JOINTS)
    assert "wrist" in result.result.error_string


def test_cancel_stops_the_arm_within_its_limits(system: System, peer: Peer) -> None:
    feedback: queue.Queue[Any] = queue.Queue()
    subscriber = zsdk.ROS2Subscriber("/follow_joint_trajectory/_action/feedback", f"{ACTION}_FeedbackMessage",
                                     feedback.put, msg_definition=msgdefs.MSG[f"{ACTION}_FeedbackMessage"])
    states: queue.Queue[Any] = queue.Queue()
    joint_states = zsdk.ROS2Subscriber("/joint_states", "sensor_msgs/msg/JointState", states.put,
                                       msg_definition=msgdefs.MSG["sensor_msgs/msg/JointState"])
    client = Client(system.port)
    try:
        start = _joints(client)
        target = [start[0] + 40.0, *start[1:]]
        response, goal_id = peer.goal([(0.0, start), (6.0, target)])
        assert response.accepted
        moving = feedback.get(timeout=WAIT_S)  # the goal runs: the feedback says where it is
        assert bytes(moving.goal_id.uuid) == goal_id
        cancel = peer.cancel.call(goal_info=peer.types["action_msgs/msg/GoalInfo"](
            goal_id=peer.uuid(goal_id), stamp=peer.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0)))
        assert cancel.return_code == 0 and len(cancel.goals_canceling) == 1
        result = peer.wait_result(goal_id)
        assert result.status == CANCELED, result.result.error_string
        stopped = _joints(client)
        assert start[0] < stopped[0] < target[0]  # stopped on the way, not at the end
        speed = get_robot("kr16").default_speed[0]
        seen = []
        while not states.empty():
            seen.append(abs(math.degrees(states.get_nowait().velocity[0])))
        assert seen and max(seen) <= speed * (1 + 1e-6)
    finally:
        client.close()
        subscriber.close()
        joint_states.close()


def test_one_robot_one_motion(system: System, peer: Peer) -> None:
    client = Client(system.port)
    try:
        start = _joints(client)
        # a goal runs: the old client's motion command gets ERROR and false, nothing else moves
        target = [start[0] - 20.0, *start[1:]]
        _response, goal_id = peer.goal([(0.0, start), (3.0, target)])
        reply = client.ask("MovePTPJoints " + " ".join(f"{v:.6f}" for v in start), lines=2)
        assert reply.startswith("ERROR: the arm is executing a ROS 2 FollowJointTrajectory goal") and \
            reply.endswith("false\n"), reply
        assert peer.wait_result(goal_id).status == SUCCEEDED
        # the old client moves the arm: a goal is refused, with the reason
        moving = threading.Thread(target=client.ask, args=("MovePTPJoints " + " ".join(f"{v:.6f}" for v in start),))
        states: queue.Queue[Any] = queue.Queue()
        joint_states = zsdk.ROS2Subscriber("/joint_states", "sensor_msgs/msg/JointState", states.put,
                                           msg_definition=msgdefs.MSG["sensor_msgs/msg/JointState"])
        try:
            moving.start()
            while max(abs(v) for v in states.get(timeout=WAIT_S).velocity) < 1e-3:
                pass  # until the joint states show the arm moving
            here = [math.degrees(p) for p in states.get(timeout=WAIT_S).position]
            _response, goal_id = peer.goal([(0.0, here), (3.0, target)])
            result = peer.wait_result(goal_id)
            assert (result.status, result.result.error_code) == (ABORTED, INVALID_GOAL)
            assert "client of the rob6 protocol" in result.result.error_string
        finally:
            moving.join(WAIT_S)
            joint_states.close()
        assert _joints(client) == pytest.approx(start, abs=1e-4)
    finally:
        client.close()
