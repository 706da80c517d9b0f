"""FollowJointTrajectory on the ad850 over simple_message against the stand-in controller
(adept-sm-sim, playing adept_ros.v2): a goal cancelled while the arm moves brings the arm
to rest within the stated bound at monitor speeds 3, 10 and 100 % (the bound and its
check: tests/motion/test_adept_realtime.py)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from harness.system import System
from tests.motion.realtime_rig import free_tcp_ports
from tests.motion.test_adept_realtime import (
    MONITOR_SPEEDS,
    POSITION_TOL,
    START,
    adept_system,
    assert_stopped_within_bound,
    connected,
    controller,
)

zsdk = pytest.importorskip("zenoh_ros2_sdk")
from tests.ros.peer import Peer, connect  # noqa: E402

pytestmark = pytest.mark.slow
SUCCEEDED, CANCELED = 4, 5


@pytest.fixture(scope="module")
def adept(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[System, int, int]]:
    motion, state = free_tcp_ports(2)
    with adept_system(motion, state) as system:
        session = connect(system.router_port, tmp_path_factory.mktemp("msg"))
        yield system, motion, state
        session.close()


@pytest.mark.parametrize("monitor", MONITOR_SPEEDS)
def test_a_cancelled_goal_brings_the_arm_to_rest_within_the_bound(adept: tuple[System, int, int],
                                                                  monitor: str) -> None:
    system, motion, state = adept
    with controller(motion, state, "--monitor-speed", monitor) as ctl, system.client() as client:
        connected(client, ctl, system)
        assert client.ask("MovePTPJoints " + " ".join(map(str, START)), timeout=120) == "true\n"
        peer = Peer()
        try:
            target = [START[0] + 40.0, *START[1:]]
            response, goal_id = peer.goal([(0.0, START), (4.0, target)])
            assert response.accepted
            ctl.wait_for(lambda s: s["position_rob6_deg"][0] > START[0] + 10.0, timeout=30,
                         what="the arm under way")
            cancel = peer.cancel.call(goal_info=peer.types["action_msgs/msg/GoalInfo"](
                goal_id=peer.uuid(goal_id), stamp=peer.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0)))
            assert cancel.return_code == 0
            assert peer.wait_result(goal_id).status == CANCELED
            assert not ctl.status()["in_motion"]  # the result once the arm itself is at rest
            assert_stopped_within_bound(ctl, client, monitor)
            assert START[0] + 10.0 < ctl.status()["position_rob6_deg"][0] < target[0]
            # and the next goal goes from there
            response, goal_id = peer.goal([(0.0, ctl.status()["position_rob6_deg"]), (2.0, START)])
            assert response.accepted and peer.wait_result(goal_id).status == SUCCEEDED
            assert np.allclose(ctl.status()["position_rob6_deg"], START, atol=POSITION_TOL)
        finally:
            peer.close()
