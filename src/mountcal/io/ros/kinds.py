"""What mountcal reads from a ROS topic, and where in the message: a :class:`Target`, decoded for a whole
batch of messages by :func:`decode` into the columns :mod:`mountcal.io.mcap.read` turns into samples.

Kinds (``Target.kind``) and their message types:

- ``imu``: ``sensor_msgs/msg/Imu`` — the message itself, or an Imu carried in a field of another
  message (``--field imu``);
- ``acc``: a ``geometry_msgs/msg/Vector3`` carried in a field (``--field imu.linear_acceleration``):
  specific force only, no gyro;
- ``temperature``, ``fix``, ``odom``: ``sensor_msgs/msg/Temperature``, ``sensor_msgs/msg/NavSatFix``,
  ``nav_msgs/msg/Odometry``;
- ``velocity``: ``geometry_msgs/msg/TwistStamped`` or ``TwistWithCovarianceStamped`` (a GNSS
  receiver's velocity): the linear velocity's three components;
- ``nmea``: ``nmea_msgs/msg/Sentence``: speed and course over ground of its RMC and VTG sentences
  (:mod:`mountcal.io.ros.nmea`; text, parsed message by message: GNSS rates are low).

A sample's stamp is the ``header.stamp`` nearest the target along its path (the Imu's own header,
else the enclosing message's); without one, the record's time (see :attr:`Target.stamp`). The
``frame_id`` of that header names the frame of an IMU's or an acceleration's vectors, or of an odometry's
pose (``Decoded.frames``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mountcal.io.ros import layout, nmea
from mountcal.io.ros.types import IMU, NAME, VECTOR3, VECTOR3_STAMPED, Types, has_stamp, type_at
from mountcal.io.ros2.cdr import CdrError, Decoded, Rows

Path = tuple[str, ...]
XYZ = ("x", "y", "z")
TYPES = {
    IMU: "imu",
    "sensor_msgs/msg/Temperature": "temperature",
    "sensor_msgs/msg/NavSatFix": "fix",
    "nav_msgs/msg/Odometry": "odom",
    "geometry_msgs/msg/TwistStamped": "velocity",
    "geometry_msgs/msg/TwistWithCovarianceStamped": "velocity",
    "nmea_msgs/msg/Sentence": "nmea",
}
FIELD_TYPES = (IMU, VECTOR3, VECTOR3_STAMPED)  # what --field may point at
_VELOCITY = {
    "geometry_msgs/msg/TwistStamped": ("twist",),
    "geometry_msgs/msg/TwistWithCovarianceStamped": ("twist", "twist"),
}


@dataclass(frozen=True)
class Target:
    """A kind read from messages of ``type_name``: from the field at ``prefix`` (``()``: the message)."""

    kind: str
    type_name: str
    prefix: Path = ()
    stamp: Path | None = ("header", "stamp")  # the header stamp timing each sample; None: the record time

    @property
    def label(self) -> str:
        return self.type_name + (f" field {'.'.join(self.prefix)}" if self.prefix else "")


def target(types: Types, type_name: str, field: str | None = None) -> Target | None:
    """The target of a topic of ``type_name``: its standard kind, or (with ``field``) the Imu or Vector3
    at that path. None when the type is not one mountcal reads, or the field is not an Imu or Vector3.
    """
    if field is None:
        kind = TYPES.get(type_name)
        if kind is None:
            return None
        prefix = _VELOCITY.get(type_name, ())
        return Target(kind, type_name, prefix, _stamp(types, type_name, prefix))
    path = tuple(field.split("."))
    desc = type_at(types, type_name, path)
    if desc is None or desc[0] != NAME or desc[1] not in FIELD_TYPES:
        return None
    if desc[1] == VECTOR3_STAMPED:
        return Target("acc", type_name, (*path, "vector"), _stamp(types, type_name, path))
    return Target("imu" if desc[1] == IMU else "acc", type_name, path, _stamp(types, type_name, path))


def _stamp(types: Types, type_name: str, path: Path) -> Path | None:
    """The header stamp nearest ``path`` (its own, then each enclosing message's), or None."""
    for i in range(len(path), -1, -1):
        if has_stamp(types, type_name, path[:i]):
            return (*path[:i], "header", "stamp")
    return None


def _columns(t: Target) -> dict[str, list[Path]]:
    p = t.prefix
    if t.kind == "imu":
        return {
            "acc": [(*p, "linear_acceleration", c) for c in XYZ],
            "gyro": [(*p, "angular_velocity", c) for c in XYZ],
            "gyro_cov": [(*p, "angular_velocity_covariance")],
        }
    if t.kind == "acc":
        return {"acc": [(*p, c) for c in XYZ]}
    if t.kind == "temperature":
        return {"temperature": [("temperature",)]}
    if t.kind == "fix":
        return {
            "status": [("status", "status")],
            "lat": [("latitude",)],
            "lon": [("longitude",)],
            "alt": [("altitude",)],
        }
    if t.kind == "odom":
        return {
            "vx": [("twist", "twist", "linear", "x")],
            "quat": [("pose", "pose", "orientation", c) for c in (*XYZ, "w")],
        }
    if t.kind == "nmea":
        return {}
    return {"v": [(*p, "linear", c) for c in XYZ]}


def decode(rows: Rows, types: Types, t: Target, *, cdr: bool) -> Decoded:
    """The target's columns for every message of ``rows`` (float64; see :mod:`mountcal.io.ros2.cdr` for
    the shape of :class:`~mountcal.io.ros2.cdr.Decoded`); stamps zero where the message has none.

    Raises
    ------
    CdrError
        A message does not hold the layout its definition declares.
    """
    columns = _columns(t)
    stamp = [] if t.stamp is None else [(*t.stamp, "sec"), (*t.stamp, "nanosec")]
    text = [("sentence",)] if t.kind == "nmea" else []
    frame = [(*t.stamp[:-1], "frame_id")] if t.stamp is not None and t.kind in ("imu", "acc", "odom") else []
    wanted = [p for paths in columns.values() for p in paths] + stamp + text + frame
    found = layout.locate(rows, types, t.type_name, wanted, cdr=cdr)
    frames = layout.string_counts(rows, found, frame[0]) if frame else {}
    out = {}
    if text:
        speed, course, bad = nmea.parse(layout.read_strings(rows, found, text[0]))
        out = {"sog": speed, "cog": course, "bad_checksum": bad}
    for name, paths in columns.items():
        if len(paths) == 1:
            out[name] = layout.read(rows, found, paths[0]).astype(np.float64)
        else:
            out[name] = layout.read_columns(rows, found, paths).astype(np.float64)
    if "gyro_cov" in out:
        out["gyro_unknown"] = (out.pop("gyro_cov") == -1.0).astype(np.float64)
    n = rows.start.size
    if t.stamp is None:
        return Decoded(np.zeros(n, np.int64), np.zeros(n, np.int64), out, frames)
    sec = layout.read(rows, found, stamp[0]).astype(np.int64)
    nanosec = layout.read(rows, found, stamp[1]).astype(np.int64)
    if np.any((nanosec < 0) | (nanosec >= 1_000_000_000)):
        raise CdrError(f"a {'.'.join(t.stamp)}.nanosec outside 0 … 999999999")
    return Decoded(sec, nanosec, out, frames)


__all__ = ["FIELD_TYPES", "TYPES", "Target", "decode", "target"]
