"""The ROS 2 message definitions (.msg text, as in ROS 2 Jazzy) the independent peer is given.

zenoh-ros2-sdk would fetch them from GitHub, which the test machines cannot reach; it reads
``<dir>/<package>/msg/<Name>.msg`` first, so the tests write these there.
"""

from __future__ import annotations

from pathlib import Path

MSG = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/msg/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/msg/String": "string data\n",
    "sensor_msgs/msg/JointState": "std_msgs/Header header\nstring[] name\nfloat64[] position\n"
                                  "float64[] velocity\nfloat64[] effort\n",
}


def write(directory: Path) -> Path:
    for name, text in MSG.items():
        package, kind, message = name.split("/")
        path = directory / package / kind / f"{message}.msg"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return directory

#: what the FollowJointTrajectory action's services need (control_msgs 5, Jazzy); the action's own
#: parts are named ``control_msgs/action/FollowJointTrajectory_*`` as rosidl names them
MSG.update({
    "unique_identifier_msgs/msg/UUID": "uint8[16] uuid\n",
    "service_msgs/msg/ServiceEventInfo": "uint8 event_type\nbuiltin_interfaces/Time stamp\nchar[16] client_gid\n"
                                         "int64 sequence_number\n",
    "action_msgs/msg/GoalInfo": "unique_identifier_msgs/UUID goal_id\nbuiltin_interfaces/Time stamp\n",
    "action_msgs/msg/GoalStatus": "action_msgs/GoalInfo goal_info\nint8 status\n",
    "action_msgs/msg/GoalStatusArray": "action_msgs/GoalStatus[] status_list\n",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
    "geometry_msgs/msg/Transform": "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    "geometry_msgs/msg/Twist": "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    "trajectory_msgs/msg/JointTrajectoryPoint": "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\n"
                                                "float64[] effort\nbuiltin_interfaces/Duration time_from_start\n",
    "trajectory_msgs/msg/JointTrajectory": "std_msgs/Header header\nstring[] joint_names\n"
                                           "trajectory_msgs/JointTrajectoryPoint[] points\n",
    "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint": "geometry_msgs/Transform[] transforms\n"
                                                        "geometry_msgs/Twist[] velocities\n"
                                                        "geometry_msgs/Twist[] accelerations\n"
                                                        "builtin_interfaces/Duration time_from_start\n",
    "trajectory_msgs/msg/MultiDOFJointTrajectory": "std_msgs/Header header\nstring[] joint_names\n"
                                                   "trajectory_msgs/MultiDOFJointTrajectoryPoint[] points\n",
    "control_msgs/msg/JointTolerance": "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration\n",
    "control_msgs/msg/JointComponentTolerance": "string joint_name\nuint16 component\nfloat64 position\n"
                                                "float64 velocity\nfloat64 acceleration\n",
    "control_msgs/action/FollowJointTrajectory_Goal":
        "trajectory_msgs/JointTrajectory trajectory\ntrajectory_msgs/MultiDOFJointTrajectory multi_dof_trajectory\n"
        "control_msgs/JointTolerance[] path_tolerance\ncontrol_msgs/JointComponentTolerance[] component_path_tolerance\n"
        "control_msgs/JointTolerance[] goal_tolerance\ncontrol_msgs/JointComponentTolerance[] component_goal_tolerance\n"
        "builtin_interfaces/Duration goal_time_tolerance\n",
    "control_msgs/action/FollowJointTrajectory_Result": "int32 error_code\nstring error_string\n",
})
SEND_GOAL = ("unique_identifier_msgs/UUID goal_id\ncontrol_msgs/action/FollowJointTrajectory_Goal goal\n",
             "bool accepted\nbuiltin_interfaces/Time stamp\n")
GET_RESULT = ("unique_identifier_msgs/UUID goal_id\n",
              "int8 status\ncontrol_msgs/action/FollowJointTrajectory_Result result\n")
CANCEL_GOAL = ("action_msgs/GoalInfo goal_info\n", "int8 return_code\naction_msgs/GoalInfo[] goals_canceling\n")
MSG.update({
    "control_msgs/action/FollowJointTrajectory_Feedback":
        "std_msgs/Header header\nstring[] joint_names\ntrajectory_msgs/JointTrajectoryPoint desired\n"
        "trajectory_msgs/JointTrajectoryPoint actual\ntrajectory_msgs/JointTrajectoryPoint error\n"
        "string[] multi_dof_joint_names\ntrajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired\n"
        "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual\n"
        "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error\n",
    "control_msgs/action/FollowJointTrajectory_FeedbackMessage":
        "unique_identifier_msgs/UUID goal_id\ncontrol_msgs/action/FollowJointTrajectory_Feedback feedback\n",
})
#: the order the SDK's type store needs them in (nested types first)
ORDER = list(MSG)
