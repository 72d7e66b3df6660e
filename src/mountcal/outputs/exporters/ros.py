"""ROS 2: ``static_transform_publisher``, a URDF ``<joint>``, a tf2 quaternion.

REP 103 makes ``base_link`` x forward, y left, z up: mountcal's vehicle frame. A tf transform
from ``frame_id`` (parent) to ``child_frame_id`` is the child's pose in the parent, mapping child
coordinates to parent coordinates (tf2 ``static_transform_publisher`` documentation; URDF joint
``<origin>``: "the transform from the parent link to the child link"). With the IMU's frame as
the child, its rotation is ``rot_vs`` itself. URDF ``rpy`` are fixed-axis roll about x, then
pitch about y, then yaw about z, radians (URDF XML specification, joint/origin), i.e.
``Rz(yaw)·Ry(pitch)·Rx(roll)``: mountcal's convention. Translation is not estimated by mountcal:
it is written as given (default 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mountcal.conventions import angles_from_rot_vs
from mountcal.outputs.exporters.common import Mounting, number, propagate_sigma


@dataclass(frozen=True)
class Frames:
    """Frame names and the IMU's position in the parent frame (m), for ROS and Autoware."""

    parent: str = "base_link"
    child: str = "imu_link"
    translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


def quaternion_xyzw(mount: Mounting) -> np.ndarray:
    """The tf2 quaternion (x, y, z, w) of the child (IMU) frame in the parent, w ≥ 0."""
    q = mount.rot_vs.as_quat()
    return -q if q[3] < 0 else q


def sigma_lines(mount: Mounting, prefix: str) -> list[str]:
    sig = propagate_sigma(lambda r: np.array(angles_from_rot_vs(r)), mount, np.array([2 * np.pi] * 3))
    text = ", ".join(
        f"{name} {'not determined' if s is None else f'{s:.3g}'}"
        for name, s in zip(("roll", "pitch", "yaw"), sig, strict=True)
    )
    lines = [f"{prefix} {h}" for h in mount.header]
    return [*lines, f"{prefix} 1σ of the fixed-axis roll, pitch, yaw (rad): {text}"]


def static_transform_command(mount: Mounting, frames: Frames = Frames()) -> str:
    """``ros2 run tf2_ros static_transform_publisher`` with the Humble+ named arguments."""
    x, y, z = (number(v) for v in frames.translation_m)
    qx, qy, qz, qw = (number(float(v), 12) for v in quaternion_xyzw(mount))
    lines = sigma_lines(mount, "#")
    lines.append(
        f"ros2 run tf2_ros static_transform_publisher --x {x} --y {y} --z {z} "
        f"--qx {qx} --qy {qy} --qz {qz} --qw {qw} --frame-id {frames.parent} --child-frame-id {frames.child}"
    )
    return "\n".join(lines) + "\n"


def urdf_joint(mount: Mounting, frames: Frames = Frames(), name: str | None = None) -> str:
    """A fixed URDF joint placing the IMU's link in the parent link."""
    roll, pitch, yaw = angles_from_rot_vs(mount.rot_vs)
    xyz = " ".join(number(v) for v in frames.translation_m)
    rpy = " ".join(number(v, 12) for v in (roll, pitch, yaw))
    comments = [f"<!-- {line[2:]} -->" for line in sigma_lines(mount, "#")]
    joint = name or f"{frames.child}_joint"
    return (
        "\n".join(
            [
                *comments,
                f'<joint name="{joint}" type="fixed">',
                f'  <parent link="{frames.parent}"/>',
                f'  <child link="{frames.child}"/>',
                f'  <origin xyz="{xyz}" rpy="{rpy}"/>',
                "</joint>",
            ]
        )
        + "\n"
    )


def tf2_quaternion(mount: Mounting, frames: Frames = Frames()) -> str:
    """The quaternion of ``parent → child`` for C++ and Python tf2 code."""
    qx, qy, qz, qw = (number(float(v), 12) for v in quaternion_xyzw(mount))
    lines = sigma_lines(mount, "//")
    lines += [
        f"// tf2 rotation {frames.parent} -> {frames.child} (x, y, z, w): child coordinates to parent coordinates",
        f"tf2::Quaternion q({qx}, {qy}, {qz}, {qw});",
        f"// Python: geometry_msgs.msg.Quaternion(x={qx}, y={qy}, z={qz}, w={qw})",
    ]
    return "\n".join(lines) + "\n"
