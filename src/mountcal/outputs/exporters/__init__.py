"""Hand a calibration to the systems that use it, each in its vendor's own conventions.

``mountcal export result.json --to FORMAT`` (:mod:`mountcal.cli.export`). Every format is built
from one :class:`Mounting` (the rotation, its σ, what was assumed), which refuses a result whose
yaw is not determined or that is not confident unless told otherwise. Definitions and sources: docs/exporters.md.
"""

from __future__ import annotations

from collections.abc import Callable

from mountcal.errors import InputError
from mountcal.outputs.exporters.autoware import DEFAULT_FRAMES as AUTOWARE_FRAMES
from mountcal.outputs.exporters.autoware import autoware_yaml
from mountcal.outputs.exporters.common import Mounting, YawPolicy, mounting
from mountcal.outputs.exporters.novatel import novatel_rotation, novatel_text
from mountcal.outputs.exporters.ros import Frames, static_transform_command, tf2_quaternion, urdf_joint
from mountcal.outputs.exporters.rotation import rotation_json, rotation_yaml
from mountcal.outputs.exporters.ublox import ublox_mount, ublox_text, ucenter_config, valset
from mountcal.result import Calibration

Writer = Callable[[Mounting, Frames | None], str | bytes]

FORMATS: dict[str, Writer] = {
    "ublox": lambda m, f: ublox_text(ublox_mount(m)),
    "ublox-ucenter": lambda m, f: ucenter_config(ublox_mount(m).raw),
    "ublox-ubx": lambda m, f: valset(ublox_mount(m).raw),
    "novatel": lambda m, f: novatel_text(novatel_rotation(m)),
    "ros2-static-tf": lambda m, f: static_transform_command(m, f or Frames()),
    "urdf": lambda m, f: urdf_joint(m, f or Frames()),
    "tf2": lambda m, f: tf2_quaternion(m, f or Frames()),
    "autoware": lambda m, f: autoware_yaml(m, f or AUTOWARE_FRAMES),
    "json": lambda m, f: rotation_json(m),
    "yaml": lambda m, f: rotation_yaml(m),
}


def export(
    cal: Calibration,
    fmt: str,
    *,
    yaw: YawPolicy = "refuse",
    accept_unconfident: bool = False,
    frames: Frames | None = None,
) -> str | bytes:
    """The calibration in ``fmt`` (text, or bytes for ``ublox-ubx``)."""
    if fmt not in FORMATS:
        raise InputError("the export format", f"one of {', '.join(FORMATS)}", repr(fmt), "Choose a listed format.")
    return FORMATS[fmt](mounting(cal, yaw, accept_unconfident), frames)


__all__ = ["FORMATS", "Frames", "Mounting", "export", "mounting"]
