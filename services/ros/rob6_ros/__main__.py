"""rob6-ros: one robot as a ROS 2 node on rob6's Zenoh network (rmw_zenoh's format)."""

from __future__ import annotations

from collections.abc import Callable

import click

from rob6 import service
from rob6.bus import Bus
from rob6.config import BusSettings, bus_options
from rob6.robots import get_robot

from .action import DEFAULT_START_TOLERANCE_DEG
from .rmw import DISTROS
from .service import MAX_RATE_HZ, RosService


@click.command()
@bus_options
@click.option("--domain-id", envvar="ROS_DOMAIN_ID", default=0, show_default=True, type=click.IntRange(0, 232),
              help="ROS 2 domain id [env ROS_DOMAIN_ID].")
@click.option("--namespace", envvar="ROB6_ROS_NAMESPACE", default="/", show_default=True,
              help="Namespace of the node and its topics [env ROB6_ROS_NAMESPACE].")
@click.option("--node-name", envvar="ROB6_ROS_NODE", default="rob6", show_default=True,
              help="Name of the ROS 2 node [env ROB6_ROS_NODE].")
@click.option("--distro", envvar="ROB6_ROS_DISTRO", default="jazzy", show_default=True,
              type=click.Choice(DISTROS), help="Key-expression format: jazzy and later carry type hashes, "
                                               "humble does not [env ROB6_ROS_DISTRO].")
@click.option("--max-rate", envvar="ROB6_ROS_MAX_RATE", default=MAX_RATE_HZ, show_default=True, type=float,
              help="joint_states at most this often (Hz) while the arm moves [env ROB6_ROS_MAX_RATE].")
@click.option("--action", envvar="ROB6_ROS_ACTION", default="follow_joint_trajectory", show_default=True,
              help="Name of the FollowJointTrajectory action in the node's namespace; empty: no action "
                   "[env ROB6_ROS_ACTION].")
@click.option("--start-tolerance", envvar="ROB6_ROS_START_TOLERANCE", default=DEFAULT_START_TOLERANCE_DEG,
              show_default=True, type=float,
              help="How far (degrees) a goal's point at t = 0 may be from where the arm is "
                   "[env ROB6_ROS_START_TOLERANCE].")
def main(settings: BusSettings, log_level: str, domain_id: int, namespace: str, node_name: str, distro: str,
         max_rate: float, action: str, start_tolerance: float) -> None:
    """The robot to ROS 2 (rmw_zenoh_cpp): joint_states, robot_description, follow_joint_trajectory."""

    def setup(bus: Bus) -> Callable[[], None]:
        ros = RosService(bus, get_robot(settings.robot), namespace=namespace, domain_id=domain_id,
                         distro=distro, node_name=node_name, max_rate_hz=max_rate, action=action,
                         start_tolerance=start_tolerance)
        ros.start()
        return ros.stop

    service.run(settings, "ros", log_level, setup)


if __name__ == "__main__":
    main()
