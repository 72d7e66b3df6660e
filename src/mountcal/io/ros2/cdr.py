"""Vectorized reading of the few ROS 2 CDR messages mountcal needs, many messages at a time.

A batch of messages is one byte buffer ``buf`` (typically a decompressed MCAP chunk) plus the start
offset and size of every serialized message in it. Each field is read for all messages at once
(:class:`Rows`): through a strided view when the messages are evenly spaced and the field sits at
one offset in all of them (the usual case), else by gathering its bytes at a per-message offset,
so a varying ``frame_id`` length costs a little speed, never correctness.

CDR rules used here (OMG XCDR1, as ROS 2 writes it):

- every message starts with a 4-byte encapsulation header; ``00 01`` is little-endian CDR, the
  only representation accepted (big-endian ``00 00`` and the parameter-list/XCDR2 kinds are refused);
- a primitive of size k is aligned to a multiple of k, counted from the byte *after* that header;
- a string is a uint32 length (including the terminating NUL) followed by its bytes.

The layouts are those of the standard message definitions (``std_msgs/Header``,
``sensor_msgs/msg/Imu``, ``Temperature``, ``NavSatFix``, ``nav_msgs/msg/Odometry``); the caller
checks that a log's schema declares exactly those fields (see :data:`FIELDS`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

U8Array = NDArray[np.uint8]
I64Array = NDArray[np.int64]
F64Array = NDArray[np.float64]

HEADER_BYTES = 4  # the encapsulation header; alignment counts from the byte after it
CDR_LE = (0x00, 0x01)

# Top-level fields (type base name, field name) of each supported message, in declaration order;
# a schema that declares anything else is not read with these layouts.
_HEADER = ("Header", "header")
FIELDS: dict[str, tuple[tuple[str, str], ...]] = {
    "imu": (
        _HEADER,
        ("Quaternion", "orientation"),
        ("float64[9]", "orientation_covariance"),
        ("Vector3", "angular_velocity"),
        ("float64[9]", "angular_velocity_covariance"),
        ("Vector3", "linear_acceleration"),
        ("float64[9]", "linear_acceleration_covariance"),
    ),
    "temperature": (_HEADER, ("float64", "temperature"), ("float64", "variance")),
    "fix": (
        _HEADER,
        ("NavSatStatus", "status"),
        ("float64", "latitude"),
        ("float64", "longitude"),
        ("float64", "altitude"),
        ("float64[9]", "position_covariance"),
        ("uint8", "position_covariance_type"),
    ),
    "odom": (
        _HEADER,
        ("string", "child_frame_id"),
        ("PoseWithCovariance", "pose"),
        ("TwistWithCovariance", "twist"),
    ),
}


class CdrError(ValueError):
    """The bytes do not hold the expected CDR layout; the text says what was found, and ``fix`` what to do
    where the bytes are valid but in a representation mountcal does not decode (else None: damage)."""

    def __init__(self, message: str, fix: str | None = None) -> None:
        super().__init__(message)
        self.fix = fix


# Encapsulation kinds (RTPS / DDS-XTypes) a valid message may start with, other than little-endian CDR
_REPRESENTATIONS = {
    0x0000: "big-endian CDR",
    0x0002: "big-endian parameter-list CDR",
    0x0003: "little-endian parameter-list CDR",
    0x0006: "big-endian XCDR2",
    0x0007: "little-endian XCDR2",
    0x0008: "big-endian parameter-list XCDR2",
    0x0009: "little-endian parameter-list XCDR2",
    0x000A: "big-endian delimited XCDR2",
    0x000B: "little-endian delimited XCDR2",
}


@dataclass(frozen=True)
class Decoded:
    """Fields of a batch of n messages.

    Attributes
    ----------
    sec, nanosec : ndarray of int64, shape (n,)
        ``header.stamp`` (seconds and nanoseconds); both zero where the sender left it unset.
    columns : dict of str to ndarray of float64, shape (n,) or (n, k)
        The message's numeric fields, in the message's own units (see each ``decode_*``).
    frames : dict of str to int
        The ``header.frame_id`` values of IMU messages (the sensor frame) and of odometry (the frame its
        heading is in), each with how many messages carry it (empty for the other messages, and where
        there is no header).
    """

    sec: I64Array
    nanosec: I64Array
    columns: dict[str, F64Array]
    frames: dict[str, int] = field(default_factory=dict)


Offset = I64Array | int  # a byte offset per row, or one shared by all rows (the fast case)
_FIND_STEP = -1  # Rows(step=...) default: work the spacing out


def gather(buf: U8Array, at: I64Array, nbytes: int) -> U8Array:
    """Bytes ``buf[at[i] : at[i] + nbytes]`` for every i, shape (n, nbytes); ranges must lie in ``buf``.

    Rows of a sliding-window view are copied whole (several times faster than gathering byte by byte).
    """
    if at.size == 0 or nbytes > buf.size:  # no rows, or none that fits: the plain gather (empty, or IndexError)
        return np.asarray(buf[at[:, None] + np.arange(nbytes, dtype=np.int64)], dtype=np.uint8)
    return np.lib.stride_tricks.sliding_window_view(buf, nbytes)[at]


def _even_step(start: I64Array) -> int | None:
    """The constant positive spacing of ``start``, or None when it is not evenly spaced."""
    if start.size == 1:
        return 1
    if start.size == 0 or start[1] <= start[0]:
        return None
    step = int(start[1] - start[0])
    return (
        step if int(start[-1] - start[0]) == step * (start.size - 1) and bool(np.all(np.diff(start) == step)) else None
    )


def as_offset(rel: I64Array) -> Offset:
    """``rel`` as one int when all rows share it, which lets :meth:`Rows.read` use a strided view."""
    return int(rel[0]) if rel.size and int(rel.min()) == int(rel.max()) else rel


class Rows:
    """n byte records in one buffer, ``buf[start[i] : start[i] + size[i]]``, read field by field.

    Fields are read for all rows at once. When the records are evenly spaced (one topic alone in a
    chunk with a constant ``frame_id``: the common case) and the field offset is shared, the read is
    a strided view over ``buf`` and one copy; otherwise a fancy-indexing gather.
    """

    def __init__(
        self, buf: U8Array, start: I64Array, size: I64Array | None = None, *, step: int | None = _FIND_STEP
    ) -> None:
        self.buf, self.start, self.size = buf, start, size
        self.step = _even_step(start) if step == _FIND_STEP else step  # the caller may know it

    def shifted(self, offset: int) -> Rows:
        """The same records seen from ``offset`` bytes further in (sizes shrink accordingly)."""
        size = None if self.size is None else self.size - offset
        return Rows(self.buf, self.start + offset, size, step=self.step)

    def need(self, end: Offset, what: str) -> None:
        """Fail unless every record holds ``end`` bytes, naming ``what`` would be cut off."""
        if self.size is None:
            raise TypeError("Rows built without sizes cannot check bounds")
        short = np.flatnonzero(self.size < end)
        if short.size:
            raise CdrError(f"{short.size} of {self.size.size} message(s) too short to hold {what}")

    def read(self, at: Offset, dtype: str, count: int = 1) -> NDArray[Any]:
        """``count`` values of ``dtype`` at offset ``at`` of each row, shape (n, count), native order.

        No bounds check: the caller has checked (:meth:`need`) or knows the records hold them.
        """
        dt = np.dtype(dtype)
        if isinstance(at, int) and self.step is not None:
            view = np.ndarray(
                (self.start.size, count),
                dt,
                buffer=self.buf,
                offset=int(self.start[0]) + at,
                strides=(self.step, dt.itemsize),
            )
        else:
            view = gather(self.buf, self.start + at, dt.itemsize * count).view(dt)
        return view.astype(dt.newbyteorder("="))

    def take(self, at: Offset, dtype: str, count: int, what: str) -> NDArray[Any]:
        """:meth:`read` after checking every record is long enough."""
        self.need(at + np.dtype(dtype).itemsize * count, what)
        return self.read(at, dtype, count)

    def string_end(self, at: Offset, what: str) -> Offset:
        """Offset just after the CDR string whose uint32 length prefix is at (aligned) ``at``."""
        at = align(at, 4)
        length = self.take(at, "<u4", 1, what)[:, 0].astype(np.int64)
        return as_offset(at + 4 + length)


def string_counts(rows: Rows, at: Offset, end: Offset) -> dict[str, int]:
    """Each value of a string field (bytes ``at`` to ``end`` of each row, checked to lie inside) with how
    many rows hold it; a trailing NUL (CDR's) is not part of the value.

    Vectorised for the usual case, one value in every row: one length (``end`` one offset), and every
    row's bytes equal to the first's, compared in one pass (a strided view when the rows are evenly
    spaced). Only when they differ are the values sorted out: one :func:`numpy.unique` per length.
    """
    n = rows.start.size
    if not n:
        return {}
    rows.need(end, "a string")
    if isinstance(at, int) and isinstance(end, int):
        if end == at:
            return {"": n}
        block = _bytes(rows, at, end - at)
        if not np.count_nonzero(block != block[0]):
            return {_text(block[0]): n}
    starts = rows.start + np.broadcast_to(np.asarray(at, np.int64), (n,))
    length = np.broadcast_to(np.asarray(end, np.int64) - np.asarray(at, np.int64), (n,))
    counts: dict[str, int] = {}
    for size in np.unique(length).tolist():  # a few distinct lengths: one gather and one unique each
        if not size:
            counts[""] = counts.get("", 0) + int(np.count_nonzero(length == 0))
            continue
        values, seen = np.unique(gather(rows.buf, starts[length == size], int(size)), axis=0, return_counts=True)
        for value, count in zip(values, seen.tolist(), strict=True):
            text = _text(value)
            counts[text] = counts.get(text, 0) + int(count)
    return counts


def _bytes(rows: Rows, at: int, nbytes: int) -> U8Array:
    """Bytes ``at : at + nbytes`` of every row, shape (n, nbytes): a view when the rows are evenly spaced."""
    if rows.step is None:
        return gather(rows.buf, rows.start + at, nbytes)
    shape, strides = (rows.start.size, nbytes), (rows.step, 1)
    return np.ndarray(shape, np.uint8, buffer=rows.buf, offset=int(rows.start[0]) + at, strides=strides)


def _text(raw: U8Array) -> str:
    return bytes(raw).rstrip(b"\0").decode("utf-8", errors="replace")


def align(at: Offset, size: int) -> Offset:
    """Round offsets (relative to the byte after the encapsulation header) up to ``size``."""
    return (at + (size - 1)) // size * size


def cdr_rows(buf: U8Array, start: I64Array, size: I64Array) -> Rows:
    """Rows positioned after the encapsulation header, refusing anything but little-endian CDR."""
    short = np.flatnonzero(size < HEADER_BYTES)
    if short.size:
        raise CdrError(f"{short.size} message(s) shorter than the 4-byte CDR encapsulation header")
    rows = Rows(buf, start, size)
    head = rows.read(0, "u1", 2)
    bad = np.flatnonzero((head[:, 0] != CDR_LE[0]) | (head[:, 1] != CDR_LE[1]))
    if bad.size:
        first = head[int(bad[0])].astype(np.uint8)
        found = bytes(first).hex(" ")
        kind = _REPRESENTATIONS.get(int(first[0]) << 8 | int(first[1]))
        if kind is None:  # no representation: the bytes are not what the channel says
            raise CdrError(f"encapsulation header {found} on {bad.size} message(s), expected 00 01 (little-endian CDR)")
        raise CdrError(
            f"encapsulation header {found} on {bad.size} message(s): {kind}, a valid representation that mountcal "
            "does not decode (it reads little-endian CDR, 00 01, as ROS 2 writes on every common platform)",
            "Re-serialize the messages as little-endian CDR (rosbags: deserialize_cdr, then serialize_cdr with "
            "little_endian=True), or export the topic to CSV.",
        )
    return rows.shifted(HEADER_BYTES)


def _header(rows: Rows) -> tuple[I64Array, I64Array, Offset]:
    """``std_msgs/Header``: stamp (sec, nanosec) and the offset just after ``frame_id`` (which starts at
    ``FRAME_ID``)."""
    stamp = rows.take(0, "<i4", 2, "header.stamp")
    sec = stamp[:, 0].astype(np.int64)
    nanosec = stamp[:, 1].astype(np.int64) & 0xFFFFFFFF  # nanosec is a uint32
    return sec, nanosec, rows.string_end(8, "header.frame_id")


FRAME_ID = 12  # header.frame_id's bytes: after the stamp (8 B) and the string's length (4 B)


# sensor_msgs/msg/Imu after the header, from the (8-aligned) quaternion: field → (offset, float64 count)
IMU_FIELDS = {
    "orientation": (0, 4),
    "orientation_covariance": (32, 9),
    "angular_velocity": (104, 3),
    "angular_velocity_covariance": (128, 9),
    "linear_acceleration": (200, 3),
    "linear_acceleration_covariance": (224, 9),
}
IMU_BYTES = 296  # the quaternion and everything after it


def imu_rows(buf: U8Array, start: I64Array, size: I64Array) -> tuple[Rows, I64Array, I64Array, Offset]:
    """Imu messages as rows checked to hold every field: rows, ``header.stamp`` (sec, nanosec) and the
    offset of the quaternion (the first field after the header, 8-aligned)."""
    rows, sec, nanosec, _, orientation = _imu_rows(buf, start, size)
    return rows, sec, nanosec, orientation


def _imu_rows(buf: U8Array, start: I64Array, size: I64Array) -> tuple[Rows, I64Array, I64Array, Offset, Offset]:
    """:func:`imu_rows`, with the offset just after ``header.frame_id`` before the quaternion's."""
    rows = cdr_rows(buf, start, size)
    sec, nanosec, end = _header(rows)
    orientation = align(end, 8)  # quaternion (32 B), then a 3x3 covariance (72 B)
    rows.need(orientation + IMU_BYTES, "the Imu fields after header")
    return rows, sec, nanosec, end, orientation


def decode_imu(buf: U8Array, start: I64Array, size: I64Array) -> Decoded:
    """``sensor_msgs/msg/Imu`` messages ``buf[start[i] : start[i] + size[i]]``.

    Returns
    -------
    Decoded
        columns ``acc`` (n, 3) ``linear_acceleration`` in m/s² and ``gyro`` (n, 3)
        ``angular_velocity`` in rad/s, both in the message's ``frame_id`` frame, and
        ``gyro_unknown`` (n,), 1.0 where ``angular_velocity_covariance[0]`` is −1: REP 145's mark
        of a field the device does not provide; ``frames``: the ``header.frame_id`` values.
    """
    rows, sec, nanosec, end, at = _imu_rows(buf, start, size)
    gyro = rows.read(at + IMU_FIELDS["angular_velocity"][0], "<f8", 3)
    gyro_unknown = (rows.read(at + IMU_FIELDS["angular_velocity_covariance"][0], "<f8", 1)[:, 0] == -1.0).astype(
        np.float64
    )
    acc = rows.read(at + IMU_FIELDS["linear_acceleration"][0], "<f8", 3)
    frames = string_counts(rows, FRAME_ID, end)
    return Decoded(sec, nanosec, {"acc": acc, "gyro": gyro, "gyro_unknown": gyro_unknown}, frames)


def decode_temperature(buf: U8Array, start: I64Array, size: I64Array) -> Decoded:
    """``sensor_msgs/msg/Temperature``: column ``temperature`` (n,) in °C."""
    rows = cdr_rows(buf, start, size)
    sec, nanosec, end = _header(rows)
    temperature = rows.take(align(end, 8), "<f8", 1, "temperature")[:, 0]
    return Decoded(sec, nanosec, {"temperature": temperature})


def decode_navsatfix(buf: U8Array, start: I64Array, size: I64Array) -> Decoded:
    """``sensor_msgs/msg/NavSatFix``.

    Columns ``status`` (n,) (``status.status``: −1 no fix, ≥ 0 a fix), ``lat`` and ``lon`` (n,) in
    degrees and ``alt`` (n,) in metres above the WGS 84 ellipsoid.
    """
    rows = cdr_rows(buf, start, size)
    sec, nanosec, end = _header(rows)
    status = rows.take(end, "i1", 1, "status.status")[:, 0].astype(np.float64)
    latitude = align(align(end + 1, 2) + 2, 8)  # after int8 status and uint16 service
    lla = rows.take(latitude, "<f8", 3, "latitude, longitude, altitude")
    return Decoded(sec, nanosec, {"status": status, "lat": lla[:, 0], "lon": lla[:, 1], "alt": lla[:, 2]})


def decode_odometry(buf: U8Array, start: I64Array, size: I64Array) -> Decoded:
    """``nav_msgs/msg/Odometry``.

    Columns ``vx`` (n,) = ``twist.twist.linear.x`` in m/s (child frame, signed: negative when
    reversing) and ``quat`` (n, 4) = ``pose.pose.orientation`` as (x, y, z, w), in the header's frame;
    ``frames``: the ``header.frame_id`` values (the frame the heading is in: :mod:`mountcal.io.heading_frame`).
    """
    rows = cdr_rows(buf, start, size)
    sec, nanosec, end = _header(rows)
    position = align(rows.string_end(end, "child_frame_id"), 8)
    # pose: position (24 B) + orientation (32 B) + 6x6 covariance (288 B), then twist.linear
    rows.need(position + 352, "pose and twist.twist.linear.x")
    quat = rows.read(position + 24, "<f8", 4)
    vx = rows.read(position + 344, "<f8", 1)[:, 0]
    return Decoded(sec, nanosec, {"vx": vx, "quat": quat}, string_counts(rows, FRAME_ID, end))


DECODERS = {
    "imu": decode_imu,
    "temperature": decode_temperature,
    "fix": decode_navsatfix,
    "odom": decode_odometry,
}
