"""The ROS 2 message definitions mountcal writes, as rosbag2 stores them in an MCAP schema.

The standard definitions (field and constant lines; comments left out), concatenated as rosbag2
does: the top-level ``.msg``, then each dependency after a line of 80 ``=`` and
``MSG: package/Type``, depth first, dependencies in sorted order, each once.
"""

from __future__ import annotations

_SEPARATOR = "=" * 80


_MSG = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/Twist": "Vector3  linear\nVector3  angular\n",
    "geometry_msgs/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "sensor_msgs/Imu": (
        "std_msgs/Header header\n\n"
        "geometry_msgs/Quaternion orientation\n"
        "float64[9] orientation_covariance\n\n"
        "geometry_msgs/Vector3 angular_velocity\n"
        "float64[9] angular_velocity_covariance\n\n"
        "geometry_msgs/Vector3 linear_acceleration\n"
        "float64[9] linear_acceleration_covariance\n"
    ),
    "sensor_msgs/Temperature": "std_msgs/Header header\n\nfloat64 temperature\nfloat64 variance\n",
    "sensor_msgs/NavSatStatus": (
        "int8 STATUS_NO_FIX =  -1\nint8 STATUS_FIX =      0\nint8 STATUS_SBAS_FIX = 1\nint8 STATUS_GBAS_FIX = 2\n\n"
        "int8 status\n\n"
        "uint16 SERVICE_GPS =     1\nuint16 SERVICE_GLONASS = 2\nuint16 SERVICE_COMPASS = 4\n"
        "uint16 SERVICE_GALILEO = 8\n\n"
        "uint16 service\n"
    ),
    "sensor_msgs/NavSatFix": (
        "std_msgs/Header header\n\n"
        "NavSatStatus status\n\n"
        "float64 latitude\nfloat64 longitude\nfloat64 altitude\n\n"
        "float64[9] position_covariance\n\n"
        "uint8 COVARIANCE_TYPE_UNKNOWN = 0\nuint8 COVARIANCE_TYPE_APPROXIMATED = 1\n"
        "uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2\nuint8 COVARIANCE_TYPE_KNOWN = 3\n\n"
        "uint8 position_covariance_type\n"
    ),
    "nav_msgs/Odometry": (
        "std_msgs/Header header\n\n"
        "string child_frame_id\n\n"
        "geometry_msgs/PoseWithCovariance pose\n\n"
        "geometry_msgs/TwistWithCovariance twist\n"
    ),
}


_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "string", "wstring"} | {
    f"{s}int{b}" for s in ("", "u") for b in (8, 16, 32, 64)
}


def _dependencies(name: str) -> list[str]:
    """Non-primitive field types of a definition, package-qualified, sorted (rosbag2's std::set)."""
    package = name.split("/", 1)[0]
    deps = set()
    for line in _MSG[name].splitlines():
        words = line.split("#", 1)[0].split()
        if len(words) < 2:
            continue
        base = words[0].split("[", 1)[0]
        if base not in _PRIMITIVES:
            deps.add(base if "/" in base else f"{package}/{base}")
    return sorted(deps)


def ros2_definition(type_name: str) -> str:
    """The complete ``ros2msg`` definition of a message type, concatenated as rosbag2 does.

    Parameters
    ----------
    type_name : str
        ``"sensor_msgs/msg/Imu"``, ``"sensor_msgs/msg/Temperature"``, ``"sensor_msgs/msg/NavSatFix"``
        or ``"nav_msgs/msg/Odometry"``.
    """
    seen: set[str] = set()

    def text(name: str) -> str:
        out = _MSG[name]
        for dep in _dependencies(name):
            if dep not in seen:
                seen.add(dep)
                out += f"\n{_SEPARATOR}\nMSG: {dep}\n" + text(dep)
        return out

    return text(type_name.replace("/msg/", "/"))


__all__ = ["ros2_definition"]
