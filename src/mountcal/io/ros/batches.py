"""ROS recordings to samples through one path, whatever the container (ROS 1 bag, ROS 2 bag folder with
SQLite ``.db3`` or ``.mcap`` storage, MCAP log read with ``--field``): topics chosen (:mod:`.topics`),
messages located a block at a time by their container (:mod:`mountcal.io.bag.read`,
:mod:`mountcal.io.mcap.topics`: a bag chunk, a batch of SQLite rows, an MCAP chunk), every field decoded for
the whole block from the message definitions (:mod:`.kinds`).

Conventions as :mod:`mountcal.io.mcap.read` states them: a sample's time is its ``header.stamp``
(the record's time where the stamp is zero or the message has none), a topic stamped on another clock than
the recorder's moved onto it (:mod:`mountcal.io.stamp_clock`); SI units; vectors in the
IMU message's frame; NaN or infinite values dropped and counted; a gyro marked unknown
(``angular_velocity_covariance[0] = −1``) is no gyro. Speed from a GNSS velocity is the horizontal
magnitude of its linear velocity (never negative); from odometry, ``twist.twist.linear.x``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Generator, Sequence
from contextlib import closing
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.io.heading_frame import heading_frame_convention
from mountcal.io.inputs import max_rows, too_many_rows
from mountcal.io.ros import kinds
from mountcal.io.ros.pieces import Piece, concat, gyro_of, keep, pieces_of
from mountcal.io.ros.topics import Selection, Topic, choose_aux, choose_imu
from mountcal.io.ros2.cdr import CdrError, Decoded, Rows
from mountcal.io.samples import Channel, FloatArray, Samples
from mountcal.io.sensor_frame import frame_ids
from mountcal.io.stamp_clock import StampClocks

if TYPE_CHECKING:
    from mountcal.core.result import Convention

I64Array = NDArray[np.int64]
MIN_COURSE_SPEED_MPS = 1.0  # a GNSS course over ground is a heading only while moving


@dataclass(frozen=True)
class Batch:
    """Messages of one selection from one block: their rows, record times (ns) and where they are."""

    selection: Selection
    rows: Rows
    record_ns: I64Array
    what: str


Batches = Callable[[Sequence[Selection]], Generator[Batch, None, None]]


def samples_of(
    where: str,
    topics: dict[str, Topic],
    batches: Batches,
    *,
    cdr: bool,
    topic: str | None = None,
    field: str | None = None,
    notes: Sequence[str] = (),
) -> Samples:
    """The samples of a recording whose topics are ``topics`` and whose messages ``batches`` yields."""
    imu = choose_imu(topics, where, topic, field)
    said = list(notes)
    aux = choose_aux(topics, where, said)
    selections = [imu, *(s for s in aux if s.topic.name != imu.topic.name)]
    collected: dict[str, list[Piece]] = {}
    dropped: Counter[str] = Counter()
    frames: Counter[str] = Counter()  # the IMU messages' header.frame_id values
    odom_frames: Counter[str] = Counter()  # the odometry's (the frame of its heading)
    held, limit = 0, max_rows()
    clocks = StampClocks("the record time (the recorder's receive time)")
    with closing(batches(selections)) as blocks:
        for batch in blocks:
            named = frames if batch.selection.kind in ("imu", "acc") else odom_frames
            for key, piece in _decode(batch, where, cdr, dropped, named, clocks).items():
                collected.setdefault(key, []).append(piece)
                held += piece.t_s.size
            if held > limit:
                raise too_many_rows(where, "samples (all topics read)", held)
    if not sum(p.t_s.size for p in collected.get("imu", [])):
        found = f"no messages on {imu.topic.name!r}"
        if dropped["imu_nonfinite"]:
            found = f"{dropped['imu_nonfinite']} messages on {imu.topic.name!r}, all with NaN or infinite values"
        raise InputError(where, "IMU samples", found, "Check the recording, or read another topic.")
    samples = concat(collected.pop("imu"))
    channels = {}
    for key, parts in collected.items():
        joined = concat(parts)
        channels[key] = Channel(joined.t_s, joined.columns["value"])
    if imu.kind == "acc":
        gyro = None
        said.append(f"acceleration from {imu.topic.name} field {'.'.join(imu.target.prefix)}: no gyro")
    else:
        gyro = gyro_of(samples, dropped)
    if imu.target.prefix and imu.kind == "imu":
        said.append(f"IMU from {imu.topic.name} field {'.'.join(imu.target.prefix)} ({imu.topic.type_name})")
    read = Samples(
        t_s=samples.t_s,
        acc_s=samples.columns["acc"],
        gyro_s=gyro,
        channels=channels,
        source=where,
        dropped={k: v for k, v in dropped.items() if v},
        notes=tuple(said),
        frame_ids=frame_ids(
            imu.topic.name + (f" field {'.'.join(imu.target.prefix)}" if imu.target.prefix else ""), frames, where
        ),
        conventions=_heading_frame(aux, channels, odom_frames, where),
    )
    return clocks.settle(read)  # topics stamped on another clock than the recorder's: onto it, said


def _decode(
    batch: Batch, where: str, cdr: bool, dropped: Counter[str], frames: Counter[str], clocks: StampClocks
) -> dict[str, Piece]:
    """The batch's pieces (keyed as ``Samples.channels``, the IMU's ``"imu"``); its stamps told to ``clocks``."""
    sel = batch.selection
    try:
        decoded = kinds.decode(batch.rows, sel.topic.definitions(where), sel.target, cdr=cdr)
    except CdrError as err:
        raise InputError(
            where,
            f"{sel.target.label} messages on {sel.topic.name!r} laid out as their definition says",
            f"{err}, in the {batch.what}",
            err.fix
            or "The file is damaged, or its definition is not the one its messages were written with; "
            "export the topic to CSV instead.",
        ) from err
    frames.update(decoded.frames)  # the IMU's (or the acceleration's), or the odometry's: the caller's counter
    pieces = _pieces(sel.kind, decoded, _times(decoded, batch.record_ns), dropped)
    clocks.add(sel.topic.name, decoded.sec, decoded.nanosec, batch.record_ns, pieces)  # no header: all unset
    return pieces


def _heading_frame(
    aux: Sequence[Selection], channels: dict[str, Channel], counts: Counter[str], where: str
) -> tuple[Convention, ...]:
    """The frame of the heading channel, where it came from odometry (:mod:`mountcal.io.heading_frame`)."""
    odom = next((s for s in aux if s.kind == "odom"), None)
    if odom is None or "heading_deg" not in channels or not counts:
        return ()
    said = heading_frame_convention(odom.topic.name, counts, where)
    return () if said is None else (said,)


def _pieces(kind: str, decoded: Decoded, t: FloatArray, dropped: Counter[str]) -> dict[str, Piece]:
    columns = {"t": t, **decoded.columns}
    if kind == "acc":
        ok = np.isfinite(columns["acc"]).all(axis=1)
        dropped["imu_nonfinite"] += int((~ok).sum())
        return {"imu": keep(t, {"acc": columns["acc"]}, ok)}
    if kind == "velocity":
        v = columns["v"]
        speed = np.hypot(v[:, 0], v[:, 1])
        ok = np.isfinite(speed)
        dropped["speed_mps_nonfinite"] += int((~ok).sum())
        return {"speed_mps": keep(t, {"value": speed}, ok)}
    if kind == "nmea":
        return _nmea(t, columns, dropped)
    return pieces_of(Decoded(decoded.sec, decoded.nanosec, columns, decoded.frames), kind, dropped)


def _nmea(t: FloatArray, columns: dict[str, FloatArray], dropped: Counter[str]) -> dict[str, Piece]:
    """Speed from RMC/VTG sentences; their course as a heading while moving (at rest it is noise)."""
    bad = columns["bad_checksum"] > 0
    speed, course = columns["sog"], columns["cog"]
    has_speed = np.isfinite(speed)
    moving = has_speed & np.isfinite(course) & (speed >= MIN_COURSE_SPEED_MPS)
    dropped["nmea_bad_checksum"] += int(bad.sum())
    dropped["nmea_sentences_without_speed"] += int((~bad & ~has_speed).sum())
    dropped[f"heading_deg_below_{MIN_COURSE_SPEED_MPS:g}_mps"] += int((has_speed & np.isfinite(course) & ~moving).sum())
    return {
        "speed_mps": keep(t, {"value": speed}, has_speed),
        "heading_deg": keep(t, {"value": np.mod(course, 360.0)}, moving),
    }


def _times(decoded: Decoded, record_ns: I64Array) -> FloatArray:
    """Header stamp in seconds, or the record time where the stamp is zero (unset or absent)."""
    sec, nanosec = decoded.sec, decoded.nanosec
    unset = (sec == 0) & (nanosec == 0)
    if unset.any():
        sec = np.where(unset, record_ns // 1_000_000_000, sec)
        nanosec = np.where(unset, record_ns % 1_000_000_000, nanosec)
    return sec.astype(np.float64) + nanosec.astype(np.float64) * 1e-9


__all__ = ["Batch", "Batches", "samples_of"]
