"""Autoware: the IMU's entry of ``sensor_kit_calibration.yaml``.

Autoware's sensor kit description loads this file with ``xacro.load_yaml`` and writes each entry
as a URDF joint ``<origin xyz="x y z" rpy="roll pitch yaw"/>`` from the parent (the YAML's
top-level key, ``sensor_kit_base_link``) to the sensor frame (Autoware documentation, "Creating
vehicle and sensor description"; ``sample_sensor_kit_description``): metres and radians,
fixed-axis roll, pitch, yaw, as in :mod:`mountcal.outputs.exporters.ros`. mountcal's rotation is from the
IMU to ``base_link``: it is the entry under ``sensor_kit_base_link`` only when that frame's axes
are parallel to ``base_link`` (zero roll, pitch, yaw in ``sensors_calibration.yaml``); otherwise
export with ``--parent base_link`` into ``sensors_calibration.yaml``.
"""

from __future__ import annotations

from mountcal.conventions import angles_from_rot_vs
from mountcal.outputs.exporters.common import Mounting, number
from mountcal.outputs.exporters.ros import Frames, sigma_lines

DEFAULT_FRAMES = Frames(parent="sensor_kit_base_link", child="imu_link")


def autoware_yaml(mount: Mounting, frames: Frames = DEFAULT_FRAMES) -> str:
    """The YAML entry (parent → child: x, y, z in m; roll, pitch, yaw in rad)."""
    roll, pitch, yaw = angles_from_rot_vs(mount.rot_vs)
    x, y, z = frames.translation_m
    lines = sigma_lines(mount, "#")
    if frames.parent != "base_link":
        lines.append(f"# valid when {frames.parent} is parallel to base_link (its roll, pitch, yaw all 0)")
    lines += [f"{frames.parent}:", f"  {frames.child}:"]
    for key, value, digits in (
        ("x", x, 9),
        ("y", y, 9),
        ("z", z, 9),
        ("roll", roll, 12),
        ("pitch", pitch, 12),
        ("yaw", yaw, 12),
    ):
        lines.append(f"    {key}: {number(value, digits)}")
    return "\n".join(lines) + "\n"
