"""Apply a calibration: sensor-frame data into the vehicle frame and back (MODEL.md §1).

``acc_v = R_vs · (acc_s − b)`` removes the fitted bias (when the calibration carries one) and
rotates; ``acc_s = R_vsᵀ · acc_v + b`` undoes it. Angular rates are only rotated.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from mountcal.conventions import G_N, FloatArray
from mountcal.errors import InputError
from mountcal.result import Calibration

ACC_COLUMNS = ("ax", "ay", "az")


def acc_to_vehicle(acc_s: FloatArray, cal: Calibration, check_units: bool = True) -> FloatArray:
    """Specific force from the sensor to the vehicle frame, bias removed.

    Parameters
    ----------
    acc_s : ndarray, shape (n, 3)
        m/s², sensor frame.
    cal : Calibration
    check_units : bool
        Refuse data whose typical magnitude is ~1 (g units) instead of ~9.8 (m/s²).

    Returns
    -------
    ndarray, shape (n, 3)
        m/s², vehicle frame.
    """
    acc = _as_vectors(acc_s, "acc_s")
    if check_units:
        _check_mps2(acc)
    if cal.bias_mps2 is not None:
        acc = acc - cal.bias_mps2
    return _rotated(acc, cal.rot_vs.as_matrix())


def acc_to_sensor(acc_v: FloatArray, cal: Calibration) -> FloatArray:
    """The inverse of :func:`acc_to_vehicle`: vehicle-frame specific force as the sensor reads it."""
    acc = _rotated(_as_vectors(acc_v, "acc_v"), cal.rot_vs.as_matrix().T)
    return acc + cal.bias_mps2 if cal.bias_mps2 is not None else acc


def rate_to_vehicle(gyro_s: FloatArray, cal: Calibration) -> FloatArray:
    """Angular rate (any unit) from the sensor to the vehicle frame: rotation only."""
    return _rotated(_as_vectors(gyro_s, "gyro_s"), cal.rot_vs.as_matrix())


def rate_to_sensor(gyro_v: FloatArray, cal: Calibration) -> FloatArray:
    """Angular rate from the vehicle back to the sensor frame."""
    return _rotated(_as_vectors(gyro_v, "gyro_v"), cal.rot_vs.as_matrix().T)


def frame_to_vehicle(
    df: pd.DataFrame,
    cal: Calibration,
    acc_columns: Sequence[str] = ACC_COLUMNS,
    gyro_columns: Sequence[str] | None = None,
) -> pd.DataFrame:
    """A copy of ``df`` with its accelerometer (m/s²) and gyro columns in the vehicle frame.

    Other columns are kept as they are; ``attrs["frame"]`` records the frame.
    """
    out = df.copy()
    out[list(acc_columns)] = acc_to_vehicle(_columns(df, acc_columns), cal)
    if gyro_columns is not None:
        out[list(gyro_columns)] = rate_to_vehicle(_columns(df, gyro_columns), cal)
    out.attrs["frame"] = "vehicle"
    return out


def frame_to_sensor(
    df: pd.DataFrame,
    cal: Calibration,
    acc_columns: Sequence[str] = ACC_COLUMNS,
    gyro_columns: Sequence[str] | None = None,
) -> pd.DataFrame:
    """The inverse of :func:`frame_to_vehicle`."""
    out = df.copy()
    out[list(acc_columns)] = acc_to_sensor(_columns(df, acc_columns), cal)
    if gyro_columns is not None:
        out[list(gyro_columns)] = rate_to_sensor(_columns(df, gyro_columns), cal)
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
    return df[list(cols)].to_numpy(dtype=float, copy=True)


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
