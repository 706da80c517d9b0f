"""FollowJointTrajectory on a kr16rt over RSI against the stand-in KR C4 (kuka-rsi-sim), real UDP
every 4 ms: a goal and a cancelled goal from the independent peer (zenoh-ros2-sdk), and the
controller never trips."""

from __future__ import annotations

import queue
import socket
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from harness.ports import free_port
from harness.system import System
from tests.motion.link_session import joints
from tests.motion.test_rsi_realtime import POSITION_TOL, assert_no_jump, connected, controller, rsi_system

zsdk = pytest.importorskip("zenoh_ros2_sdk")
from tests.ros import msgdefs  # noqa: E402
from tests.ros.peer import ACTION, WAIT_S, Peer, connect  # noqa: E402

pytestmark = pytest.mark.slow
SUCCEEDED, CANCELED = 4, 5


@pytest.fixture(scope="module")
def rsi(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[System, int]]:
    port = free_port(socket.SOCK_DGRAM)
    with rsi_system(port) as system:
        session = connect(system.router_port, tmp_path_factory.mktemp("msg"))
        yield system, port
        session.close()


def test_goals_over_rsi_without_a_trip(rsi: tuple[System, int]) -> None:
    system, port = rsi
    with controller(port) as kuka, system.client() as client:
        start = connected(client, kuka, system).tolist()
        peer = Peer()
        feedback: queue.Queue[Any] = queue.Queue()
        subscriber = zsdk.ROS2Subscriber("/follow_joint_trajectory/_action/feedback", f"{ACTION}_FeedbackMessage",
                                         feedback.put, msg_definition=msgdefs.MSG[f"{ACTION}_FeedbackMessage"])
        try:
            target = [start[0] + 15.0, start[1] + 5.0, start[2] - 5.0, *start[3:5], start[5] + 20.0]
            response, goal_id = peer.goal([(0.0, start), (2.0, target)])
            assert response.accepted
            result = peer.wait_result(goal_id)
            assert (result.status, result.result.error_code) == (SUCCEEDED, 0), result.result.error_string
            assert np.allclose(joints(client), target, atol=POSITION_TOL)
            assert np.allclose(kuka.status()["aipos"], target, atol=POSITION_TOL)
            # a longer goal, cancelled once it runs: the arm stops on its ramp, the controller with it
            _response, goal_id = peer.goal([(0.0, target), (5.0, start)])
            while bytes(feedback.get(timeout=WAIT_S).goal_id.uuid) != goal_id:
                pass  # feedback of the first goal may still be queued
            cancel = peer.cancel.call(goal_info=peer.types["action_msgs/msg/GoalInfo"](
                goal_id=peer.uuid(goal_id), stamp=peer.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0)))
            assert cancel.return_code == 0
            assert peer.wait_result(goal_id).status == CANCELED
            stopped = joints(client)
            assert start[0] < stopped[0] < target[0]
            assert np.allclose(kuka.status()["aipos"], stopped, atol=POSITION_TOL)
            assert_no_jump(kuka.status())  # 0 trips, no correction step beyond the rated speeds
        finally:
            subscriber.close()
            peer.close()
