"""Apply a calibration: sensor-frame data into the vehicle frame and back (docs/conventions.md §1).

``acc_v = R_vs · (I + E)⁻¹ (acc_s − b)`` removes the fitted sensor effects (those the calibration
carries: :func:`mountcal.estimate.effects.apply_corrections`) and rotates; ``acc_to_sensor`` undoes
it. Angular rates are only rotated.

Samples already in the vehicle (or levelled) frame are refused (:func:`refuse_rotated`): the mounting would
be applied twice. The readers know it from the file's own metadata (``Samples.rotated``), a DataFrame from
``attrs["frame"]`` (:func:`frame_to_vehicle` sets it).

A calibration without a determined yaw is refused (its rotation only levels: the heading would be
the sensor's own), unless the caller asks for exactly that with ``level_only=True``
(``--level-only``); :func:`check_applicable` is the one place that decides, and also says when a
result is not confident (refused with ``require_confident=True``).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd

from mountcal.core.conventions import G_N, FloatArray
from mountcal.core.errors import InputError, refuse_not_confident
from mountcal.core.option_names import option
from mountcal.core.result import Calibration
from mountcal.estimate.effects import apply_corrections
from mountcal.io.frame import FRAME_NAMES, Rotated, refuse_leftover, rotated_of
from mountcal.io.frame import refuse_rotated as refused
from mountcal.io.samples import Samples

ACC_COLUMNS = ("ax", "ay", "az")


def refuse_rotated(rotated: Rotated | None, where: str) -> None:
    """Refuse samples mountcal already rotated: a second rotation would apply the mounting twice, and
    nothing in the result could show it (:func:`mountcal.io.frame.refuse_rotated`)."""
    refused(rotated, where, "rotating again would apply the mounting twice", "Rotate the original log.")


def refuse_gravity_free(samples: Samples) -> None:
    """Refuse an acceleration marked gravity-free where it was read: the output would call it specific force."""
    if samples.gravity_free:
        raise InputError(
            samples.source,
            "the specific force (an accelerometer's reading, gravity included), written as the vehicle frame's",
            f"an acceleration without gravity: {samples.gravity_free}",
            "Rotate the raw accelerometer (with g); mountcal writes no gravity-free acceleration as specific force.",
        )


def yaw_sources() -> str:
    """Where a determined yaw comes from, naming the options that give it."""
    return (
        f"calibrate with {option('protocol')} (a protocol sheet: headings from the slope's uphill direction), "
        f"with {option('uphill_azimuth')} and a heading signal in the log, or from a log with driving and a "
        "vehicle speed channel"
    )


def check_applicable(
    cal: Calibration, *, level_only: bool = False, require_confident: bool = False, where: str | None = None
) -> list[str]:
    """Refuse a calibration that must not be applied as asked; the warnings for one applied with care.

    Raises
    ------
    InputError
        Yaw is not determined and ``level_only`` is False (the rotation would only level); the
        result is not confident and ``require_confident`` is True; the calibration was made of samples
        mountcal had already rotated (its angles are what that rotation left over).
    """
    where = where or f"calibration of {cal.provenance.input or 'unknown input'}"
    refuse_leftover(cal.provenance.conventions, where, "rotate samples into the vehicle frame")
    if not cal.yaw_determined and not level_only:
        raise InputError(
            where,
            "a calibration with a determined yaw, to rotate into the vehicle frame",
            f"yaw not determined ({cal.yaw_reason or 'no reason recorded'})",
            f"Determine yaw: {yaw_sources()}. Or, to level only (z up, the heading left the sensor's own), "
            f"pass {option('level_only', True)}.",
        )
    found: list[str] = []
    if not cal.confident:
        why = "; ".join(u.what for u in cal.unexplained) or "see the result's notes"
        if require_confident:
            refuse_not_confident(
                where,
                f"a result that is not confident ({why})",
                "Check the result's notes and unexplained structure, re-calibrate",
            )
        found.append(
            f"the calibration is not confident ({why}); its σ are qualified and the rotation may be wrong "
            f"(roll ± {cal.roll_sigma_deg:.2g}°, pitch ± {cal.pitch_sigma_deg:.2g}°)"
        )
    if level_only and not cal.yaw_determined:
        found.append(f"levelled only: yaw not determined ({cal.yaw_reason}); the heading is the sensor's own")
    return found


def _matrix(cal: Calibration, level_only: bool) -> FloatArray:
    if (not cal.yaw_determined and not level_only) or rotated_of(cal.provenance.conventions) is not None:
        check_applicable(cal)  # raises with the reason (and what would determine yaw)
    return np.asarray(cal.rot_vs.as_matrix(), dtype=float)


def acc_to_vehicle(
    acc_s: FloatArray, cal: Calibration, check_units: bool = True, *, level_only: bool = False
) -> FloatArray:
    """Specific force from the sensor to the vehicle frame, bias removed.

    Parameters
    ----------
    acc_s : ndarray, shape (n, 3)
        m/s², sensor frame.
    cal : Calibration
    check_units : bool
        Refuse data whose typical magnitude is ~1 (g units) instead of ~9.8 (m/s²).
    level_only : bool
        Accept a calibration without a determined yaw (the result is then levelled, not in the
        vehicle frame); refused otherwise.

    Returns
    -------
    ndarray, shape (n, 3)
        m/s², vehicle frame.
    """
    acc = _as_vectors(acc_s, "acc_s")
    if check_units:
        _check_mps2(acc)
    matrix = _matrix(cal, level_only)
    acc = apply_corrections(acc, cal)
    return _rotated(acc, matrix)


def acc_to_sensor(acc_v: FloatArray, cal: Calibration, *, level_only: bool = False) -> FloatArray:
    """The inverse of :func:`acc_to_vehicle`: vehicle-frame specific force as the sensor reads it."""
    acc = _rotated(_as_vectors(acc_v, "acc_v"), _matrix(cal, level_only).T)
    return apply_corrections(acc, cal, inverse=True)


def rate_to_vehicle(gyro_s: FloatArray, cal: Calibration, *, level_only: bool = False) -> FloatArray:
    """Angular rate (any unit) from the sensor to the vehicle frame: rotation only."""
    return _rotated(_as_vectors(gyro_s, "gyro_s"), _matrix(cal, level_only))


def rate_to_sensor(gyro_v: FloatArray, cal: Calibration, *, level_only: bool = False) -> FloatArray:
    """Angular rate from the vehicle back to the sensor frame."""
    return _rotated(_as_vectors(gyro_v, "gyro_v"), _matrix(cal, level_only).T)


def frame_to_vehicle(
    df: pd.DataFrame,
    cal: Calibration,
    acc_columns: Sequence[str] = ACC_COLUMNS,
    gyro_columns: Sequence[str] | None = None,
    *,
    level_only: bool = False,
    require_confident: bool = False,
) -> pd.DataFrame:
    """A copy of ``df`` with its accelerometer (m/s²) and gyro columns in the vehicle frame.

    Other columns are kept as they are; ``attrs["frame"]`` records the frame (``"levelled"`` with
    ``level_only`` and no determined yaw), ``attrs["confident"]`` the calibration's verdict and
    ``attrs["warnings"]`` what :func:`check_applicable` found (also issued as a ``UserWarning``).
    """
    frame = df.attrs.get("frame")
    if frame in FRAME_NAMES:  # what frame_to_vehicle sets: the frames mountcal writes
        refuse_rotated(Rotated(str(frame), "", 'its attrs["frame"]'), "DataFrame")
    found = check_applicable(cal, level_only=level_only, require_confident=require_confident)
    for text in found:
        warnings.warn(text, UserWarning, stacklevel=2)
    out = df.copy()
    out[list(acc_columns)] = acc_to_vehicle(_columns(df, acc_columns), cal, level_only=level_only)
    if gyro_columns is not None:
        _check_turns(df, cal, acc_columns, gyro_columns)
        out[list(gyro_columns)] = rate_to_vehicle(_columns(df, gyro_columns), cal, level_only=level_only)
    out.attrs.update(
        frame="vehicle" if cal.yaw_determined else "levelled", confident=cal.confident, warnings=list(found)
    )
    return out


def _check_turns(df: pd.DataFrame, cal: Calibration, acc_columns: Sequence[str], gyro_columns: Sequence[str]) -> None:
    """What ``rotate`` checks of a log's turns against a calibration made elsewhere (:class:`TurnWatch`: a gyro
    axis reversed, a calibration half a turn off), where the frame holds the times and a speed or heading
    (:func:`~mountcal.apply.rotate_log.to_frame`'s columns)."""
    aux = [key for key in ("speed_mps", "heading_deg") if key in df.columns]
    if "t_s" not in df.columns or not aux:
        return
    from mountcal.io.samples import Channel, Samples
    from mountcal.loop.crosscheck import TurnWatch

    t = np.asarray(df["t_s"].to_numpy(dtype=float), dtype=np.float64)
    channels = {}
    for key in aux:
        value = np.asarray(df[key].to_numpy(dtype=float), dtype=np.float64)
        known = np.isfinite(value) & np.isfinite(t)
        channels[key] = Channel(t[known], value[known])
    acc, gyro = _columns(df, acc_columns), _columns(df, gyro_columns)
    rows = np.isfinite(t) & np.isfinite(acc).all(axis=1) & np.isfinite(gyro).all(axis=1)
    source = str(df.attrs.get("source") or "DataFrame")
    # the turns' sense only: this API rotates rates in any unit
    TurnWatch.of(cal, scale=False).look(Samples(t[rows], acc[rows], gyro[rows], channels=channels, source=source))


def frame_to_sensor(
    df: pd.DataFrame,
    cal: Calibration,
    acc_columns: Sequence[str] = ACC_COLUMNS,
    gyro_columns: Sequence[str] | None = None,
    *,
    level_only: bool = False,
) -> pd.DataFrame:
    """The inverse of :func:`frame_to_vehicle`."""
    out = df.copy()
    out[list(acc_columns)] = acc_to_sensor(_columns(df, acc_columns), cal, level_only=level_only)
    if gyro_columns is not None:
        out[list(gyro_columns)] = rate_to_sensor(_columns(df, gyro_columns), cal, level_only=level_only)
    out.attrs["frame"] = "sensor"
    return out


def _rotated(vectors: FloatArray, matrix: FloatArray) -> FloatArray:
    """Rows ``v`` as ``R · v``: one (n, 3) × (3, 3) product."""
    return np.asarray(vectors @ matrix.T, dtype=float)


def _as_vectors(a: FloatArray, name: str) -> FloatArray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(name, "an array of shape (n, 3)", f"shape {arr.shape}", "Pass one row per sample.")
    return arr


def _columns(df: pd.DataFrame, cols: Sequence[str]) -> FloatArray:
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise InputError(
            "DataFrame",
            f"columns {', '.join(cols)}",
            f"no {', '.join(missing)}",
            "Name the columns with acc_columns= / gyro_columns=.",
        )
    return np.asarray(df[list(cols)].to_numpy(dtype=float, copy=True), dtype=np.float64)


def _check_mps2(acc: FloatArray) -> None:
    if acc.shape[0] < 10:
        return
    typical = float(np.nanmedian(np.linalg.norm(acc, axis=1)))
    if typical < 0.3 * G_N:
        raise InputError(
            "acc_s",
            "specific force in m/s² (typically ≈ 9.8 in magnitude)",
            f"a median magnitude of {typical:.3g}",
            "Convert g to m/s² (× 9.80665) first.",
        )
