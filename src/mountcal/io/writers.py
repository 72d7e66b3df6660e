"""Write samples as real logs — ROS 2 MCAP and every CAN log format — with their protocol sheet.

The formats' own writers do the writing, so a file is what a real recorder would leave:

- **MCAP**: ``mcap_ros2.writer.Writer`` (CDR, zstd chunks) with ``sensor_msgs/msg/Imu``,
  ``sensor_msgs/msg/Temperature``, ``sensor_msgs/msg/NavSatFix`` and ``nav_msgs/msg/Odometry``.
  The schemas are the standard definitions (field and constant lines; comments left out),
  concatenated as rosbag2 does: the top-level ``.msg``, then each dependency (depth first, sorted, each
  once) after a line of 80 ``=`` and ``MSG: package/Type``.
- **CAN**: python-can's writer for the suffix (BLF, ASC, candump ``.log``, TRC, CSV; MF4 through
  its ``MF4Writer``, which uses asammdf), every frame encoded by cantools from a DBC. The default
  layout is ``data/imu_mm5_10.dbc``: the Bosch MM5.10 IMU (AY1 + Yaw_Rate in 0x70, AX1 + Roll_Rate
  in 0x80, AZ in 0x576, 0.000127465 g/bit) and mountcal's own speed, heading, temperature and GNSS
  messages (0x300–0x304).

Conventions of every writer here:

- **Clock**: a sample at ``t_s`` is stamped ``start_time_s + t_s`` (Unix seconds). Each writer
  returns :class:`WrittenLog` whose ``start_time_s`` is the log's ``t_s = 0`` *on the clock
  mountcal's reader gives that file* — the written start for every format but ASC, which python-can
  reads relative to its first frame. Write the protocol sheet with that value and it lines up.
- **Quantisation is real**: a CAN signal holds what its DBC scaling can (the MM5.10's 1.25 mm/s²); python-can
  stores times as float seconds (≈ 0.24 µs at Unix-epoch magnitudes; BLF keeps ns, the text formats µs). A value
  outside a signal's DBC range is written saturated and counted; a non-finite sample is not written and counted.
- **Output**: a temporary file renamed into place (never a partial file). **Units**: SI, x, y, z as ax/ay/az.
"""

from __future__ import annotations

import heapq
import math
import os
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from mountcal.core.atomic import atomic_output, atomic_path
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.can.dbc import load_dbc
from mountcal.io.can.signals import UNIT_KIND
from mountcal.io.can.write import (
    EncodedMessage,
    can_format,
    encode,
    physical,
    resolve_signal,
    signal_unit,
    write_frames,
)
from mountcal.io.heading_frame import north_east_down
from mountcal.io.ros2.definitions import ros2_definition
from mountcal.io.samples import FloatArray, Samples

START_TIME_S = 1_714_557_600.0  # 2024-05-01 10:00:00 UTC: the default absolute start of a written log
AUX_RATE_HZ = {"speed_mps": 10.0, "heading_deg": 10.0, "temperature_c": 1.0}  # simulated channels, thinned
FIX_RATE_HZ = 1.0
FRAME_SPACING_S = 250e-6  # an 8-byte frame at 500 kbit/s: the IMU's messages of one sample follow each other

# --------------------------------------------------------------------------- ROS 2 message definitions


# --------------------------------------------------------------------------- what gets written


class SimulatedLog(Protocol):
    """A simulated log as a logger records it (:class:`mountcal.simulate.stops.ParkingLog`): the samples,
    the auxiliary channels at the samples' rate, and the stops' protocol."""

    @property
    def t_s(self) -> FloatArray: ...
    @property
    def acc_s(self) -> FloatArray: ...
    @property
    def gyro_s(self) -> FloatArray: ...
    @property
    def speed_mps(self) -> FloatArray: ...
    @property
    def heading_deg(self) -> FloatArray: ...
    @property
    def temperature_c(self) -> FloatArray: ...
    @property
    def protocol(self) -> list[tuple[float, float, float]]: ...


@dataclass(frozen=True)
class WrittenLog:
    """What a writer wrote.

    Attributes
    ----------
    path : str
    format : str
        ``"mcap"``, ``"blf"``, ``"asc"``, ``"log"``, ``"trc"``, ``"csv"`` or ``"mf4"``.
    start_time_s : float
        The log's ``t_s = 0`` in seconds on the clock mountcal's reader gives this file (see the
        module docstring); add it to the log's times to get the file's.
    messages : dict of str to int
        Messages written, per topic or CAN message name.
    saturated : dict of str to int
        Values written at the end of their DBC range instead of their own, per ``message.signal``.
    skipped : dict of str to int
        Samples not written, by reason (non-finite values).
    """

    path: str
    format: str
    start_time_s: float
    messages: dict[str, int]
    saturated: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class _Series:
    """The samples to write: IMU rows and auxiliary channels, each on its own clock (s, SI)."""

    t_s: FloatArray  # (n,)
    acc_s: FloatArray  # (n, 3), m/s²
    gyro_s: FloatArray | None  # (n, 3), rad/s
    channels: dict[str, tuple[FloatArray, FloatArray]]  # key (as Samples.channels) → (t_s, value)


def _thin(t_s: FloatArray, rate_hz: float) -> NDArray[np.intp]:
    """Indices of the first sample in each 1/rate_hz slot: a channel thinned to about rate_hz."""
    slot = np.floor((t_s - t_s[0]) * rate_hz + 1e-9).astype(np.int64)
    return np.flatnonzero(np.concatenate([[True], np.diff(slot) > 0]))


def _series(log: SimulatedLog | Samples, with_fix: tuple[float, float, float] | None) -> _Series:
    """The log as a :class:`_Series`; a ParkingLog's 100 Hz channels thinned to AUX_RATE_HZ."""
    t = np.asarray(log.t_s, dtype=np.float64)
    if t.ndim != 1 or t.size == 0 or np.any(np.diff(t) < 0) or not np.all(np.isfinite(t)):
        raise InputError(
            "the log to write",
            "samples with finite, non-decreasing times",
            "no samples" if t.size == 0 else "times that are not finite or not in order",
            "Sort the samples by time and drop those without one.",
        )
    acc = np.asarray(log.acc_s, dtype=np.float64)
    gyro = None if log.gyro_s is None else np.asarray(log.gyro_s, dtype=np.float64)
    channels: dict[str, tuple[FloatArray, FloatArray]] = {}
    if isinstance(log, Samples):
        channels = {
            k: (np.asarray(c.t_s, np.float64), np.asarray(c.value, np.float64)) for k, c in log.channels.items()
        }
    else:
        for key, rate in AUX_RATE_HZ.items():
            keep = _thin(t, rate)
            channels[key] = (t[keep], np.asarray(getattr(log, key), np.float64)[keep])
    if with_fix is not None:
        times = t[_thin(t, FIX_RATE_HZ)]
        for key, value in zip(("lat_deg", "lon_deg", "alt_m"), with_fix, strict=True):
            channels[key] = (times, np.full(times.size, float(value)))
    return _Series(t, acc, gyro, channels)


def _to_ns(time_s: float) -> int:
    """Seconds as integer nanoseconds, exact for whole and µs-resolved times."""
    whole = math.floor(time_s)
    return whole * 1_000_000_000 + round((time_s - whole) * 1e9)


# --------------------------------------------------------------------------- MCAP


IMU_TOPIC = "/imu/data"
TEMPERATURE_TOPIC = "/imu/temperature"
FIX_TOPIC = "/gnss/fix"
ODOMETRY_TOPIC = "/odom"

_Message = tuple[int, str, str, dict[str, Any]]  # (stamp in ns, topic, ROS 2 type, message as a dict)


def write_mcap(
    path: str | os.PathLike[str],
    log: SimulatedLog | Samples,
    *,
    imu_topic: str = IMU_TOPIC,
    frame_id: str = "imu_link",
    with_temperature: bool = True,
    with_fix: tuple[float, float, float] | None = None,
    with_odometry: bool = True,
    start_time_s: float = START_TIME_S,
    stamp_offsets_s: Mapping[str, float] | None = None,
    odometry_frame: str = "enu",
) -> WrittenLog:
    """Write a ROS 2 MCAP log (CDR) with the real writer, ``mcap_ros2.writer.Writer``.

    Messages of all topics are written in time order, as a recorder receives them; each topic's
    schema is registered when its first message is written.

    Parameters
    ----------
    path : str or path-like
        The ``.mcap`` to write (atomically).
    log : ParkingLog or Samples
        ``t_s`` (n,) s, ``acc_s`` (n, 3) m/s² and ``gyro_s`` (n, 3) rad/s in the sensor frame; the
        channels ``temperature_c``, ``speed_mps``, ``heading_deg`` (compass) and, for Samples,
        ``lat_deg``/``lon_deg``/``alt_m``. A ParkingLog's channels are thinned to ``AUX_RATE_HZ``.
    imu_topic, frame_id : str
        Topic and ``header.frame_id`` of the ``sensor_msgs/msg/Imu`` messages (the sensor frame).
    with_temperature : bool
        Write ``temperature_c`` as ``sensor_msgs/msg/Temperature`` on ``/imu/temperature``.
    with_fix : (lat_deg, lon_deg, alt_m), optional
        Write this fixed position as ``sensor_msgs/msg/NavSatFix`` at 1 Hz on ``/gnss/fix``
        (WGS 84, altitude above the ellipsoid); without it, a Samples' own position channels.
    with_odometry : bool
        Write ``nav_msgs/msg/Odometry`` on ``/odom`` (frame ``odometry_frame``): speed in
        ``twist.twist.linear.x``, heading as the orientation's yaw = 90° − compass heading.
    start_time_s : float
        Unix time of the log's ``t_s = 0``: every ``header.stamp`` and log time is ``start_time_s + t``.
    stamp_offsets_s : mapping of topic to float, optional
        A driver's clock: the topic's ``header.stamp`` = log time + offset (s) (boot time: ``100 - start_time_s``).
    odometry_frame : str
        The odometry's ``header.frame_id`` (:mod:`mountcal.io.heading_frame`): ``enu``, or ``…_ned`` (NED yaw).

    Returns
    -------
    WrittenLog

    Notes
    -----
    The Imu orientation is unknown: ``orientation_covariance[0] = -1``, as the message definition asks; without a
    gyro the same holds for ``angular_velocity``. Other covariances are zero (unknown). Needs mcap-ros2-support.
    """
    try:
        from mcap_ros2.writer import Writer
    except ImportError as err:
        raise InputError(
            str(path), "mcap-ros2-support, to write ROS 2 MCAP", "it is not installed", "pip install mcap-ros2-support"
        ) from err
    series, start_ns = _series(log, with_fix), _to_ns(start_time_s)
    ok = np.asarray(np.isfinite(series.acc_s).all(axis=1), dtype=np.bool_)
    if series.gyro_s is not None:
        ok &= np.isfinite(series.gyro_s).all(axis=1)
    skipped = {"imu: non-finite value": int((~ok).sum())} if not ok.all() else {}
    streams = [
        _imu_messages(series, ok, start_ns, imu_topic, frame_id),
        _temperature_messages(series, start_ns, frame_id) if with_temperature else iter(()),
        _fix_messages(series, start_ns),
        _odometry_messages(series, start_ns, odometry_frame) if with_odometry else iter(()),
    ]
    counts: Counter[str] = Counter()
    schemas: dict[str, Any] = {}
    with atomic_output(path) as f:
        writer: Any = Writer(f)
        for t_ns, topic, type_name, message in heapq.merge(*streams, key=lambda m: m[0]):
            if topic not in schemas:
                schemas[topic] = writer.register_msgdef(type_name, ros2_definition(type_name))
            if stamp_offsets_s and topic in stamp_offsets_s:  # a driver stamping on its own clock
                message["header"] = _header(t_ns + _to_ns(stamp_offsets_s[topic]), message["header"]["frame_id"])
            writer.write_message(
                topic, schemas[topic], message, log_time=t_ns, publish_time=t_ns, sequence=counts[topic]
            )
            counts[topic] += 1
        writer.finish()
    return WrittenLog(str(path), "mcap", start_time_s, dict(counts), {}, skipped)


def _stamps(start_ns: int, t_s: FloatArray) -> list[int]:
    stamps: list[int] = (start_ns + np.round(t_s * 1e9).astype(np.int64)).tolist()  # int64 → Python ints
    return stamps


def _header(t_ns: int, frame_id: str) -> dict[str, Any]:
    return {"stamp": {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000}, "frame_id": frame_id}


def _vector(v: list[float]) -> dict[str, float]:
    return {"x": v[0], "y": v[1], "z": v[2]}


def _imu_messages(
    series: _Series, ok: NDArray[np.bool_], start_ns: int, topic: str, frame_id: str
) -> Iterator[_Message]:
    acc = series.acc_s[ok].tolist()
    gyro = series.gyro_s[ok].tolist() if series.gyro_s is not None else [[0.0, 0.0, 0.0]] * len(acc)
    unknown = [-1.0] + [0.0] * 8  # "element 0 = -1: no estimate" (sensor_msgs/msg/Imu)
    zero = [0.0] * 9
    gyro_cov = zero if series.gyro_s is not None else unknown
    for t_ns, a, w in zip(_stamps(start_ns, series.t_s[ok]), acc, gyro, strict=True):
        yield (
            t_ns,
            topic,
            "sensor_msgs/msg/Imu",
            {
                "header": _header(t_ns, frame_id),
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                "orientation_covariance": unknown,
                "angular_velocity": _vector(w),
                "angular_velocity_covariance": gyro_cov,
                "linear_acceleration": _vector(a),
                "linear_acceleration_covariance": zero,
            },
        )


def _temperature_messages(series: _Series, start_ns: int, frame_id: str) -> Iterator[_Message]:
    if "temperature_c" not in series.channels:
        return
    t, value = series.channels["temperature_c"]
    for t_ns, v in zip(_stamps(start_ns, t), value.tolist(), strict=True):
        message = {"header": _header(t_ns, frame_id), "temperature": v, "variance": 0.0}  # 0: unknown
        yield t_ns, TEMPERATURE_TOPIC, "sensor_msgs/msg/Temperature", message


def _fix_messages(series: _Series, start_ns: int) -> Iterator[_Message]:
    ch = series.channels
    if not {"lat_deg", "lon_deg", "alt_m"} <= ch.keys():
        return
    t, lat = ch["lat_deg"]
    lon, alt = (_held(t, *ch[k]) for k in ("lon_deg", "alt_m"))
    for t_ns, la, lo, al in zip(_stamps(start_ns, t), lat.tolist(), lon.tolist(), alt.tolist(), strict=True):
        yield (
            t_ns,
            FIX_TOPIC,
            "sensor_msgs/msg/NavSatFix",
            {
                "header": _header(t_ns, "gnss"),
                "status": {"status": 0, "service": 1},  # STATUS_FIX, SERVICE_GPS
                "latitude": la,
                "longitude": lo,
                "altitude": al,
                "position_covariance": [0.0] * 9,
                "position_covariance_type": 0,  # COVARIANCE_TYPE_UNKNOWN
            },
        )


def _odometry_messages(series: _Series, start_ns: int, frame_id: str) -> Iterator[_Message]:
    ch = series.channels
    if "speed_mps" not in ch:
        return
    t, speed = ch["speed_mps"]
    # the frame's yaw of the compass heading: ENU counter-clockwise from east (90° − heading), NED the heading
    heading = _held(t, *ch["heading_deg"]) if "heading_deg" in ch else None
    yaw = None if heading is None else np.radians(heading if north_east_down(frame_id) else 90.0 - heading)
    for i, (t_ns, v) in enumerate(zip(_stamps(start_ns, t), speed.tolist(), strict=True)):
        if yaw is None:  # a zero quaternion is no rotation (readers drop it), rather than a false "east"
            quat = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0}
        else:
            quat = {"x": 0.0, "y": 0.0, "z": math.sin(yaw[i] / 2.0), "w": math.cos(yaw[i] / 2.0)}
        yield (
            t_ns,
            ODOMETRY_TOPIC,
            "nav_msgs/msg/Odometry",
            {
                "header": _header(t_ns, frame_id),
                "child_frame_id": "base_link",
                "pose": {
                    "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": quat},
                    "covariance": [0.0] * 36,
                },
                "twist": {
                    "twist": {"linear": {"x": v, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}},
                    "covariance": [0.0] * 36,
                },
            },
        )


def _held(t_s: FloatArray, t_ch: FloatArray, value: FloatArray) -> FloatArray:
    """The channel's latest value at each time (its first before it starts): no interpolation of angles."""
    index = np.clip(np.searchsorted(t_ch, t_s, side="right") - 1, 0, t_ch.size - 1)
    return value[index]


# --------------------------------------------------------------------------- CAN

MM5_10_SIGNALS: dict[str, str] = {  # role → "message.signal" in data/imu_mm5_10.dbc
    "ax": "MM5_10_TX2.AX1",
    "ay": "MM5_10_TX1.AY1",
    "az": "MM5_10_TX3.AZ",
    "gx": "MM5_10_TX2.Roll_Rate",
    "gy": "MM5_10_TX3.Pitch_Rate",
    "gz": "MM5_10_TX1.Yaw_Rate",
    "speed": "SIM_VEHICLE_SPEED.VehicleSpeed",
    "heading": "SIM_GNSS_HEADING.Heading",
    "temperature": "SIM_IMU_TEMPERATURE.ImuTemperature",
    "latitude": "SIM_GNSS_POSITION.Latitude",
    "longitude": "SIM_GNSS_POSITION.Longitude",
    "altitude": "SIM_GNSS_ALTITUDE.Altitude",
}
_IMU_ROLES = ("ax", "ay", "az", "gx", "gy", "gz")
_CHANNEL_OF_ROLE = {
    "speed": "speed_mps",
    "heading": "heading_deg",
    "temperature": "temperature_c",
    "latitude": "lat_deg",
    "longitude": "lon_deg",
    "altitude": "alt_m",
}


@dataclass
class _Layout:
    """The DBC signals each role is written to, grouped by message."""

    imu: dict[Any, dict[str, str]] = field(default_factory=dict)  # message → {signal: role}
    aux: dict[Any, dict[str, str]] = field(default_factory=dict)


def write_can_log(
    path: str | os.PathLike[str],
    log: SimulatedLog | Samples,
    *,
    dbc_path: str | os.PathLike[str],
    signals: Mapping[str, str] | None = None,
    with_fix: tuple[float, float, float] | None = None,
    start_time_s: float = START_TIME_S,
    channel: int = 0,
) -> WrittenLog:
    """Write a CAN log — BLF, ASC, candump ``.log``, TRC, CSV or MF4 by the suffix — with python-can.

    Each IMU sample becomes one frame of every IMU message (in id order, ``FRAME_SPACING_S``
    apart, the message carrying ``ax`` at the sample's time); the auxiliary channels become their
    messages' frames on their own clocks. Payloads are encoded by cantools from the DBC.

    Parameters
    ----------
    path : str or path-like
        The log to write (atomically); its suffix picks the writer.
    log : ParkingLog or Samples
        As in :func:`write_mcap`. Without a gyro the rate signals are written as 0.
    dbc_path : str or path-like
        The DBC (``data/imu_mm5_10.dbc`` for the default ``signals``). MF4 files embed it.
    signals : mapping of str to str, optional
        Role → ``"message.signal"`` (a message by name or id, as in mapping files): ``ax``, ``ay``,
        ``az``, optionally ``gx``/``gy``/``gz``, ``speed``, ``heading``, ``temperature``,
        ``latitude``, ``longitude``, ``altitude``. Default :data:`MM5_10_SIGNALS`. Signals of a
        written message that no role names are written as 0 (or their range's nearest end).
    with_fix : (lat_deg, lon_deg, alt_m), optional
        A fixed position written at 1 Hz to the latitude/longitude/altitude signals.
    start_time_s : float
        Unix time of the log's ``t_s = 0``.
    channel : int
        CAN channel, python-can numbering (0 is Vector's "CAN 1").

    Returns
    -------
    WrittenLog
        ``start_time_s`` on the clock mountcal reads back (for ASC: relative to the first frame);
        ``saturated`` counts values clipped to a signal's DBC range.

    Raises
    ------
    InputError
        Unknown suffix, unreadable DBC, a role naming no signal of it, a unit the writer cannot
        convert to, or a log without samples.
    """
    fmt = can_format(path)
    db = load_dbc(Path(dbc_path))
    series = _series(log, with_fix)
    layout = _layout(db, dict(signals or MM5_10_SIGNALS), str(dbc_path), series)
    saturated: Counter[str] = Counter()
    skipped: Counter[str] = Counter()
    encoded = _encode_imu(series, layout, saturated, skipped, str(dbc_path))
    encoded += _encode_aux(series, layout, saturated, skipped, str(dbc_path))
    with atomic_path(path, keep_name=True) as tmp:
        write_frames(tmp, fmt, encoded, start_time_s, Path(dbc_path), channel)
    first = min(float(e.t_s.min()) for e in encoded if e.t_s.size)
    clock = -first if fmt == "asc" else start_time_s  # python-can reads ASC from its first frame on
    messages = {e.message.name: len(e.data) for e in encoded}
    return WrittenLog(str(path), fmt, clock, messages, dict(saturated), dict(skipped))


def _layout(db: Any, signals: dict[str, str], where: str, series: _Series) -> _Layout:
    """Which signals of which messages to write; roles the log has no data for are left out."""
    unknown = sorted(set(signals) - set(UNIT_KIND))
    if unknown or not {"ax", "ay", "az"} <= signals.keys():
        raise InputError(
            "signals",
            "roles ax, ay, az and optionally " + ", ".join(r for r in UNIT_KIND if r not in ("ax", "ay", "az")),
            f"unknown roles {unknown}" if unknown else f"only {sorted(signals)}",
            "Fix the role names.",
        )
    layout = _Layout()
    for role, text in signals.items():
        if role in ("gx", "gy", "gz") and series.gyro_s is None:
            continue
        if role in _CHANNEL_OF_ROLE and _CHANNEL_OF_ROLE[role] not in series.channels:
            continue
        message, signal = resolve_signal(db, text, role, where)
        signal_unit(signal, role, where)  # fail early on a unit the writer cannot convert to
        group = layout.imu if role in _IMU_ROLES else layout.aux
        if message in (layout.aux if role in _IMU_ROLES else layout.imu):
            raise InputError(where, f"IMU and auxiliary signals in separate messages ({role})", message.name, "Remap.")
        group.setdefault(message, {})[signal.name] = role
    return layout


def _encode_imu(
    series: _Series, layout: _Layout, saturated: Counter[str], skipped: Counter[str], where: str
) -> list[EncodedMessage]:
    rows = np.column_stack([series.acc_s] + ([series.gyro_s] if series.gyro_s is not None else []))
    ok = np.isfinite(rows).all(axis=1)
    if not ok.all():
        skipped["imu: non-finite value"] += int((~ok).sum())
    rows, t_s = rows[ok], series.t_s[ok]
    messages = sorted(layout.imu, key=lambda m: (int(m.frame_id), m.name))
    ax_rank = next(i for i, m in enumerate(messages) if "ax" in layout.imu[m].values())
    out = []
    for rank, message in enumerate(messages):
        columns = {
            name: physical(message.get_signal_by_name(name), role, rows[:, _IMU_ROLES.index(role)], saturated, message)
            for name, role in layout.imu[message].items()
        }
        t_frames = t_s + (rank - ax_rank) * FRAME_SPACING_S
        out.append(EncodedMessage(message, t_frames, encode(message, columns, t_s.size, where)))
    return out


def _encode_aux(
    series: _Series, layout: _Layout, saturated: Counter[str], skipped: Counter[str], where: str
) -> list[EncodedMessage]:
    out = []
    for message, roles in sorted(layout.aux.items(), key=lambda item: int(item[0].frame_id)):
        first = _CHANNEL_OF_ROLE[next(iter(roles.values()))]
        t_ch = series.channels[first][0]
        si = {name: _held(t_ch, *series.channels[_CHANNEL_OF_ROLE[role]]) for name, role in roles.items()}
        ok = np.all([np.isfinite(v) for v in si.values()], axis=0)
        if not ok.all():
            skipped[f"{message.name}: non-finite value"] += int((~ok).sum())
        columns = {
            name: physical(message.get_signal_by_name(name), roles[name], v[ok], saturated, message)
            for name, v in si.items()
        }
        out.append(EncodedMessage(message, t_ch[ok], encode(message, columns, int(ok.sum()), where)))
    return out


# --------------------------------------------------------------------------- protocol sheet


def write_protocol(path: str | os.PathLike[str], log: SimulatedLog, *, start_time_s: float = START_TIME_S) -> None:
    """Write the protocol sheet, CSV ``t_start_s, t_end_s, beta_deg``, on a written log's clock.

    Parameters
    ----------
    path : str or path-like
        The CSV to write (atomically).
    log : ParkingLog
        Its ``protocol``: (t_start_s, t_end_s, beta_deg) of each stop, β from the uphill direction.
    start_time_s : float
        The log's ``t_s = 0`` on the written file's clock: :attr:`WrittenLog.start_time_s`.
    """
    rows = np.asarray(log.protocol, dtype=np.float64).reshape(-1, 3)
    lines = ["t_start_s,t_end_s,beta_deg"]
    lines += [f"{t0 + start_time_s:.6f},{t1 + start_time_s:.6f},{beta:.10g}" for t0, t1, beta in rows.tolist()]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")


def check_log_path(path: str | os.PathLike[str], dbc_path: str | os.PathLike[str] | None) -> str:
    """The format a log path will be written in; InputError before anything is simulated or written."""
    if Path(path).suffix.lower() == ".mcap":
        return "mcap"
    fmt = can_format(path, others=(".mcap",))
    if dbc_path is None:
        raise InputError(
            str(path),
            "a DBC to encode the CAN frames",
            "none",
            f"Pass the DBC (e.g. {option('dbc', 'data/imu_mm5_10.dbc')}, the Bosch MM5.10 layout).",
        )
    load_dbc(Path(dbc_path))
    return fmt


def write_log(
    path: str | os.PathLike[str],
    log: SimulatedLog | Samples,
    *,
    dbc_path: str | os.PathLike[str] | None = None,
    with_fix: tuple[float, float, float] | None = None,
    start_time_s: float = START_TIME_S,
) -> WrittenLog:
    """Write ``log`` as the format its suffix names: :func:`write_mcap` or :func:`write_can_log`."""
    if check_log_path(path, dbc_path) == "mcap":
        return write_mcap(path, log, with_fix=with_fix, start_time_s=start_time_s)
    assert dbc_path is not None  # checked: a CAN log needs one
    return write_can_log(path, log, dbc_path=dbc_path, with_fix=with_fix, start_time_s=start_time_s)


__all__ = [
    "MM5_10_SIGNALS",
    "START_TIME_S",
    "WrittenLog",
    "check_log_path",
    "write_can_log",
    "write_log",
    "write_mcap",
    "write_protocol",
]
