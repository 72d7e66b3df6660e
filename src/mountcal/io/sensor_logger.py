"""A Sensor Logger recording (the phone app by Kelvin Choi) as one log: its folder, or its ``.zip`` export.

Sensor Logger (github.com/tszheichoi/awesome-sensor-logger: UNITS.md, COORDINATES.md, CROSSPLATFORM.md)
writes one CSV per sensor, each with ``time`` (ns since the Unix epoch, UTC), ``seconds_elapsed`` and its
values; ``Metadata.csv`` (one row) names the ``platform``. Read here (names case-insensitive; the zip's
members are read in memory, never extracted):

- the acceleration with gravity: ``TotalAcceleration.csv`` (x, y, z in m/s²; logged on Android only), else
  ``Accelerometer.csv`` (gravity removed) + ``Gravity.csv`` (the phone's gravity vector), Gravity
  interpolated onto the accelerometer's times (rows outside Gravity's span are dropped and counted);
- ``Gyroscope.csv`` (rad/s, the same sign on both platforms), interpolated onto the acceleration's times;
- ``Location.csv`` → channels ``speed_mps`` and ``heading_deg`` (a negative speed or bearing means
  invalid: those rows are left out of that channel and counted in a note), ``lat_deg``, ``lon_deg``,
  ``alt_m`` (WGS 84 ellipsoid).

**The sign.** Android logs the specific force (+g up at rest). iOS, with the app's setting "Standardise
Units & Frames" off (its default), logs the inertial force: acceleration and gravity negated in all three
axes; with it on, it follows Android. The setting is not recorded, so the sign is (``acceleration_sign``
in ``Samples.conventions``): **stated** by the platform (Android), or by a Metadata column naming the
setting; **inferred** from ``AccelerometerUncalibrated.csv`` (in g with the setting off, in m/s² with it
on); else the app's **default** (off: negated). A default the handedness checks of the answer then
contradict is turned round once (:func:`other_sign`, :mod:`mountcal.calibration.pipeline`); one nothing
confirms leaves the result not confident (:func:`mountcal.loop.plausibility.sign_check`).
"""

from __future__ import annotations

import io
import re
import zipfile
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Literal

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.core.result import Convention
from mountcal.io.folder import LocalFolder
from mountcal.io.reader import LogReader
from mountcal.io.samples import Channel, FloatArray, Samples

if TYPE_CHECKING:
    from mountcal.io.folder import Folder
    from mountcal.io.reader import LogOptions

METADATA = "metadata.csv"
TOTAL = "totalacceleration.csv"
LINEAR = "accelerometer.csv"
GRAVITY = "gravity.csv"
GYRO = "gyroscope.csv"
LOCATION = "location.csv"
UNCALIBRATED = "accelerometeruncalibrated.csv"
ACCELERATION = (TOTAL, LINEAR)
SETTING = "Standardise Units & Frames"
SIGN = "acceleration_sign"
AS_LOGGED = "as logged (specific force: +g up at rest)"
NEGATED = f"negated (logged as the inertial force: iOS with {SETTING!r} off)"
WHAT = (
    "a Sensor Logger recording: Metadata.csv with TotalAcceleration.csv (Android) or Accelerometer.csv and "
    "Gravity.csv (iOS)"
)
_HOWS: tuple[Literal["stated", "inferred", "default"], ...] = ("stated", "inferred", "default")
_G_RANGE = (0.8, 1.2)  # a still uncalibrated accelerometer's median |a| in g ...
_MPS2_RANGE = (7.8, 11.8)  # ... and in m/s²


class _Recording:
    """The CSV files of a recording, by lower-case name: a folder's files or a zip's members."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._zip: zipfile.ZipFile | None = None
        self.files: dict[str, str] = {}
        if path.is_dir():
            self.files = {p.name.lower(): p.name for p in path.iterdir() if p.is_file()}
            self.members = sorted(self.files.values())
            return
        self._zip = _open_zip(path)
        names = [n for n in self._zip.namelist() if not n.endswith("/") and not n.startswith("__MACOSX/")]
        meta = [n for n in names if PurePosixPath(n).name.lower() == METADATA]
        folder = PurePosixPath(meta[0]).parent if len(meta) == 1 else PurePosixPath(".")  # it may sit in a folder
        inside = [n for n in names if PurePosixPath(n).parent == folder]
        self.files = {PurePosixPath(n).name.lower(): n for n in inside}
        self.members = names

    def has(self, name: str) -> bool:
        return name in self.files

    def where(self, name: str) -> str:
        inner = self.files.get(name, name)
        return f"{self.path}:{inner}" if self._zip is not None else str(self.path / inner)

    def table(self, name: str) -> pd.DataFrame:
        """The file's rows, its column names stripped and in lower case."""
        try:
            if self._zip is not None:
                frame = pd.read_csv(io.BytesIO(self._zip.read(self.files[name])))
            else:
                frame = pd.read_csv(self.path / self.files[name])
        except (OSError, ValueError, zipfile.BadZipFile, pd.errors.ParserError) as err:
            where = self.where(name)
            raise InputError(where, "a CSV file", f"one that does not read ({err})", "Export again.") from err
        return frame.rename(columns=lambda c: str(c).strip().lower())

    def close(self) -> None:
        if self._zip is not None:
            self._zip.close()


def _open_zip(path: Path) -> zipfile.ZipFile:
    try:
        return zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as err:
        raise InputError(
            str(path),
            WHAT + " (a zip)",
            f"a zip archive that does not open ({err}): cut short in a copy or a download?",
            "Copy or export it again.",
        ) from err


def _is_recording_zip(path: Path) -> bool:
    """A zip holding CSV files (a phone app's export), or one that does not open (cut short): claimed, to be read
    or refused saying what it holds or why it does not open. Other zips are left to plugins (a plugin's format
    may be a zip inside)."""
    try:
        with zipfile.ZipFile(path) as z:
            return any(n.lower().endswith(".csv") for n in z.namelist())
    except zipfile.BadZipFile:
        return path.is_file()  # no zip's directory at its end (cut short): refused by the reader, naming that
    except OSError:
        return False


def _vectors(rec: _Recording, name: str) -> tuple[FloatArray, FloatArray, int]:
    """(t_s sorted, (n, 3) values, rows dropped as non-finite or unstamped) of a file's ``x, y, z``."""
    frame = rec.table(name)
    missing = [c for c in ("time", "x", "y", "z") if c not in frame.columns]
    if missing:
        raise InputError(
            rec.where(name),
            "Sensor Logger's columns time (ns), x, y, z",
            f"columns {', '.join(map(repr, frame.columns))}",
            "Export the recording again with Sensor Logger.",
        )
    t = _seconds(frame["time"])
    values = frame[["x", "y", "z"]].apply(pd.to_numeric, errors="coerce").to_numpy(np.float64)
    ok = np.isfinite(t) & np.isfinite(values).all(axis=1)
    if not ok.any():
        raise InputError(
            rec.where(name),
            "rows with a time (ns since 1970) and finite x, y, z",
            f"none among its {t.size} rows",
            "Export the recording again with Sensor Logger.",
        )
    order = np.argsort(t[ok], kind="stable")
    return t[ok][order], values[ok][order], int((~ok).sum())


def _seconds(column: pd.Series) -> FloatArray:
    """Unix seconds of ``time`` in ns, split so that the float keeps the nanoseconds' microseconds."""
    ns = pd.to_numeric(column, errors="coerce")
    if ns.dtype.kind in "iu":
        whole = ns.to_numpy(np.int64)
        seconds = (whole // 1_000_000_000).astype(np.float64) + (whole % 1_000_000_000).astype(np.float64) * 1e-9
        return np.asarray(seconds, dtype=np.float64)
    return np.asarray(ns.to_numpy(np.float64) * 1e-9, dtype=np.float64)


def _on(t: FloatArray, t_from: FloatArray, values: FloatArray) -> FloatArray:
    """``values`` stamped ``t_from`` interpolated at ``t`` (within ``t_from``'s span)."""
    return np.column_stack([np.interp(t, t_from, values[:, k]) for k in range(values.shape[1])])


def _inside(t: FloatArray, t_from: FloatArray) -> NDArray[np.bool_]:
    """Which of ``t`` lie within ``t_from``'s span (none when it has fewer than two times)."""
    if t_from.size < 2:
        return np.zeros(t.shape, np.bool_)
    return np.asarray((t >= t_from[0]) & (t <= t_from[-1]), dtype=np.bool_)


def _metadata(rec: _Recording) -> dict[str, str]:
    """Metadata.csv's one row by lower-case column name (extra and missing columns tolerated)."""
    if not rec.has(METADATA):
        return {}
    frame = rec.table(METADATA)
    if frame.empty:
        return {}
    return {k: str(v).strip() for k, v in frame.iloc[0].items() if pd.notna(v)}


def _setting_stated(meta: dict[str, str]) -> tuple[bool, str] | None:
    """(the setting is on, the column) where a Metadata column names it with a true/false value."""
    for key, value in meta.items():
        if re.search(r"standardi[sz]", key):
            word = value.strip().lower()
            if word in ("true", "1", "yes", "on"):
                return True, key
            if word in ("false", "0", "no", "off"):
                return False, key
    return None


def _uncalibrated_unit(rec: _Recording) -> tuple[str, float] | None:
    """("g" or "m/s2", the median |a|) of AccelerometerUncalibrated.csv, where its magnitude tells."""
    if not rec.has(UNCALIBRATED):
        return None
    _, values, _ = _vectors(rec, UNCALIBRATED)
    if values.shape[0] == 0:
        return None
    size = float(np.median(np.linalg.norm(values, axis=1)))
    if _G_RANGE[0] <= size <= _G_RANGE[1]:
        return "g", size
    if _MPS2_RANGE[0] <= size <= _MPS2_RANGE[1]:
        return "m/s2", size
    return None


def sign_of(rec: _Recording, meta: dict[str, str], total: bool) -> Convention:
    """How the acceleration's sign is known (module docstring); ``total``: TotalAcceleration.csv is read."""
    platform = meta.get("platform", "").lower()
    where = rec.where(METADATA)
    if total or platform == "android":
        by = f"{where}: platform Android" if platform == "android" else "TotalAcceleration.csv (Android logs it only)"
        return Convention(SIGN, AS_LOGGED, "stated" if platform == "android" else "inferred", by)
    said = f"platform {meta['platform']}" if "platform" in meta else "no platform named"
    stated = _setting_stated(meta)
    if stated is not None:
        on, column = stated
        return Convention(SIGN, AS_LOGGED if on else NEGATED, "stated", f"{where}: {said}, column {column!r}")
    unit = _uncalibrated_unit(rec)
    if unit is not None:
        on = unit[0] == "m/s2"
        return Convention(
            SIGN,
            AS_LOGGED if on else NEGATED,
            "inferred",
            f"{rec.where(UNCALIBRATED)}: its median |a| {unit[1]:.3g} is in {unit[0]}, so {SETTING!r} was "
            f"{'on' if on else 'off'} ({said})",
        )
    return Convention(
        SIGN,
        NEGATED,
        "default",
        f"the app's default ({SETTING!r} off; {said}; no AccelerometerUncalibrated.csv to tell)",
    )


def read_recording(path: Path) -> Samples:
    """The samples of a Sensor Logger recording folder or zip (module docstring).

    Raises
    ------
    InputError
        A zip or folder that is no Sensor Logger recording (saying what it holds), a file without
        Sensor Logger's columns, or a recording without an acceleration with gravity.
    """
    rec = _Recording(path)
    try:
        return _read(rec)
    finally:
        rec.close()


def _read(rec: _Recording) -> Samples:
    if not rec.has(METADATA) or not (rec.has(TOTAL) or (rec.has(LINEAR) and rec.has(GRAVITY))):
        held = rec.members
        shown = ", ".join(held[:12]) + (" …" if len(held) > 12 else "") or "nothing"
        raise InputError(
            str(rec.path),
            WHAT,
            f"{'a zip' if rec.path.is_file() else 'a folder'} holding {shown}",
            "Give the recording Sensor Logger exported (its zip, or the folder it unzips to), with the "
            "accelerometer and gravity recorded.",
        )
    meta = _metadata(rec)
    dropped: dict[str, int] = {}
    notes = []
    total = rec.has(TOTAL)
    if total:
        t, acc, bad = _vectors(rec, TOTAL)
        source = "TotalAcceleration.csv"
    else:
        t, acc, bad = _vectors(rec, LINEAR)
        t_g, gravity, bad_g = _vectors(rec, GRAVITY)
        keep = _inside(t, t_g)
        if (~keep).sum():
            dropped["accelerometer rows outside Gravity.csv's span"] = int((~keep).sum())
        t, acc = t[keep], acc[keep] + _on(t[keep], t_g, gravity)
        bad += bad_g
        source = "Accelerometer.csv + Gravity.csv (gravity interpolated on the accelerometer's times)"
    if bad:
        dropped["non-finite or unstamped acceleration rows"] = bad
    sign = sign_of(rec, meta, total)
    if sign.value == NEGATED:
        acc = -acc
    gyro = None
    if rec.has(GYRO):
        t_w, rate, _ = _vectors(rec, GYRO)
        keep = _inside(t, t_w)
        if keep.any():
            if (~keep).sum():
                dropped["acceleration rows outside Gyroscope.csv's span"] = int((~keep).sum())
            t, acc, gyro = t[keep], acc[keep], _on(t[keep], t_w, rate)
        else:
            notes.append("Gyroscope.csv does not overlap the acceleration: read without a gyro")
    channels, said = _location(rec)
    platform = meta.get("platform", "an unnamed platform")
    notes.insert(
        0,
        f"read as a Sensor Logger recording ({platform}): {source}"
        + (", Gyroscope.csv (interpolated)" if gyro is not None else "")
        + (", Location.csv" if channels else "")
        + f"; time in ns since 1970 (UTC); acceleration {sign.value}",
    )
    return Samples(
        t,
        np.ascontiguousarray(acc, dtype=np.float64),
        gyro,
        channels,
        source=str(rec.path),
        dropped=dropped,
        notes=(*notes, *said),
        conventions=(sign,),
    )


def _location(rec: _Recording) -> tuple[dict[str, Channel], list[str]]:
    """Location.csv's channels, negative speeds and bearings left out (invalid) and counted."""
    if not rec.has(LOCATION):
        return {}, []
    frame = rec.table(LOCATION)
    if "time" not in frame.columns:
        return {}, [f"{rec.where(LOCATION)} has no column time: not read"]
    t = _seconds(frame["time"])
    channels: dict[str, Channel] = {}
    notes = []
    for column, key, signed in (
        ("speed", "speed_mps", True),
        ("bearing", "heading_deg", True),
        ("latitude", "lat_deg", False),
        ("longitude", "lon_deg", False),
        ("altitude", "alt_m", False),
    ):
        if column not in frame.columns:
            continue
        value = pd.to_numeric(frame[column], errors="coerce").to_numpy(np.float64)
        ok = np.isfinite(t) & np.isfinite(value)
        invalid = ok & (value < 0) if signed else np.zeros(ok.shape, np.bool_)
        if invalid.any():
            notes.append(
                f"Location.csv: {int(invalid.sum())} of {int(ok.sum())} rows with a negative {column} (invalid) "
                f"left out of {key}"
            )
        ok &= ~invalid
        order = np.argsort(t[ok], kind="stable")
        if ok.any():
            channels[key] = Channel(t[ok][order], value[ok][order])
    return channels, notes


def other_sign(samples: Samples, why: str) -> Samples | None:
    """``samples`` with the acceleration's other sign, where it was only the app's default (else None):
    what a handedness check that found the default mirrored (``why``) infers."""
    turned = turned_sign(samples.conventions, why)
    if turned is None:
        return None
    conventions, note = turned
    return replace(samples, acc_s=-samples.acc_s, conventions=conventions, notes=(*samples.notes, note))


def turned_sign(conventions: Sequence[Convention], why: str) -> tuple[tuple[Convention, ...], str] | None:
    """The conventions with the acceleration's other sign, inferred, and the note saying so, where the sign was only
    the app's default (else None): what a handedness check that found the default mirrored (``why``) infers, for a
    recording's samples (:func:`other_sign`) and for a stop table made from one (its column ``acceleration_sign``)."""
    sign = acceleration_sign(conventions)
    if sign is None or sign.how != "default":
        return None
    value = AS_LOGGED if sign.value == NEGATED else NEGATED
    by = f"the handedness checks, which found the app's default ({sign.value}) mirrored: {why}"
    if value == AS_LOGGED:
        by += f" — {SETTING!r} was on"
    turned = Convention(SIGN, value, "inferred", by)
    note = f"acceleration_sign: {value}, inferred by the handedness checks (the app's default was mirrored)"
    return tuple(turned if c.name == SIGN else c for c in conventions), note


def sign_hint(conventions: Sequence[Convention]) -> str:
    """What to say about the sign in a refusal of mirrored data from a Sensor Logger recording, its samples' or its
    stop table's conventions ("" otherwise)."""
    sign = acceleration_sign(conventions)
    if sign is None:
        return ""
    return (
        f" A Sensor Logger recording: the acceleration was read {sign.value} ({sign.how}: {sign.by}); an iOS "
        f"recording made with {SETTING!r} on or off, where the other was taken, mirrors the data this way."
    )


def sign_column(conventions: Sequence[Convention]) -> str | None:
    """A stop table's column ``acceleration_sign``: the sign its means were read with and how it is known
    (``<value>; <how>: <by>``), or None where the input states no sign."""
    sign = acceleration_sign(conventions)
    return None if sign is None else f"{sign.value}; {sign.how}: {sign.by}"


def column_sign(values: Sequence[object], where: str, column: str = SIGN) -> Convention:
    """The sign a stop table's column ``acceleration_sign`` states (:func:`sign_column`'s text, one in every row;
    a value alone, ``as logged`` or ``negated``, is stated by the column), as the convention it was written from."""
    texts = sorted({str(v).strip() for v in values})
    said, _, known = (texts[0] if len(texts) == 1 else "").partition("; ")
    value = next((v for v in (AS_LOGGED, NEGATED) if said.lower() in (v.lower(), v.split(" (")[0])), "")
    said_how, _, by = known.partition(": ")
    how = next((h for h in _HOWS if h == (said_how or "stated")), None)
    if not value or how is None:
        raise InputError(
            where,
            f"one sign in the column {column}: '{AS_LOGGED.split(' (')[0]}' or '{NEGATED.split(' (')[0]}', as "
            "`mountcal stops` writes it ('<sign>; <stated|inferred|default>: <by what>')",
            ", ".join(map(repr, texts)) or "no value",
            "Give every row the sign the stops were read with, or drop the column.",
        )
    column_said = f"{where}: column {column}"
    return Convention(SIGN, value, how, f"{by} ({column_said})" if by else column_said)


def sign_for_calibration(samples: Samples, made_with: Sequence[Convention]) -> tuple[bool, str]:
    """Whether to turn the acceleration of ``samples`` round before applying a calibration made with the
    conventions ``made_with`` (``mountcal rotate``), and what to say. A sign the reading only assumed (the app's
    default) gives way to the one the calibration stated or inferred; a default nothing confirmed is said.

    Raises
    ------
    InputError
        The reading and the calibration state or infer different signs.
    """
    read = acceleration_sign(samples.conventions)
    if read is None:
        return False, ""
    made = acceleration_sign(made_with)
    if made is not None and made.value != read.value:
        if read.how == "default":
            return True, f"acceleration {made.value}, as the calibration found it ({made.how} by {made.by})"
        raise InputError(
            samples.source or "log",
            f"the acceleration's sign the calibration was made with: {made.value} ({made.how} by {made.by})",
            f"{read.value} ({read.how} by {read.by})",
            "Apply a calibration made from this recording (calibrate it), or one made with the same app setting.",
        )
    if read.how == "default" and (made is None or made.how == "default"):
        return False, (
            f"acceleration {read.value}: the app's default, which nothing confirmed ({read.by}); recorded with "
            f"{SETTING!r} on, the vehicle-frame data are a mirror image: calibrate this recording with headings "
            "(--protocol) or a drive to check it"
        )
    return False, ""


def acceleration_sign(conventions: Sequence[Convention]) -> Convention | None:
    """The ``acceleration_sign`` convention among ``conventions`` (None: the input states no sign)."""
    return next((c for c in conventions if c.name == SIGN), None)


class SensorLoggerReader(LogReader):
    """Sensor Logger recordings in the registry: a folder holding Metadata.csv and the sensors' CSVs, or
    the app's zip export."""

    name = "sensor-logger"
    description = "Sensor Logger recording (its zip, or the folder with Metadata.csv)"

    def claims(self, path: Path, options: LogOptions) -> bool:
        if path.is_dir():
            return self.claims_folder(LocalFolder(path), options)
        return path.suffix.lower() == ".zip" and _is_recording_zip(path)

    def claims_folder(self, folder: Folder, options: LogOptions) -> bool:
        names = {name.lower() for name in folder.files()}
        return METADATA in names and bool(names & {TOTAL, LINEAR, GRAVITY, GYRO})

    def read(self, path: Path, options: LogOptions) -> Samples:
        return read_recording(path)


__all__ = [
    "SIGN",
    "SensorLoggerReader",
    "acceleration_sign",
    "column_sign",
    "other_sign",
    "read_recording",
    "sign_column",
    "sign_for_calibration",
    "sign_hint",
    "sign_of",
    "turned_sign",
]
