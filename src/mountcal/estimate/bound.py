"""Cramér–Rao bounds of the angles for a stop set and a model (docs/conventions.md §5)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from mountcal.core.angles import AngleValues
from mountcal.core.conventions import FloatArray, angles_from_rot_vs
from mountcal.estimate import effects, full
from mountcal.stops.table import StopTable


def euler_gradients(rot: Rotation, k: int, h: float = 1e-7) -> FloatArray:
    """∂(roll, pitch, yaw)/∂δ for a left perturbation δ about the vehicle axes; shape (3, k)."""
    grads = np.zeros((3, k))
    for j in range(k):
        d = np.zeros(3)
        d[j] = h
        up = np.array(angles_from_rot_vs(Rotation.from_rotvec(d) * rot))
        down = np.array(angles_from_rot_vs(Rotation.from_rotvec(-d) * rot))
        grads[:, j] = np.angle(np.exp(1j * (up - down))) / (2 * h)
    return grads


def crb_deg(
    table: StopTable, state: full.State, terms: tuple[str, ...], g_mps2: float, noise_scale: float = 1.0
) -> AngleValues | None:
    """1σ bounds of roll, pitch, yaw and slope (degrees) at ``state``; None when singular.

    The table's stop covariances (times ``noise_scale²``) are the noise model.
    """
    info, names = full.information(table, state, terms, g_mps2)
    if full.null_space(info).size:
        return None
    cov = np.linalg.inv(info) * noise_scale**2
    k = 3 if "rot_z" in names else 2
    grads = euler_gradients(state.rot_vs, k)
    sig = [float(np.degrees(np.sqrt(max(c @ cov[:k, :k] @ c, 0.0)))) for c in grads]
    slopes = [i for i, n in enumerate(names) if n.startswith("slope")]
    return AngleValues(
        roll_deg=sig[0],
        pitch_deg=sig[1],
        yaw_deg=sig[2] if k == 3 else None,
        slope_deg=float(np.degrees(np.sqrt(cov[slopes[0], slopes[0]]))) if len(slopes) == 1 else None,
    )


def true_state(
    rot_vs: Rotation,
    slope_deg: float,
    g_mps2: float,
    values: Mapping[str, ArrayLike | None] | None = None,
    **reported: ArrayLike | None,
) -> full.State:
    """A parameter-space point from true values (for bounds at the truth).

    Each effect's values in its parameters' order, by effect name in ``values`` or by its ``report_key``
    as a keyword (``bias_mps2=``, as a result file names it); None or absent: no such effect.
    """
    by_key = {e.report_key: name for name, e in effects.registered().items()}
    unknown = set(reported) - by_key.keys()
    if unknown:
        raise TypeError(f"true_state() got unexpected keyword arguments {sorted(unknown)}")
    given = {**(values or {}), **{by_key[k]: v for k, v in reported.items()}}
    state = {k: np.asarray(v, dtype=float) for k, v in given.items() if v is not None}
    return full.State(rot_vs, np.array([np.radians(slope_deg)]), np.zeros(0), g_mps2, state)
