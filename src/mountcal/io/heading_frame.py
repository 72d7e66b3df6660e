"""The frame a ROS odometry heading is measured in: the ``header.frame_id`` of the ``nav_msgs/msg/Odometry``
messages whose ``pose.pose.orientation`` gives the log's heading channel.

The readers (MCAP, ROS 1 bags, ROS 2 bag folders) turn that orientation into a compass heading by taking
its frame as east-north-up (REP 103: yaw counter-clockwise from east, heading = 90° − yaw), or, where every
message's frame is named north-east-down (``ned``, ``…_ned``: MAVROS, PX4), as NED (yaw clockwise from north:
the heading itself). That holds for a frame aligned with
the earth, and for no other: REP 105's ``odom`` frame starts wherever the odometry started (wheel odometry
reads yaw 0 at power-on, facing anywhere), and a ``map`` frame is as a map-maker laid it out (a SLAM map
starts at the robot's first pose). The data cannot tell: an offset turns every heading by one angle, which
turns the stops' yaw by as much — exactly what an uphill azimuth in another north would do.

So :func:`heading_frame_convention` states the frame in every result made of such samples
(``provenance.conventions``, name ``heading_frame``): ``stated`` where the frame's name says it is
east-north-up (``enu``, ``…_enu``, ``utm``, ``utm_…``: robot_localization's navsat_transform) or
north-east-down, else
``default`` — taken as east-north-up because REP 103 asks it, by no statement of the log.
:func:`heading_frame_check` fails (the result is then not confident) where β came from such a heading and
an uphill azimuth: the yaw is then only as right as the assumption that the odometry frame faces east. A
stop table made of such β keeps it in its column ``heading_frame`` (:func:`odometry_frame_column`, read back
by :func:`odometry_frame_from_column`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.core.option_names import option

if TYPE_CHECKING:  # core.result loads numpy
    from mountcal.core.result import Check, Convention

HEADING_FRAME = "heading_frame"  # the Convention's name


def earth_aligned(frame: str) -> bool:
    """Whether a frame's name says it is aligned with the earth: east-north-up, or north-east-down."""
    name = frame.strip().lstrip("/").lower()
    return name in ("enu", "utm") or name.endswith("_enu") or name.startswith("utm_") or north_east_down(frame)


def north_east_down(frame: str) -> bool:
    """Whether a frame's name says it is north-east-down (``ned``, ``…_ned``: MAVROS' ``local_origin_ned``, PX4's
    ``odom_ned``), whose yaw about the down axis is clockwise from north: the compass heading itself."""
    name = frame.strip().lstrip("/").lower()
    return name == "ned" or name.endswith("_ned")


def all_north_east_down(counts: Mapping[str, int]) -> bool:
    """Whether the odometry messages counted by frame name are all in a north-east-down frame."""
    named = [name for name, n in counts.items() if n]
    return bool(named) and all(north_east_down(name) for name in named)


def heading_frame_convention(topic: str, counts: Mapping[str, int], where: str) -> Convention | None:
    """How the frame of the heading read from ``topic``'s odometry is known; None when none was read."""
    from mountcal.core.result import Convention

    named = {name: n for name, n in counts.items() if n}
    if not named:
        return None
    source = Path(where).name or where
    several = len(named) > 1
    listing = ", ".join(f"{name or '(empty)'}" + (f" ({n} messages)" if several else "") for name, n in named.items())
    by = f"header.frame_id of {topic} in {source}"
    if all_north_east_down(named):
        return Convention(HEADING_FRAME, f"{listing} (north-east-down: yaw clockwise from north)", "stated", by)
    if all(earth_aligned(name) and not north_east_down(name) for name in named):
        return Convention(HEADING_FRAME, f"{listing} (east-north-up: yaw counter-clockwise from east)", "stated", by)
    return Convention(
        HEADING_FRAME,
        f"{listing} (taken as east-north-up, REP 103)",
        "default",
        f"{by}: a name that does not say the frame faces east (REP 105's odom starts where the odometry started, "
        "a map where its maker laid it out)",
    )


def _resting(conventions: Sequence[Convention]) -> Convention | None:
    """The odometry frame β rest on, where it is not known to face east: β from its heading and an uphill
    azimuth (a log), or from a stop table whose column says so; None otherwise."""
    frame = next((c for c in conventions if c.name == HEADING_FRAME), None)
    if frame is None or frame.how != "default":
        return None
    from_column = frame.by.endswith(f"column {HEADING_FRAME})")
    return frame if from_column or any(c.name == "uphill_azimuth" for c in conventions) else None


def odometry_frame_column(conventions: Sequence[Convention]) -> str | None:
    """A stop table's column ``heading_frame`` (``<value>; default: <by>``), written where its β rest on an
    odometry frame not known to face east, so that the table keeps it; else None."""
    frame = _resting(conventions)
    return None if frame is None else f"{frame.value}; {frame.how}: {frame.by}"


def odometry_frame_from_column(values: Sequence[object], where: str) -> Convention:
    """The convention a stop table's column ``heading_frame`` states (:func:`odometry_frame_column`'s text, one in
    every row)."""
    from mountcal.core.errors import InputError
    from mountcal.core.result import Convention

    texts = sorted({str(v).strip() for v in values})
    value, _, known = (texts[0] if len(texts) == 1 else "").partition("; ")
    how, _, by = known.partition(": ")
    if not value or how != "default":
        raise InputError(
            where,
            f"one text in the column {HEADING_FRAME}, as `mountcal stops` writes it ('<frame>; default: <by what>')",
            ", ".join(map(repr, texts)) or "no value",
            "Give every row the text the table was written with, or drop the column (state the headings instead).",
        )
    return Convention(HEADING_FRAME, value, "default", f"{by} ({where}: column {HEADING_FRAME})")


def heading_frame_check(conventions: Sequence[Convention]) -> Check | None:
    """A failed check where β came from an odometry heading in a frame not known to face east, with an
    uphill azimuth (the stops' yaw then rests on that frame's alignment); None otherwise."""
    from mountcal.core.result import Check

    frame = _resting(conventions)
    if frame is None:
        return None
    return Check(
        HEADING_FRAME,
        False,
        f"the stops' β come from {option('uphill_azimuth')} and the odometry's heading in frame {frame.value} "
        f"({frame.by}): if that frame does not face east, every heading, and the yaw, is off by its offset, which "
        f"the data cannot show. Give the stops' headings with {option('protocol')}, or record the heading in a frame "
        "named enu or utm",
    )


__all__ = [
    "HEADING_FRAME",
    "all_north_east_down",
    "earth_aligned",
    "heading_frame_check",
    "heading_frame_convention",
    "odometry_frame_column",
    "odometry_frame_from_column",
]
