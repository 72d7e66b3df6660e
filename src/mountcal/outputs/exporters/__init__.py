"""Hand a calibration to the systems that use it, each in its vendor's own conventions.

``mountcal export result.json --to FORMAT`` (:mod:`mountcal.cli.export`). Every format is built
from one :class:`Mounting` (the rotation, its σ, what was assumed), which refuses a result whose
yaw is not determined or that is not confident unless told otherwise. Definitions and sources: docs/exporters.md.
"""

from __future__ import annotations

from collections.abc import Callable

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.result import Calibration
from mountcal.outputs.exporters.autoware import DEFAULT_FRAMES as AUTOWARE_FRAMES
from mountcal.outputs.exporters.autoware import autoware_yaml, read_parent_pose
from mountcal.outputs.exporters.common import Mounting, YawPolicy, mounting
from mountcal.outputs.exporters.novatel import novatel_rotation, novatel_text
from mountcal.outputs.exporters.ros import (
    BODY_FRAME,
    Frames,
    ParentPose,
    static_transform_command,
    tf2_quaternion,
    urdf_joint,
)
from mountcal.outputs.exporters.rotation import rotation_json, rotation_yaml
from mountcal.outputs.exporters.ublox import ublox_mount, ublox_text, ucenter_config, valsets

Writer = Callable[[Mounting, Frames], str | bytes]

FORMATS: dict[str, Writer] = {
    "ublox": lambda m, f: ublox_text(ublox_mount(m)),
    "ublox-ucenter": lambda m, f: ucenter_config(ublox_mount(m).messages),
    "ublox-ubx": lambda m, f: valsets(ublox_mount(m)),
    "novatel": lambda m, f: novatel_text(novatel_rotation(m)),
    "ros2-static-tf": static_transform_command,
    "urdf": urdf_joint,
    "tf2": tf2_quaternion,
    "autoware": autoware_yaml,
    "json": lambda m, f: rotation_json(m),
    "yaml": lambda m, f: rotation_yaml(m),
}
DEFAULT_FRAMES = {"ros2-static-tf": Frames(), "urdf": Frames(), "tf2": Frames(), "autoware": AUTOWARE_FRAMES}
TEXT_FORMATS = tuple(f for f in FORMATS if f != "ublox-ubx")
SUFFIXES: dict[str, tuple[str, ...]] = {  # an output file's suffix → the formats it can hold (export -o)
    ".ubx": ("ublox-ubx",),
    ".json": ("json",),
    ".yaml": ("yaml", "autoware"),
    ".yml": ("yaml", "autoware"),
    ".urdf": ("urdf",),
    ".xacro": ("urdf",),
    ".xml": ("urdf",),
    ".txt": TEXT_FORMATS,
    ".sh": ("ros2-static-tf",),
}


def export(
    cal: Calibration,
    fmt: str,
    *,
    yaw: YawPolicy = "refuse",
    accept_unconfident: bool = False,
    frames: Frames | None = None,
) -> str | bytes:
    """The calibration in ``fmt`` (text, or bytes for ``ublox-ubx``).

    ``frames`` (parent, child, translation, the parent's pose) applies to the formats that name
    frames (:data:`DEFAULT_FRAMES`); giving it to another format is refused, not ignored.
    """
    if fmt not in FORMATS:
        raise InputError("the export format", f"one of {', '.join(FORMATS)}", repr(fmt), "Choose a listed format.")
    if frames is not None and fmt not in DEFAULT_FRAMES:
        raise InputError(
            f"export --to {fmt}",
            f"no frame names, translation or parent pose (they apply to {', '.join(DEFAULT_FRAMES)})",
            f"parent {frames.parent!r}, child {frames.child!r}, translation {frames.translation_m}",
            "Leave them out for this format.",
        )
    if frames is not None and frames.parent == BODY_FRAME and frames.parent_pose is not None:
        raise InputError(
            f"the parent frame {BODY_FRAME}",
            f"no pose of its own (the pose of a parent is given in {BODY_FRAME})",
            f"a pose from {frames.parent_pose.source}",
            f"Name the parent that pose belongs to ({option('parent')}), or leave the pose out.",
        )
    chosen = frames if frames is not None else DEFAULT_FRAMES.get(fmt, Frames())
    return FORMATS[fmt](mounting(cal, yaw, accept_unconfident), chosen)


__all__ = [
    "DEFAULT_FRAMES",
    "FORMATS",
    "SUFFIXES",
    "Frames",
    "Mounting",
    "ParentPose",
    "export",
    "mounting",
    "read_parent_pose",
]
