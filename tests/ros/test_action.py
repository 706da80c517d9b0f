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
from collections.abc import Iterator
from typing import Any

import pytest

from harness.client import Client
from harness.system import System, running
from rob6.robots import get_robot
from rob6.units import speed_si
from tests.ros import msgdefs

zsdk = pytest.importorskip("zenoh_ros2_sdk")
from tests.ros.peer import ACTION, JOINTS, WAIT_S, Peer, connect  # noqa: E402

SUCCEEDED, CANCELED, ABORTED = 4, 5, 6
INVALID_GOAL, INVALID_JOINTS = -1, -2


@pytest.fixture(scope="module")
def system(tmp_path_factory: pytest.TempPathFactory) -> Iterator[System]:
    with running("kr16", dummy=False) as system:
        session = connect(system.router_port, tmp_path_factory.mktemp("msg"))
        yield system
        session.close()


@pytest.fixture
def peer(system: System) -> Iterator[Peer]:
    peer = Peer()
    yield peer
    peer.close()


@pytest.fixture
def client(system: System) -> Iterator[Client]:
    """A client of the old protocol (port 5005) for one test."""
    with Client(system.port) as client:
        yield client


def _joints(client: Client) -> list[float]:
    return [float(v) for v in client.ask("GetPositionJoints").split()]


def test_a_goal_moves_the_arm(client: Client, peer: Peer) -> None:
    start = _joints(client)
    target = [start[0] + 8.0, start[1] - 5.0, *start[2:5], start[5] + 10.0]
    response, goal_id = peer.goal([(0.0, start), (1.5, target)])
    assert response.accepted
    result = peer.wait_result(goal_id)
    assert (result.status, result.result.error_code, result.result.error_string) == (SUCCEEDED, 0, "")
    assert _joints(client) == pytest.approx(target, abs=1e-4)


def test_a_point_outside_the_limits_is_refused_and_nothing_moves(client: Client, peer: Peer) -> None:
    start = _joints(client)
    outside = [start[0], start[1], start[2], start[3], start[4], 10_000.0]
    response, goal_id = peer.goal([(0.0, start), (2.0, outside)])
    assert response.accepted  # and ended at once, with the reason
    result = peer.wait_result(goal_id)
    assert (result.status, result.result.error_code) == (ABORTED, INVALID_GOAL)
    assert "joint 6" in result.result.error_string and "turn limits" in result.result.error_string
    assert _joints(client) == start


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
        # cancelled near its top speed (the goal's middle), so the stop starts from a speed that matters
        while math.degrees(moving.feedback.actual.positions[0]) < start[0] + 15.0:
            moving = feedback.get(timeout=WAIT_S)
        cancel = peer.cancel.call(goal_info=peer.types["action_msgs/msg/GoalInfo"](
            goal_id=peer.uuid(goal_id), stamp=peer.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0)))
        assert cancel.return_code == 0 and len(cancel.goals_canceling) == 1
        result = peer.wait_result(goal_id)
        assert result.status == CANCELED, result.result.error_string
        stopped = _joints(client)
        assert start[0] < stopped[0] < target[0]  # stopped on the way, not at the end
        # joint_states velocities are rad/s; the protocol's speed is degrees per 12 ms unit cycle
        speed = speed_si(get_robot("kr16").default_speed)[0]
        seen = []
        while not states.empty():
            seen.append(abs(math.degrees(states.get_nowait().velocity[0])))
        assert 0.5 * speed < max(seen) <= speed * (1 + 1e-6), (max(seen), speed)
    finally:
        client.close()
        subscriber.close()
        joint_states.close()


def test_a_client_leaving_does_not_stop_a_goal(system: System, peer: Peer) -> None:
    with Client(system.port) as client:
        start = _joints(client)
    target = [start[0] + 10.0, *start[1:]]
    response, goal_id = peer.goal([(0.0, start), (1.5, target)])
    assert response.accepted
    with Client(system.port) as reader:  # another client comes, looks and leaves while the goal runs
        assert len(reader.ask("GetPositionJoints").split()) == 6
    result = peer.wait_result(goal_id)
    assert (result.status, result.result.error_string) == (SUCCEEDED, "")
    with Client(system.port) as client:
        assert _joints(client) == pytest.approx(target, abs=1e-4)


def test_one_robot_one_motion(client: Client, peer: Peer) -> None:
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
