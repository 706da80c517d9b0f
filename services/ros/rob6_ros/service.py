"""The ROS 2 service of one robot: its joint states and robot description as a ROS 2 node.

The node (``rob6`` by default, in ``ROB6_ROS_NAMESPACE``) publishes on rob6's own Zenoh
session, in rmw_zenoh's format (``rmw``):

* ``joint_states`` (sensor_msgs/JointState): the URDF's joint names, positions in radians
  (rob6's URDF joint value is the robot's joint angle, ``rob6_kinematics.urdf``) and
  velocities in rad/s, from the driver's state; at most ``max_rate_hz`` (100 Hz) while the
  arm moves, and every state the driver publishes at rest (10 Hz);
* ``robot_description`` (std_msgs/String, transient local, depth 1): the URDF rob6 already
  has, kept by the publisher for late joiners as rmw_zenoh does.

and serves the action ``follow_joint_trajectory`` (control_msgs/FollowJointTrajectory,
``action``), whose goals the planner checks and the driver executes like every motion.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import xml.etree.ElementTree as ET
from typing import Any

from rob6.bus import Bus, decode
from rob6.messages import JointState
from rob6.robots import RobotModel

from .action import DEFAULT_START_TOLERANCE_DEG, FollowJointTrajectoryServer
from .rmw import LATCHED_QOS, Node

log = logging.getLogger("rob6.ros")

#: joint_states while the arm moves: at most this often (the driver's cycle is 4-16 ms)
MAX_RATE_HZ = 100.0


def urdf_joint_names(urdf: str) -> list[str]:
    """The movable joints of a URDF in document order (rob6's URDFs list joint_1..joint_6 in order)."""
    root = ET.fromstring(urdf)
    return [j.attrib["name"] for j in root.iter("joint") if j.attrib.get("type") in ("revolute", "continuous",
                                                                                     "prismatic")]


def stamp(seconds: float) -> dict[str, int]:
    sec = math.floor(seconds)
    return {"sec": int(sec), "nanosec": int(round((seconds - sec) * 1e9)) % 1_000_000_000}


class RosService:
    def __init__(self, bus: Bus, robot: RobotModel, *, namespace: str = "/", domain_id: int = 0,
                 distro: str = "jazzy", node_name: str = "rob6", max_rate_hz: float = MAX_RATE_HZ,
                 action: str = "follow_joint_trajectory",
                 start_tolerance: float = DEFAULT_START_TOLERANCE_DEG):
        self.bus, self.robot = bus, robot
        self.urdf = robot.urdf
        self.joint_names = urdf_joint_names(self.urdf)
        if len(self.joint_names) != 6:
            raise ValueError(f"{robot.geometry}.urdf has {len(self.joint_names)} movable joints, expected 6")
        self.node = Node(bus.session, node_name, namespace=namespace, domain_id=domain_id, distro=distro)
        self.min_period = 1.0 / max_rate_hz
        self._last_sent = -math.inf
        self._lock = threading.Lock()
        self.latest: JointState | None = None
        self._stopped = False  # under _lock: no joint state goes out after the node closed
        self.joint_states = self.node.publisher("joint_states", "sensor_msgs/msg/JointState")
        self.description = self.node.publisher("robot_description", "std_msgs/msg/String", LATCHED_QOS)
        self.action = FollowJointTrajectoryServer(self.node, bus, self.joint_names, lambda: self.latest,
                                                  name=action, start_tolerance=start_tolerance) if action else None

    def start(self) -> None:
        self.description.publish({"data": self.urdf})
        self._states = self.bus.subscribe("driver/state", self._on_state, owner="driver")
        self.bus.announce()
        log.info("ROS 2 node %s up: %s", self.node.name, self.joint_states.key)

    def _on_state(self, _key: str, payload: bytes) -> None:
        state = decode(JointState, payload)
        with self._lock:
            self.latest = state
            now = time.monotonic()
            if self._stopped or (state.moving and now - self._last_sent < self.min_period):
                return
            self._last_sent = now
            self.joint_states.publish(self.joint_state_message(state))

    def joint_state_message(self, state: JointState) -> dict[str, Any]:
        return {"header": {"stamp": stamp(time.time()), "frame_id": ""}, "name": self.joint_names,
                "position": [math.radians(q) for q in state.q], "velocity": [math.radians(v) for v in state.qd],
                "effort": []}

    def stop(self) -> None:
        self._states.undeclare()
        with self._lock:  # a state on its way out goes first
            self._stopped = True
        self.node.close()
