"""ROS 2: ``static_transform_publisher``, a URDF ``<joint>``, a tf2 quaternion.

REP 103 makes a body frame such as ``base_link`` x forward, y left, z up: mountcal's vehicle frame.
A tf transform from ``frame_id`` (parent) to ``child_frame_id`` is the child's pose in the parent,
mapping child coordinates to parent coordinates (tf2 ``static_transform_publisher`` documentation;
URDF joint ``<origin>``: "the transform from the parent link to the child link"). With the IMU's
frame as the child and a REP 103 body frame aligned with the vehicle as the parent, its rotation is
``rot_vs`` itself. A parent that is turned against the vehicle (a sensor kit's base) needs its pose
in the body frame (:class:`ParentPose`); the rotation written is then ``parentᵀ · rot_vs``. URDF
``rpy`` are fixed-axis roll about x, then pitch about y, then yaw about z, radians (URDF XML
specification, joint/origin), i.e. ``Rz(yaw)·Ry(pitch)·Rx(roll)``: mountcal's convention.
Translation is not estimated by mountcal: it is written as given (default 0).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from mountcal.outputs.exporters.common import (
    BODY_FRAME,
    Exporter,
    ExportOptions,
    Frames,
    Mounting,
    number,
    propagate_sigma,
)

if TYPE_CHECKING:
    import numpy as np

    from mountcal.core.result import Calibration

DEFAULT_FRAMES = Frames()  # base_link -> the IMU's frame (imu_link when the log named none), no translation


def quaternion_xyzw(mount: Mounting, frames: Frames = DEFAULT_FRAMES) -> np.ndarray:
    """The tf2 quaternion (x, y, z, w) of the child (IMU) frame in the parent, w ≥ 0."""
    q: np.ndarray = frames.in_parent(mount.rot_vs).as_quat()  # scipy ships no types
    return -q if q[3] < 0 else q


def frame_lines(mount: Mounting, frames: Frames, prefix: str) -> list[str]:
    """The comment lines every ROS format starts with: what the transform means, its parent, and its σ."""
    import numpy as np

    from mountcal.core.conventions import angles_from_rot_vs

    lines = [f"{prefix} {h}" for h in [*mount.header, *frames.said]]
    lines.append(
        f"{prefix} transform {frames.parent} -> {frames.child_name}: the IMU's pose in {frames.parent}, mapping IMU "
        f"coordinates to {frames.parent} coordinates (p_parent = q p_imu q*)"
    )
    pose = frames.parent_pose
    if pose is None:
        lines.append(
            f"{prefix} {frames.parent} must be a REP 103 body frame aligned with the vehicle: x forward, y left, z up"
        )
    else:
        rpy = " ".join(number(v, 9) for v in angles_from_rot_vs(pose.rotation))
        lines.append(
            f"{prefix} {frames.parent} is turned in {BODY_FRAME} by rpy {rpy} rad (from {pose.source}), "
            f"composed here; its own uncertainty is not in the σ below"
        )
    sig = propagate_sigma(lambda r: np.array(angles_from_rot_vs(frames.in_parent(r))), mount, np.array([2 * np.pi] * 3))
    text = ", ".join(
        f"{name} {'not determined' if s is None else f'{s:.3g}'}"
        for name, s in zip(("roll", "pitch", "yaw"), sig, strict=True)
    )
    return [*lines, f"{prefix} 1σ of the fixed-axis roll, pitch, yaw (rad): {text}"]


def static_transform_command(mount: Mounting, frames: Frames = DEFAULT_FRAMES) -> str:
    """``ros2 run tf2_ros static_transform_publisher`` with the Humble+ named arguments."""
    x, y, z = (number(v) for v in frames.translation_m)
    qx, qy, qz, qw = (number(float(v), 12) for v in quaternion_xyzw(mount, frames))
    lines = frame_lines(mount, frames, "#")
    lines.append(
        f"ros2 run tf2_ros static_transform_publisher --x {x} --y {y} --z {z} "
        f"--qx {qx} --qy {qy} --qz {qz} --qw {qw} --frame-id {frames.parent} --child-frame-id {frames.child_name}"
    )
    return "\n".join(lines) + "\n"


def urdf_joint(mount: Mounting, frames: Frames = DEFAULT_FRAMES, name: str | None = None) -> str:
    """A fixed URDF joint placing the IMU's link in the parent link."""
    from mountcal.core.conventions import angles_from_rot_vs

    roll, pitch, yaw = angles_from_rot_vs(frames.in_parent(mount.rot_vs))
    xyz = " ".join(number(v) for v in frames.translation_m)
    rpy = " ".join(number(v, 12) for v in (roll, pitch, yaw))
    # XML comments may not hold "--"
    comments = [f"<!-- {line[2:].replace('--', '- -')} -->" for line in frame_lines(mount, frames, "#")]
    joint = name or f"{frames.child_name}_joint"
    return (
        "\n".join(
            [
                *comments,
                f'<joint name="{joint}" type="fixed">',
                f'  <parent link="{frames.parent}"/>',
                f'  <child link="{frames.child_name}"/>',
                f'  <origin xyz="{xyz}" rpy="{rpy}"/>',
                "</joint>",
            ]
        )
        + "\n"
    )


def tf2_quaternion(mount: Mounting, frames: Frames = DEFAULT_FRAMES) -> str:
    """The quaternion of ``parent → child`` for C++ and Python tf2 code."""
    qx, qy, qz, qw = (number(float(v), 12) for v in quaternion_xyzw(mount, frames))
    lines = frame_lines(mount, frames, "//")
    lines += [
        f"tf2::Quaternion q({qx}, {qy}, {qz}, {qw});  // x, y, z, w",
        f"// Python: geometry_msgs.msg.Quaternion(x={qx}, y={qy}, z={qz}, w={qw})",
    ]
    return "\n".join(lines) + "\n"


def _writer(fn: Callable[[Mounting, Frames], str]) -> Callable[[Calibration, ExportOptions], str]:
    def write(cal: Calibration, options: ExportOptions) -> str:
        return fn(options.mounting(cal), options.frames or DEFAULT_FRAMES)

    return write


EXPORTERS = (
    Exporter(
        "ros2-static-tf",
        (".sh", ".txt"),
        "ROS 2: the `ros2 run tf2_ros static_transform_publisher` command (parent → IMU frame)",
        _writer(static_transform_command),
        DEFAULT_FRAMES,
    ),
    Exporter(
        "urdf",
        (".urdf", ".xacro", ".xml", ".txt"),
        "URDF: a fixed `<joint>` placing the IMU's link",
        _writer(urdf_joint),
        DEFAULT_FRAMES,
    ),
    Exporter(
        "tf2",
        (".txt",),
        "tf2: the quaternion of parent → IMU frame, for C++ and Python code",
        _writer(tf2_quaternion),
        DEFAULT_FRAMES,
    ),
)
