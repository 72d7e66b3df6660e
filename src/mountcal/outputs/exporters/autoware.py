"""Autoware: the IMU's entry of ``sensor_kit_calibration.yaml`` (or of ``sensors_calibration.yaml``).

Autoware's sensor description (Autoware documentation, "Creating a sensor model for Autoware";
``sample_sensor_kit_description``) keeps two files, each ``parent: {child: {x, y, z, roll, pitch,
yaw}}`` in metres and radians, which its xacros turn into URDF joints ``<origin xyz="x y z"
rpy="roll pitch yaw"/>`` (fixed-axis roll, pitch, yaw: :mod:`mountcal.outputs.exporters.ros`):

- ``sensors_calibration.yaml``: ``base_link`` → ``sensor_kit_base_link`` (and sensors mounted on the
  body directly);
- ``sensor_kit_calibration.yaml``: ``sensor_kit_base_link`` → each sensor of the kit.

mountcal's rotation is the IMU's orientation in ``base_link`` (the REP 103 body frame). The kit's
base is itself turned (the sample kit's by roll −0.001, pitch 0.015, yaw −0.0364 rad: 2.1° of yaw),
so the entry under ``sensor_kit_base_link`` is composed with that pose, read from
``sensors_calibration.yaml`` (:func:`read_parent_pose`): ``R_kit←imu = R_base←kitᵀ · R_base←imu``.
Without that pose only ``base_link`` itself can be the parent.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.outputs.exporters.common import BODY_FRAME, Exporter, ExportOptions, Frames, Mounting, ParentPose, number
from mountcal.outputs.exporters.ros import frame_lines

if TYPE_CHECKING:
    from mountcal.core.result import Calibration

DEFAULT_FRAMES = Frames(parent="sensor_kit_base_link")  # child: the IMU's frame (imu_link when the log named none)
POSE_KEYS = ("x", "y", "z", "roll", "pitch", "yaw")


def autoware_yaml(mount: Mounting, frames: Frames = DEFAULT_FRAMES) -> str:
    """The YAML entry (parent → child: x, y, z in m; roll, pitch, yaw in rad)."""
    if frames.parent != BODY_FRAME and frames.parent_pose is None:
        raise InputError(
            f"the Autoware parent frame {frames.parent}",
            f"its pose in {BODY_FRAME} (mountcal's rotation is the IMU's orientation in {BODY_FRAME})",
            "none given",
            f"Give the sensors_calibration.yaml that places {frames.parent} ({option('parent_pose')}), or write "
            f"the entry under {BODY_FRAME} ({option('parent', BODY_FRAME)}).",
        )
    from mountcal.core.conventions import angles_from_rot_vs

    roll, pitch, yaw = angles_from_rot_vs(frames.in_parent(mount.rot_vs))
    x, y, z = frames.translation_m
    lines = frame_lines(mount, frames, "#")
    lines += [f"{_key(frames.parent)}:", f"  {_key(frames.child_name)}:"]
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


def _key(name: str) -> str:
    """A frame name as a YAML key that reads back as that string: plain, or quoted where YAML would read another
    type (``on``, ``null``, ``1``: a boolean, nothing, a number). The name's characters are checked before
    (:func:`mountcal.outputs.exporters.child.check_name`)."""
    import json

    import yaml  # PyYAML, the parser of Autoware's xacro tools

    return name if yaml.safe_load(name) == name else json.dumps(name)


def read_parent_pose(path: str | Path, parent: str) -> ParentPose:
    """The pose of ``parent`` in ``base_link`` from an Autoware ``sensors_calibration.yaml``.

    The file holds ``base_link: {parent: {x, y, z, roll, pitch, yaw}}``; roll, pitch and yaw are the
    URDF joint's fixed-axis angles in radians.
    """
    import yaml  # PyYAML: imported here, so that the rest of mountcal does not load it

    where = str(path)
    if parent == BODY_FRAME:
        raise InputError(
            f"{where} for the parent frame {BODY_FRAME}",
            f"a parent other than {BODY_FRAME} (poses are given in {BODY_FRAME}; it has none of its own)",
            f"the parent {BODY_FRAME}",
            f"Name the parent the pose belongs to ({option('parent', 'sensor_kit_base_link')}), or leave the pose out.",
        )
    try:
        doc: Any = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(where, "a readable YAML file", f"{type(exc).__name__}: {exc}", "Check the path.") from exc
    except yaml.YAMLError as exc:
        raise InputError(where, "YAML", f"a syntax error ({exc})", "Give Autoware's sensors_calibration.yaml.") from exc
    top = doc if isinstance(doc, dict) else {}
    entry = top.get(BODY_FRAME, {}).get(parent) if isinstance(top.get(BODY_FRAME), dict) else None
    if not isinstance(entry, dict):
        keys = sorted(map(str, top))
        found = f"top-level keys {', '.join(keys[:6])}{', …' if len(keys) > 6 else ''}" if top else "no mapping"
        hint = (
            " That looks like sensor_kit_calibration.yaml, which places the sensors in the kit; the kit's own "
            "pose is in sensors_calibration.yaml."
            if parent in top
            else ""
        )
        raise InputError(
            where,
            f"{BODY_FRAME}: {{{parent}: {{x, y, z, roll, pitch, yaw}}}} (Autoware's sensors_calibration.yaml)",
            found,
            f"Give the file that places {parent} in {BODY_FRAME}.{hint}",
        )
    values = {}
    for key in POSE_KEYS:
        value = entry.get(key)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise InputError(
                f"{where}: {BODY_FRAME}/{parent}/{key}",
                "a number (metres, or radians for roll, pitch, yaw)",
                repr(value),
                "Fix the entry.",
            )
        values[key] = float(value)
    from mountcal.core.conventions import rot_vs_from_angles

    rotation = rot_vs_from_angles(values["roll"], values["pitch"], values["yaw"])  # URDF rpy = Rz·Ry·Rx
    return ParentPose(rotation, f"{Path(path).name}: {BODY_FRAME}/{parent}")


def _write(cal: Calibration, options: ExportOptions) -> str:
    return autoware_yaml(options.mounting(cal), options.frames or DEFAULT_FRAMES)


EXPORTERS = (
    Exporter(
        "autoware",
        (".yaml", ".yml", ".txt"),
        "Autoware: the IMU's entry of sensor_kit_calibration.yaml (x, y, z, roll, pitch, yaw)",
        _write,
        DEFAULT_FRAMES,
    ),
)
