"""``sensor_msgs/msg/Imu`` in CDR, every field: decoded and encoded on whole arrays (the MCAP copy of
``mountcal rotate``). The field layout is :data:`mountcal.io.ros2.cdr.IMU_FIELDS`, shared with the
reader's :func:`~mountcal.io.ros2.cdr.decode_imu`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mountcal.io.ros2 import cdr
from mountcal.io.samples import FloatArray

U8Array = NDArray[np.uint8]
I64Array = NDArray[np.int64]


@dataclass(frozen=True)
class ImuMessages:
    """Fields of n ``sensor_msgs/msg/Imu`` messages (ROS units: s, rad/s, m/s²).

    ``orientation`` is (x, y, z, w); covariances are row-major 3×3, shape (n, 9).
    """

    sec: NDArray[np.int64]
    nanosec: NDArray[np.int64]
    orientation: FloatArray  # (n, 4)
    orientation_covariance: FloatArray  # (n, 9)
    angular_velocity: FloatArray  # (n, 3)
    angular_velocity_covariance: FloatArray  # (n, 9)
    linear_acceleration: FloatArray  # (n, 3)
    linear_acceleration_covariance: FloatArray  # (n, 9)

    def __len__(self) -> int:
        return int(self.sec.shape[0])

    @classmethod
    def unknown_orientation(cls, t_ns: NDArray[np.int64], gyro: FloatArray | None, acc: FloatArray) -> ImuMessages:
        """Messages without orientation (``orientation_covariance[0] = −1``, as REP 145 asks) or
        covariances; the gyro's covariance is −1 too when there is no gyro."""
        n = t_ns.shape[0]
        unknown = np.zeros((n, 9))
        unknown[:, 0] = -1.0
        return cls(
            sec=t_ns // 1_000_000_000,
            nanosec=t_ns % 1_000_000_000,
            orientation=np.zeros((n, 4)),
            orientation_covariance=unknown,
            angular_velocity=np.zeros((n, 3)) if gyro is None else gyro,
            angular_velocity_covariance=unknown.copy() if gyro is None else np.zeros((n, 9)),
            linear_acceleration=acc,
            linear_acceleration_covariance=np.zeros((n, 9)),
        )


def decode_imu_messages(buf: U8Array, start: I64Array, size: I64Array) -> ImuMessages:
    """Every field of CDR ``sensor_msgs/msg/Imu`` messages ``buf[start[i] : start[i] + size[i]]``.

    Raises
    ------
    cdr.CdrError
        When a message is not little-endian CDR or is too short for its layout.
    """
    rows, sec, nanosec, at = cdr.imu_rows(buf, start, size)
    fields = {name: rows.read(at + offset, "<f8", count) for name, (offset, count) in cdr.IMU_FIELDS.items()}
    return ImuMessages(sec=sec, nanosec=nanosec, **fields)


def encode_imu_messages(msgs: ImuMessages, frame_id: str) -> U8Array:
    """CDR payloads of ``sensor_msgs/msg/Imu`` messages, one row each, shape (n, L) uint8.

    All rows share one ``frame_id``, so they share one layout: built with a structured array.
    """
    name = frame_id.encode() + b"\x00"
    base = cdr.HEADER_BYTES + int(cdr.align(12 + len(name), 8))
    fields: dict[str, tuple[str, tuple[int, ...], int]] = {
        "encapsulation": ("u1", (4,), 0),
        "sec": ("<i4", (), 4),
        "nanosec": ("<u4", (), 8),
        "name_len": ("<u4", (), 12),
        "name": ("u1", (len(name),), 16),
        **{key: ("<f8", (count,), base + offset) for key, (offset, count) in cdr.IMU_FIELDS.items()},
    }
    dtype = np.dtype(
        {
            "names": list(fields),
            "formats": [(f, s) if s else f for f, s, _ in fields.values()],
            "offsets": [o for _, _, o in fields.values()],
            "itemsize": base + cdr.IMU_BYTES,
        }
    )
    rows = np.zeros(len(msgs), dtype=dtype)
    rows["encapsulation"] = (0, 1, 0, 0)
    rows["sec"] = msgs.sec
    rows["nanosec"] = msgs.nanosec
    rows["name_len"] = len(name)
    rows["name"] = np.frombuffer(name, np.uint8)
    for key in list(fields)[5:]:
        rows[key] = getattr(msgs, key)
    return rows.view(np.uint8).reshape(len(msgs), dtype.itemsize)


__all__ = ["ImuMessages", "decode_imu_messages", "encode_imu_messages"]
