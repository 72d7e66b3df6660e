"""A comma2k19 segment (folders of NumPy arrays) as samples, with the car's own accelerations.

comma2k19 (github.com/commaai/comma2k19) stores each signal of a one-minute segment as a folder
holding ``t`` (boot-time seconds) and ``value`` (NumPy ``.npy`` files without a suffix). Read here:

- ``processed_log/IMU/accelerometer`` and ``gyro``: the windshield phone's IMU (m/s², rad/s) in
  the device's axes **[forward, right, down]**. That triad is right-handed; it is mapped to the
  sensor frame ``s`` = [forward, left, up] — ``axis_map = "x,-y,-z"`` (a 180° turn about x, so
  still right-handed) — which puts gravity on +z as mountcal's convention (+g up at rest) reads it.
- ``processed_log/CAN/speed``: the car's speed (m/s, ~83 Hz) → channel ``speed_mps``.
- ``processed_log/GNSS/live_gnss_ublox``: [lat, lon, speed, utc, alt, bearing] → channels
  ``lat_deg``, ``lon_deg``, ``alt_m``.
- ``processed_log/CAN/raw_can`` (``t, src, address, data``; ``data`` is ``|S8``, read as bytes so
  trailing NULs survive): the car's ``KINEMATICS`` message (0x24 on bus ``src`` 0) decoded with the
  DBC beside the segment (``toyota_new_mc_pt_generated.dbc``) by :func:`mountcal.io.can.dbc.decode`:
  ``ACCEL_X``, ``ACCEL_Y`` (m/s²) and ``YAW_RATE`` (deg/s), as the car sends them.

The car's signs are not ISO 8855's: on this segment ``ACCEL_X`` follows −d(speed)/dt and ``ACCEL_Y``
and ``YAW_RATE`` follow −v·ω and +ω of a counter-clockwise turn (correlations in
``docs/real-data-driving.md``), so :data:`KINEMATICS_TO_ISO` gives the vehicle-frame ``a_x``,
``a_y`` as ``−ACCEL_X``, ``−ACCEL_Y``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.io.can.dbc import decode, load_dbc
from mountcal.io.can.frames import DATA_WIDTH, CanFrames
from mountcal.io.folder import LocalFolder
from mountcal.io.reader import LogReader
from mountcal.io.samples import Channel, FloatArray, Samples
from mountcal.io.whole import found_cut, unreadable_part

if TYPE_CHECKING:
    from mountcal.io.folder import Folder
    from mountcal.io.reader import LogOptions

AXIS_MAP = "x,-y,-z"  # sensor [forward, left, up] from device [forward, right, down]
_DEVICE_TO_SENSOR = np.array([1.0, -1.0, -1.0])  # the diagonal of the 180° turn about x
DBC_NAME = "toyota_new_mc_pt_generated.dbc"
KINEMATICS_ID = 0x24
KINEMATICS_BUS = 0
KINEMATICS_TO_ISO = {"ACCEL_X": -1.0, "ACCEL_Y": -1.0}  # vehicle a_x = −ACCEL_X, a_y = −ACCEL_Y


@dataclass(frozen=True)
class Comma2k19Segment:
    """The phone's samples and the car's ``KINEMATICS`` signals of one segment.

    Attributes
    ----------
    samples : Samples
        ``acc_s`` (n, 3) m/s² and ``gyro_s`` (n, 3) rad/s in the sensor frame [forward, left, up]
        of the phone; channels ``speed_mps`` (CAN), ``lat_deg``, ``lon_deg``, ``alt_m`` (u-blox).
    kinematics : dict of str to Channel
        ``ACCEL_X``, ``ACCEL_Y`` (m/s²) and ``YAW_RATE`` (deg/s) as decoded from the CAN, on the
        same (boot-time) clock, with the car's signs (see :data:`KINEMATICS_TO_ISO`).
    """

    samples: Samples
    kinematics: dict[str, Channel]


def _array(folder: Path, *parts: str) -> NDArray[Any]:
    """The file's array in its own dtype (times and values are float, CAN fields integers)."""
    path = folder.joinpath(*parts)
    try:
        return np.asarray(np.load(path, allow_pickle=False))  # a .npy file without pickles: always an array
    except FileNotFoundError as err:
        raise InputError(
            str(path),
            "a comma2k19 segment folder (processed_log/…/t and value NumPy files)",
            "no such file",
            "Pass the segment folder itself (e.g. rav4_2018-08-02--08-34-47_seg40).",
        ) from err
    except (OSError, ValueError) as err:
        _check_whole(path)
        raise InputError(str(path), "a NumPy array file", f"an unreadable file ({err})", "Check the download.") from err


def _check_whole(path: Path) -> None:
    """A ``.npy`` file shorter than its header's shape and dtype say: cut short (:mod:`mountcal.io.whole`);
    an array cut short is not read in part."""
    try:
        with path.open("rb") as f:
            major, _ = np.lib.format.read_magic(f)
            header = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
            shape, _, dtype = header(f)
            expected = f.tell() + math.prod(shape) * dtype.itemsize
    except (OSError, ValueError):
        return  # not a .npy header: the error above says what is wrong
    size = path.stat().st_size
    if size < expected:
        cut = found_cut(path, size, f"the rest of its {dtype} array of shape {shape} (to byte {expected})")
        raise unreadable_part(cut, "a NumPy array is only whole")


def _signal(folder: Path, *parts: str) -> tuple[FloatArray, FloatArray]:
    t = np.asarray(_array(folder, *parts, "t"), dtype=np.float64)
    value = np.asarray(_array(folder, *parts, "value"), dtype=np.float64)
    if value.shape[0] != t.shape[0]:
        raise InputError(
            str(folder.joinpath(*parts)),
            "as many values as times",
            f"{value.shape[0]} and {t.shape[0]}",
            "Re-download.",
        )
    return t, value


def read_comma2k19(folder: str | os.PathLike[str], dbc: str | os.PathLike[str] | None = None) -> Comma2k19Segment:
    """Read a comma2k19 segment folder.

    Parameters
    ----------
    folder : path
        The segment folder (holding ``processed_log``).
    dbc : path, optional
        The car's DBC; default ``toyota_new_mc_pt_generated.dbc`` in the folder or its parent.

    Returns
    -------
    Comma2k19Segment

    Raises
    ------
    InputError
        A missing or unreadable array, or no DBC.
    """
    root = Path(folder)
    return Comma2k19Segment(read_segment_samples(root), read_kinematics(root, dbc))


def read_segment_samples(folder: str | os.PathLike[str]) -> Samples:
    """The phone's samples of a comma2k19 segment folder, with speed and position channels (no DBC needed)."""
    root = Path(folder)
    t_acc, acc = _signal(root, "processed_log", "IMU", "accelerometer")
    t_gyro, gyro = _signal(root, "processed_log", "IMU", "gyro")
    if acc.ndim != 2 or acc.shape[1] != 3 or gyro.shape != acc.shape or not np.array_equal(t_acc, t_gyro):
        raise InputError(
            str(root / "processed_log" / "IMU"),
            "accelerometer and gyro of shape (n, 3) on one clock",
            f"shapes {acc.shape} and {gyro.shape}",
            "Check the segment.",
        )
    ok = np.isfinite(t_acc) & np.isfinite(acc).all(axis=1) & np.isfinite(gyro).all(axis=1)
    order = np.argsort(t_acc[ok], kind="stable")
    channels: dict[str, Channel] = {}
    t_speed, speed = _signal(root, "processed_log", "CAN", "speed")
    channels["speed_mps"] = _channel(t_speed, speed.reshape(t_speed.shape[0], -1)[:, 0])
    t_gnss, gnss = _signal(root, "processed_log", "GNSS", "live_gnss_ublox")
    for key, column in (("lat_deg", 0), ("lon_deg", 1), ("alt_m", 4)):
        channels[key] = _channel(t_gnss, gnss[:, column])
    return Samples(
        t_acc[ok][order],
        acc[ok][order] * _DEVICE_TO_SENSOR,
        gyro[ok][order] * _DEVICE_TO_SENSOR,
        channels,
        source=str(root),
        axis_map=AXIS_MAP,
        dropped={"non-finite IMU samples": int((~ok).sum())} if not ok.all() else {},
    )


class Comma2k19Reader(LogReader):
    """comma2k19 segment folders in the registry: the phone's IMU as a log (``mountcal calibrate SEGMENT``)."""

    name = "comma2k19"
    description = "comma2k19 segment folder (processed_log/IMU)"

    def claims(self, path: Path, options: LogOptions) -> bool:
        return path.is_dir() and self.claims_folder(LocalFolder(path), options)

    def claims_folder(self, folder: Folder, options: LogOptions) -> bool:
        return folder.has_folder("processed_log/IMU/accelerometer")

    def read(self, path: Path, options: LogOptions) -> Samples:
        return read_segment_samples(path)


def _channel(t: FloatArray, value: FloatArray) -> Channel:
    ok = np.isfinite(t) & np.isfinite(value)
    order = np.argsort(t[ok], kind="stable")
    return Channel(t[ok][order], value[ok][order])


def read_kinematics(folder: str | os.PathLike[str], dbc: str | os.PathLike[str] | None = None) -> dict[str, Channel]:
    """The car's ``KINEMATICS`` (0x24, bus 0) signals from the segment's raw CAN, decoded with the DBC."""
    root = Path(folder)
    dbc_path = Path(dbc) if dbc is not None else _find_dbc(root)
    base = ("processed_log", "CAN", "raw_can")
    t = np.asarray(_array(root, *base, "t"), dtype=np.float64)
    src = np.asarray(_array(root, *base, "src"))
    address = np.asarray(_array(root, *base, "address"))
    raw = np.asarray(_array(root, *base, "data"))
    if raw.dtype.kind != "S" or not (t.shape == src.shape == address.shape == raw.shape):
        raise InputError(
            str(root.joinpath(*base)),
            "raw CAN arrays t, src, address and data (|S8) of one length",
            f"data of dtype {raw.dtype} and lengths {t.shape}, {src.shape}, {address.shape}, {raw.shape}",
            "Check the segment.",
        )
    mine = (src == KINEMATICS_BUS) & (address == KINEMATICS_ID)
    n = int(mine.sum())
    width = raw.dtype.itemsize
    payload = np.zeros((n, DATA_WIDTH), np.uint8)
    payload[:, :width] = raw[mine].view(np.uint8).reshape(n, width)  # a view keeps trailing NUL bytes
    frames = CanFrames(
        t[mine],
        np.full(n, KINEMATICS_BUS, np.int64),
        address[mine].astype(np.uint32),
        np.zeros(n, np.bool_),
        np.full(n, width, np.uint8),
        payload,
    )
    db = load_dbc(dbc_path)
    try:
        message = db.get_message_by_frame_id(KINEMATICS_ID)
    except KeyError as err:
        raise InputError(str(dbc_path), "a KINEMATICS message (0x24)", "none", "Pass the car's DBC.") from err
    values = decode(frames, message, ["ACCEL_X", "ACCEL_Y", "YAW_RATE"])
    order = np.argsort(frames.t_s, kind="stable")
    return {name: _channel(frames.t_s[order], v[order]) for name, v in values.items()}


def _find_dbc(root: Path) -> Path:
    for candidate in (root / DBC_NAME, root.parent / DBC_NAME):
        if candidate.is_file():
            return candidate
    raise InputError(
        str(root),
        f"the car's DBC ({DBC_NAME}) in the segment folder or beside it",
        "none",
        "Pass dbc= (the opendbc Toyota file generated as comma2k19's README says).",
    )
