"""The action's client side for the tests: zenoh-ros2-sdk's service clients and its type store.

zenoh-ros2-sdk would fetch .msg files from GitHub; ``connect`` points its registry at the
definitions of ``msgdefs`` and registers them (nested types first) in its rosbags store.
"""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import Any

import numpy as np
from zenoh_ros2_sdk import ROS2ServiceClient, message_registry
from zenoh_ros2_sdk.session import ZenohSession

from rob6_ros import idl
from tests.ros import msgdefs

ACTION = "control_msgs/action/FollowJointTrajectory"
JOINTS = [f"joint_{i}" for i in range(1, 7)]
WAIT_S = 20.0  # bounds for answers, not sleeps: each call returns as soon as its answer arrives


def connect(router_port: int, msg_dir: Path) -> ZenohSession:
    message_registry._registry = None
    message_registry.get_registry(str(msgdefs.write(msg_dir)))
    ZenohSession._instance = None
    session = ZenohSession.get_instance("127.0.0.1", router_port)
    for name in msgdefs.ORDER:  # the SDK's type store needs nested types first
        session.register_message_type(msgdefs.MSG[name], name)
    return session


class Peer:
    """The action's client side, as the SDK's service clients (one per action service)."""

    def __init__(self) -> None:
        def client(service: str, type_name: str, defs: tuple[str, str]) -> Any:
            return ROS2ServiceClient(f"/follow_joint_trajectory/_action/{service}", type_name,
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
