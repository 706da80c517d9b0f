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
