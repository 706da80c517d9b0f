"""The ros service's settings: ROS_DOMAIN_ID, the namespace, the distro's format, ROB6_ROS=0.

The graph is read the way rmw_zenoh reads it: a liveliness query for ``@ros2_lv/<domain>/**``
on a plain Zenoh session connected to the system's router.
"""

from __future__ import annotations

import zenoh

from harness.system import System, running

EXPECTED_S = 5.0  # the liveliness query's bound: it returns when the router has answered


def _graph(system: System, domain: int) -> list[str]:
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{system.router_port}"]')
    session = zenoh.open(config)
    try:
        replies = session.liveliness().get(f"@ros2_lv/{domain}/**", timeout=EXPECTED_S)
        return sorted(str(r.ok.key_expr) for r in replies if r.ok is not None)
    finally:
        session.close()


def test_domain_namespace_and_humble_format() -> None:
    env = {"ROS_DOMAIN_ID": "7", "ROB6_ROS_NAMESPACE": "/cell2", "ROB6_ROS_DISTRO": "humble"}
    with running("kr16", extra_env=env) as system:
        tokens = _graph(system, 7)
        assert not _graph(system, 0)
    node = [t for t in tokens if "/NN/" in t]
    assert len(node) == 1 and node[0].endswith("/NN/%/%cell2/rob6")
    publisher = [t for t in tokens if "/MP/" in t and "%cell2%joint_states" in t]
    assert len(publisher) == 1
    assert "/%cell2%joint_states/sensor_msgs::msg::dds_::JointState_/TypeHashNotSupported/::,10:,:,:,," \
        in publisher[0]
    services = [t for t in tokens if "/SS/" in t]
    assert any("%cell2%follow_joint_trajectory%_action%send_goal/"
               "control_msgs::action::dds_::FollowJointTrajectory_SendGoal_/TypeHashNotSupported/" in t
               for t in services)


def test_rob6_ros_0_starts_no_ros_node() -> None:
    with running("kr16", extra_env={"ROB6_ROS": "0"}) as system:
        assert "ros" not in system.pids()
        assert not _graph(system, 0)
