"""The child frame of an export (the IMU's frame in ROS and Autoware): the frame the calibration's data were in.

A transform is for one named frame. The calibration's sensor frame is the frame its samples were in, which a
ROS log names (``header.frame_id``, recorded in the result as the ``sensor_frame`` convention:
:mod:`mountcal.io.sensor_frame`). So the child defaults to that name; a child the user gives is written as
given (a rename can be deliberate), and when it differs from the recorded frame the output and stderr say
so. A result whose log named no frame gets mountcal's default, ``imu_link``, said to be one; a result whose
log named several frames gets no default (picking one would be a guess): the user names the child. A result
of samples mountcal already rotated (the ``frame`` convention, :mod:`mountcal.io.frame`) is left as before.

The recorded frame's axes are the data's as its messages carry them, which is what a consumer of the
transform rotates (robot_localization, imu_transformer). A calibration made with ``--axes`` has its angles
on the mapped axes, so the transform for the recorded frame composes that map in (``Frames.axes``); a
reflection cannot be composed into a rotation, and is refused.
"""

from __future__ import annotations

import re
from dataclasses import replace
from typing import TYPE_CHECKING

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.terminal import safe
from mountcal.io.sensor_frame import recorded_frame, several
from mountcal.outputs.exporters.common import DEFAULT_CHILD, Frames, user_axes

if TYPE_CHECKING:
    from mountcal.core.result import Calibration

FRAME_NAME = re.compile(r"[A-Za-z0-9_/][A-Za-z0-9_/.-]*")  # what a command, XML and YAML all read as written


def check_name(name: str, role: str) -> None:
    """Refuse a frame name given for ``role`` (``child``, ``parent``) that would be written as something else:
    a shell word split or taken for an option, an XML attribute broken, a YAML comment or mapping."""
    if not FRAME_NAME.fullmatch(name):
        raise InputError(
            f"the {role} frame of the export ({option(role)})",
            "a frame name of letters, digits, '_', '/', '.' and '-', not starting with '-' or '.' (written into "
            "commands, XML and YAML as it is)",
            repr(safe(name)),
            f"Give the frame's name as ROS names it ({option(role)} NAME).",
        )


def with_child(cal: Calibration, frames: Frames) -> Frames:
    """``frames`` with the child named and what the output says of the name (``Frames.said``);
    ``warn`` set when the child given is not the frame the data were in. Frames already resolved
    (``said`` set) are returned as they are.

    Raises
    ------
    InputError
        No child given for a calibration whose log named several IMU frames; a child or parent given whose
        name a command, XML or YAML would misread (:func:`check_name`).
    """
    from mountcal.io.frame import FRAME_CONVENTION  # loads numpy: not when the formats are listed

    if frames.said:
        return frames
    check_name(frames.parent, "parent")
    given = frames.child
    if given is not None:
        check_name(given, "child")
    conventions = cal.provenance.conventions
    if any(c.name == FRAME_CONVENTION for c in conventions):  # rotated samples: their frame is said elsewhere
        return replace(frames, child=given or DEFAULT_CHILD)
    recorded = recorded_frame(conventions)
    if recorded is None:
        said = (
            f"child frame {given}: as given; the calibration's log named no frame"
            if given
            else f"child frame {DEFAULT_CHILD}: mountcal's default (the calibration's log named no frame; "
            f"{option('child')} names another)"
        )
        return replace(frames, child=given or DEFAULT_CHILD, said=(safe(said),))
    if several(recorded):
        if not given:
            raise InputError(
                "the child frame of the export",
                "the one frame the calibration's data were in",
                f"{recorded.value} ({recorded.by})",
                f"Name the IMU's frame the transform is for ({option('child')}).",
            )
        said = (
            f"child frame {given}: as given; the calibration's data were in {recorded.value} "
            f"(stated by {recorded.by}): the transform is written for {given}"
        )
        return replace(frames, said=(safe(said),), warn=True)
    if not given and not FRAME_NAME.fullmatch(recorded.value):
        raise InputError(
            "the child frame of the export",
            "a frame name of letters, digits, '_', '/', '.' and '-' (written into commands and XML as it is)",
            f"the frame {safe(recorded.value)!r} the calibration's data were in ({recorded.by})",
            f"Name the IMU's frame the transform is for ({option('child')}).",
        )
    if not given or given == recorded.value:
        said = f"child frame {recorded.value}: the frame the calibration's data were in (stated by {recorded.by})"
        mapped = user_axes(conventions)
        if mapped is None:
            return replace(frames, child=recorded.value, said=(safe(said),))
        if mapped.reflection:
            raise InputError(
                "the child frame of the export",
                f"a rotation that maps the data of {recorded.value}, as its messages carry them, to {frames.parent}",
                f"a calibration made with {option('axes')} {mapped.text}, a reflection: those data are left-handed, "
                "and no rotation mirrors them",
                f"Fix the axis sign where the data are published (REP 103 frames are right-handed), or name the "
                f"frame of the mapped axes ({option('child')}).",
            )
        said += (
            f"; the calibration's {option('axes')} {mapped.text} is composed in: the transform maps the data of "
            f"{recorded.value} as its messages carry them"
        )
        return replace(frames, child=recorded.value, said=(safe(said),), axes=mapped.text)
    said = (
        f"child frame {given}: as given, NOT the frame the calibration's data were in: they were in frame "
        f"{recorded.value} (stated by {recorded.by}); the transform is written for {given}"
    )
    return replace(frames, said=(safe(said),), warn=True)


__all__ = ["FRAME_NAME", "check_name", "with_child"]
