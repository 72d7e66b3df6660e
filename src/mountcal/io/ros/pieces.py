"""Decoded ROS messages as samples, the same for every container (MCAP, ROS 1 bag, ROS 2 bag folder): a
:class:`Piece` holds one kind's finite, time-sorted values from one block; :func:`pieces_of` applies the
drop rules of :mod:`mountcal.io.mcap.read` (NaN or infinite values, no GNSS fix, an orientation that is no
rotation), :func:`concat` joins a recording's pieces in time order, :func:`gyro_of` decides the gyro."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mountcal.io.heading_frame import all_north_east_down
from mountcal.io.ros2 import cdr
from mountcal.io.samples import FloatArray


@dataclass
class Piece:
    """Decoded, finite, time-sorted values of one kind from one block."""

    t_s: FloatArray
    columns: dict[str, FloatArray]


def _sorted(t: FloatArray) -> bool:
    return bool(np.all(t[1:] >= t[:-1]))


def keep(t: FloatArray, columns: dict[str, FloatArray], ok: NDArray[np.bool_]) -> Piece:
    """Rows where ``ok``, stably sorted by time (copies skipped when there is nothing to do)."""
    if not ok.all():
        t, columns = t[ok], {k: v[ok] for k, v in columns.items()}
    if not _sorted(t):
        order = np.argsort(t, kind="stable")
        t, columns = t[order], {k: v[order] for k, v in columns.items()}
    return Piece(t, columns)


def _finite(*arrays: FloatArray) -> NDArray[np.bool_]:
    """Rows where every value is finite (times need no check: they come from integers)."""
    ok = np.ones(arrays[0].shape[0], dtype=bool)
    with np.errstate(all="ignore"):  # a finite sum proves every term finite: the usual, cheap case
        if all(np.isfinite(a.sum()) for a in arrays):
            return ok
    for a in arrays:
        ok &= np.isfinite(a).reshape(a.shape[0], -1).all(axis=1)
    return ok


def _heading_deg(quat: FloatArray, ned: bool = False) -> FloatArray:
    """Compass heading (clockwise from north, [0, 360)) from an orientation (x, y, z, w) in an ENU frame (yaw
    counter-clockwise from east), or in a NED one (``ned``: yaw clockwise from north, the heading itself)."""
    x, y, z, w = quat.T
    yaw = np.degrees(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))  # about the frame's z
    heading = np.mod(yaw if ned else 90.0 - yaw, 360.0)
    return np.asarray(np.where(heading >= 360.0, heading - 360.0, heading), dtype=np.float64)


def pieces_of(decoded: cdr.Decoded, kind: str, dropped: Counter[str]) -> dict[str, Piece]:
    """Finite, sorted samples (``"imu"``) or channels (keyed like ``Samples.channels``)."""
    c = decoded.columns
    t = c["t"]
    if kind == "imu":
        unknown = c["gyro_unknown"] > 0  # the gyro of these messages is not used (see gyro_of)
        ok = _finite(c["acc"]) & (unknown | _finite(c["gyro"]))
        dropped["imu_nonfinite"] += int((~ok).sum())
        return {"imu": keep(t, {"acc": c["acc"], "gyro": c["gyro"], "gyro_unknown": c["gyro_unknown"]}, ok)}
    if kind == "temperature":
        ok = _finite(c["temperature"])
        dropped["temperature_c_nonfinite"] += int((~ok).sum())
        return {"temperature_c": keep(t, {"value": c["temperature"]}, ok)}
    if kind == "fix":
        fix = c["status"] >= 0
        ok = fix & _finite(c["lat"], c["lon"], c["alt"])
        dropped["fix_no_fix"] += int((~fix).sum())
        dropped["fix_nonfinite"] += int((fix & ~ok).sum())
        return {
            key: keep(t, {"value": c[col]}, ok)
            for key, col in (("lat_deg", "lat"), ("lon_deg", "lon"), ("alt_m", "alt"))
        }
    speed_ok = _finite(c["vx"])
    norm = np.linalg.norm(c["quat"], axis=1)
    heading_ok = _finite(c["quat"]) & (np.abs(norm - 1.0) < 0.1)  # else not a rotation
    dropped["speed_mps_nonfinite"] += int((~speed_ok).sum())
    dropped["heading_deg_invalid_orientation"] += int((~heading_ok).sum())
    return {
        "speed_mps": keep(t, {"value": c["vx"]}, speed_ok),
        "heading_deg": keep(t, {"value": _heading_deg(c["quat"], all_north_east_down(decoded.frames))}, heading_ok),
    }


def concat(pieces: list[Piece]) -> Piece:
    """Join pieces and sort by time (stable, so file order breaks ties)."""
    joined = join_unsorted(pieces)
    if _sorted(joined.t_s):
        return joined
    order = np.argsort(joined.t_s, kind="stable")
    return Piece(joined.t_s[order], {k: v[order] for k, v in joined.columns.items()})


def join_unsorted(pieces: list[Piece]) -> Piece:
    if len(pieces) == 1:
        return pieces[0]
    return Piece(
        np.concatenate([p.t_s for p in pieces]),
        {k: np.concatenate([p.columns[k] for p in pieces]) for k in pieces[0].columns},
    )


def gyro_of(piece: Piece, dropped: Counter[str]) -> FloatArray | None:
    """The gyro column, or None when messages mark it unknown (``angular_velocity_covariance[0]
    = −1``, REP 145: an accelerometer without a gyro publishes zeros there). Where only some do,
    none is used: zeros among real rates would read as standing still; the count is reported."""
    unknown = int(np.count_nonzero(piece.columns["gyro_unknown"]))
    if not unknown:
        return piece.columns["gyro"]
    dropped["imu_gyro_marked_unknown"] += unknown
    return None


__all__ = ["Piece", "concat", "gyro_of", "join_unsorted", "keep", "pieces_of"]
