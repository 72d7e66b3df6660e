"""The name a log gives the IMU's frame: the ``header.frame_id`` of the IMU messages it was read from.

A calibration's sensor frame is the frame of the samples it was made of; in a ROS log that frame has a
name, which the readers (MCAP, ROS 1 bags, ROS 2 bag folders) record as :class:`FrameIds` in
``Samples.frame_ids``. :func:`sensor_frame_convention` states it in every result made of those samples
(``provenance.conventions``, name ``sensor_frame``), so that an export names the frame the data were in
(:mod:`mountcal.outputs.exporters`). A topic whose messages name several frames is said as such, with
each name's count, never reduced to one of them. Logs without frame names (CAN, tables) record none.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.core.option_names import option

if TYPE_CHECKING:  # core.result loads numpy: the exporters' registry reads this module without it
    from mountcal.core.result import Check, Convention

SENSOR_FRAME = "sensor_frame"  # the Convention's name
SEVERAL = "several frames: "  # how the value of a topic naming several frames starts


@dataclass(frozen=True)
class FrameIds:
    """The ``header.frame_id`` values of the IMU messages read from ``topic`` of ``source`` (file names),
    with how many messages carried each, the most common first."""

    topic: str
    counts: tuple[tuple[str, int], ...]
    source: str

    @property
    def by(self) -> str:
        """``header.frame_id of /imu/data in parking.mcap``."""
        return f"header.frame_id of {self.topic} in {self.source}"

    @property
    def named(self) -> tuple[tuple[str, int], ...]:
        """The counts of the non-empty names (an empty ``frame_id`` names no frame)."""
        return tuple((name, n) for name, n in self.counts if name)


def frame_ids(topic: str, counts: Mapping[str, int], where: str) -> FrameIds | None:
    """The frame names counted on ``topic`` of the log at ``where``; None when no message was counted."""
    return _ordered(topic, counts.items(), Path(where).name or where) if counts else None


def _ordered(topic: str, items: Iterable[tuple[str, int]], source: str) -> FrameIds:
    total: dict[str, int] = {}
    for name, n in items:
        total[name] = total.get(name, 0) + n
    return FrameIds(topic, tuple(sorted(total.items(), key=lambda kv: -kv[1])), source)


def joined(parts: Sequence[FrameIds | None]) -> FrameIds | None:
    """The frame names of several files of one log (splits), counted together."""
    found = [p for p in parts if p is not None]
    if not found:
        return None
    topics = dict.fromkeys(p.topic for p in found)
    sources = dict.fromkeys(p.source for p in found)
    return _ordered(" + ".join(topics), (kv for p in found for kv in p.counts), " + ".join(sources))


def sensor_frame_convention(ids: FrameIds) -> Convention | None:
    """The frame the samples are in, by the name the log gives it; None when its messages name none."""
    from mountcal.core.result import Convention

    named = ids.named
    if not named:
        return None
    if len(ids.counts) == 1:
        return Convention(SENSOR_FRAME, named[0][0], "stated", ids.by)
    return Convention(SENSOR_FRAME, SEVERAL + _listing(ids), "stated", ids.by)


def sensor_frame_note(ids: FrameIds | None) -> str | None:
    """What a result made of messages naming several frames should say; None for one frame (or none)."""
    if ids is None or len(ids.counts) < 2 or not ids.named:
        return None
    return (
        f"the IMU messages name several frames ({_listing(ids)}: {ids.by}): the samples were taken as one "
        f"sensor frame; an export names its child frame only when told which ({option('child')})"
    )


def several_frames_check(conventions: Iterable[Convention]) -> Check | None:
    """A failed check where the IMU messages read name several frames: the samples were taken as one
    sensor's, which mixes two mountings where the names are two sensors (two drivers on one topic)."""
    from mountcal.core.result import Check

    frame = recorded_frame(conventions)
    if frame is None or not several(frame):
        return None
    return Check(
        SENSOR_FRAME,
        False,
        f"the IMU messages name {frame.value.removeprefix(SEVERAL)} ({frame.by}): the samples were taken as one "
        "sensor's; if the names are several sensors (two drivers publishing on one topic), the answer mixes their "
        f"mountings. Record each sensor on its own topic and read one ({option('topic')})",
    )


def several_column(conventions: Iterable[Convention]) -> str | None:
    """A stop table's column ``sensor_frame``: written where the stops' samples named several frames (the
    check above then fails on the table too), with what stated it; else None."""
    frame = recorded_frame(conventions)
    return None if frame is None or not several(frame) else f"{frame.value}; {frame.by}"


def column_several(values: Sequence[object], where: str) -> Convention:
    """The convention a stop table's column ``sensor_frame`` states (:func:`several_column`'s text)."""
    from mountcal.core.errors import InputError
    from mountcal.core.result import Convention

    texts = sorted({str(v).strip() for v in values})
    value, _, by = (texts[0] if len(texts) == 1 else "").partition("; ")
    if not value.startswith(SEVERAL):
        raise InputError(
            where,
            f"one text in the column {SENSOR_FRAME}, as `mountcal stops` writes it ('{SEVERAL}…; <by what>')",
            ", ".join(map(repr, texts)) or "no value",
            "Give every row the text the table was written with, or drop the column.",
        )
    said = f"{where}: column {SENSOR_FRAME}"
    return Convention(SENSOR_FRAME, value, "stated", f"{by} ({said})" if by else said)


def refuse_several(counts: Mapping[str, int], topic: str, where: str) -> None:
    """Refuse to apply one calibration to IMU messages naming several frames (``rotate``): the samples of a
    frame it was not made for would be written rotated as if they were."""
    named = sorted(name for name, n in counts.items() if name and n)
    if len(named) > 1:
        from mountcal.core.errors import InputError

        raise InputError(
            where,
            f"IMU messages on {topic} in one sensor frame, as one calibration applies to",
            "messages naming several frames: " + ", ".join(f"{name} ({counts[name]})" for name in named),
            f"Record each sensor on its own topic and rotate one ({option('topic')}) with its own calibration.",
        )


def _listing(ids: FrameIds) -> str:
    return ", ".join(f"{name or '(empty)'} ({n} messages)" for name, n in ids.counts)


def recorded_frame(conventions: Iterable[Convention]) -> Convention | None:
    """The ``sensor_frame`` convention of a result, if its log named the IMU's frame."""
    return next((c for c in conventions if c.name == SENSOR_FRAME), None)


def several(convention: Convention) -> bool:
    """Whether a ``sensor_frame`` convention lists several frames (no one name to use)."""
    return convention.value.startswith(SEVERAL)


__all__ = [
    "SENSOR_FRAME",
    "FrameIds",
    "column_several",
    "frame_ids",
    "joined",
    "recorded_frame",
    "refuse_several",
    "sensor_frame_convention",
    "sensor_frame_note",
    "several",
    "several_column",
    "several_frames_check",
]
