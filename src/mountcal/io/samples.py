"""Time-stamped samples, the value every reader returns.

All arrays are float64 in SI units; vectors are in the sensor frame ``s`` (right-handed, after the
reader's axis mapping, which is recorded in ``axis_map``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError

if TYPE_CHECKING:
    from mountcal.core.result import Convention
    from mountcal.io.frame import Rotated
    from mountcal.io.sensor_frame import FrameIds

FloatArray = NDArray[np.float64]

# what gravity does to a log's acceleration, for every reader that checks the unit it read in (tables, CAN)
GRAVITY_FREE_MPS2 = 0.5  # a median |a| below this has no gravity in it (g read as m/s² gives ≈ 1)
GRAVITY_BAND_G = (0.5, 1.5)  # the median |a| of samples with gravity: at rest 1 g, driving close to it


@dataclass(frozen=True)
class Channel:
    """A scalar auxiliary signal on its own clock (temperature, speed, heading, position)."""

    t_s: FloatArray  # shape (m,), seconds on the log's clock
    value: FloatArray  # shape (m,), in the unit named by the channel key


@dataclass(frozen=True)
class Samples:
    """Accelerometer (and gyro) samples of one log, sensor frame, SI units.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Sample times in seconds on the log's clock, non-decreasing.
    acc_s : ndarray, shape (n, 3)
        Specific force in m/s², sensor frame.
    gyro_s : ndarray, shape (n, 3), or None
        Angular rate in rad/s, sensor frame, when the log has one.
    channels : dict of str to Channel
        Optional auxiliary signals, keyed by a name that carries the unit:
        ``temperature_c``, ``speed_mps``, ``heading_deg``, ``lat_deg``, ``lon_deg``, ``alt_m``.
    source : str
        The file the samples came from.
    axis_map : str
        How the device's axes were mapped to the right-handed sensor frame (``"x,y,z"`` when as-is).
    dropped : dict of str to int
        Frames or messages the reader discarded, counted by reason.
    notes : tuple of str
        What the reader inferred or chose and says (a detected export, the topic a speed came from).
    gravity_free : str
        Why ``acc_s`` is known to lack gravity (a "linear acceleration" export, or any log whose median
        magnitude is below 0.5 m/s²: :func:`marked_gravity_free`), else "": such samples read and list, but
        neither calibrate (the mounting is measured against gravity) nor rotate (the output would call them
        specific force).
    rotated : Rotated or None
        What the file's own metadata say when mountcal already rotated the samples into the vehicle (or
        levelled) frame (:mod:`mountcal.io.frame`), else None: such samples calibrate (to the rotation
        left over, ≈ 0), but do not rotate again (the mounting would be applied twice).
    incomplete : tuple of str
        Files read although cut short (``--allow-truncated``): where each ends and what its format
        expected there (:mod:`mountcal.io.whole`); empty when every file was whole.
    conventions : tuple of Convention
        How the log's conventions were known (axes, heading unit): set by :func:`mountcal.io.logs.read_log`.
    frame_ids : FrameIds or None
        The ``header.frame_id`` values of the IMU messages, with their counts (:mod:`mountcal.io.sensor_frame`):
        the name the log gives the sensor frame; None for a log that names no frames (CAN, tables).
    """

    t_s: FloatArray
    acc_s: FloatArray
    gyro_s: FloatArray | None = None
    channels: dict[str, Channel] = field(default_factory=dict)
    source: str = ""
    axis_map: str = "x,y,z"
    dropped: dict[str, int] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    gravity_free: str = ""
    rotated: Rotated | None = None
    incomplete: tuple[str, ...] = ()
    conventions: tuple[Convention, ...] = ()
    frame_ids: FrameIds | None = None

    def __post_init__(self) -> None:
        n = self.t_s.shape[0]
        if self.t_s.shape != (n,) or self.acc_s.shape != (n, 3):
            raise ValueError(f"t_s must be (n,) and acc_s (n, 3); got {self.t_s.shape}, {self.acc_s.shape}")
        if self.gyro_s is not None and self.gyro_s.shape != (n, 3):
            raise ValueError(f"gyro_s must be (n, 3); got {self.gyro_s.shape}")

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True)
class Stream:
    """One stream of a log as `mountcal inspect` lists it: a topic, or a CAN message."""

    name: str  # topic name, or CAN message name (or hex id when no DBC names it)
    kind: str  # message type / schema name, or "can" with the channel
    count: int
    rate_hz: float
    fields: tuple[str, ...] = ()  # signal or field names, where known
    dlcs: tuple[int, ...] = ()  # CAN: the data lengths the id was seen with


@dataclass(frozen=True)
class LogSummary:
    """What a log holds (the output of `mountcal inspect`)."""

    source: str
    format: str  # "mcap", "blf", "asc", "log", "trc", "csv", "mf4", "parquet"
    duration_s: float
    streams: tuple[Stream, ...]
    notes: tuple[str, ...] = ()  # what the reader inferred (a recognised export and its units)
    incomplete: tuple[str, ...] = ()  # as Samples.incomplete: the file was cut and read in part


def slices(samples: Samples, max_samples: int) -> Iterator[Samples]:
    """``samples`` in consecutive pieces of at most ``max_samples`` (views, not copies).

    Each auxiliary sample goes with the piece whose time span holds it (the first and last piece
    take those before and after the IMU samples); ``dropped`` and ``incomplete`` go with the first piece.
    """
    if max_samples < 1:
        raise ValueError(f"max_samples must be >= 1; got {max_samples}")
    n = len(samples)
    starts = list(range(0, n, max_samples)) or [0]
    for k, start in enumerate(starts):
        stop = min(start + max_samples, n)
        lo = -np.inf if k == 0 else samples.t_s[start]
        hi = np.inf if k == len(starts) - 1 else samples.t_s[stop]
        channels = {}
        for key, ch in samples.channels.items():
            i, j = np.searchsorted(ch.t_s, [lo, hi], side="left")
            channels[key] = Channel(ch.t_s[i:j], ch.value[i:j])
        yield replace(
            samples,
            t_s=samples.t_s[start:stop],
            acc_s=samples.acc_s[start:stop],
            gyro_s=None if samples.gyro_s is None else samples.gyro_s[start:stop],
            channels=channels,
            dropped=samples.dropped if k == 0 else {},
            notes=samples.notes if k == 0 else (),
            incomplete=samples.incomplete if k == 0 else (),
        )


def summary(samples: Samples, fmt: str, kind: str) -> LogSummary:
    """A log of one stream of samples (of type ``kind``) as `mountcal inspect` lists it."""
    n = len(samples)
    dur = float(samples.t_s[-1] - samples.t_s[0]) if n > 1 else 0.0
    rate = (n - 1) / dur if dur > 0 else 0.0
    fields = ("ax", "ay", "az", *(("gx", "gy", "gz") if samples.gyro_s is not None else ()), *samples.channels)
    return LogSummary(samples.source, fmt, dur, (Stream("samples", kind, n, rate, fields),), samples.notes)


def marked_gravity_free(samples: Samples) -> Samples:
    """``samples``, marked gravity-free (``gravity_free``) where their acceleration's median magnitude is
    below 0.5 m/s²: gravity is in every accelerometer's reading, so such an acceleration had it removed
    (a ROS ``Imu`` of "free" or linear acceleration, a phone's linear accelerometer). Applied to every log
    reader's samples (:func:`mountcal.io.logs.stated`); such samples read, but neither calibrate nor rotate."""
    if samples.gravity_free or not len(samples):
        return samples
    m = float(np.median(np.linalg.norm(samples.acc_s, axis=1)))
    if m >= GRAVITY_FREE_MPS2:
        return samples
    reason = f"the acceleration's median magnitude is {m:.3g} m/s²: no gravity in it, as in a 'linear acceleration'"
    return replace(samples, gravity_free=reason)


def with_gravity(samples: Samples) -> Samples:
    """``samples``, refused when their acceleration is known to lack gravity (a "linear acceleration"):
    the mounting is measured against gravity, which such samples have had removed.

    Raises
    ------
    InputError
        ``samples.gravity_free`` says why they lack it.
    """
    if samples.gravity_free:
        raise InputError(
            samples.source,
            "the specific force (an accelerometer's reading, gravity included) for calibration",
            f"an acceleration without gravity: {samples.gravity_free}",
            "Export the raw accelerometer (with g); a gravity-free acceleration can be neither levelled nor "
            "calibrated against gravity.",
        )
    return samples
