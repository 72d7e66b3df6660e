"""What every exporter shares: the rotation to export, the refusals, σ propagation, number text.

The result stores the σ of small rotations about the vehicle x, y, z axes (``rot_vs`` perturbed
as ``exp([δ]×) · rot_vs``, δ in the vehicle frame), not a full covariance: the exporters take
that covariance as diagonal and propagate it to each vendor's parameters to first order through
a numeric Jacobian.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, rot_vs_from_angles
from mountcal.core.errors import NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.core.result import Calibration

YawPolicy = Literal["refuse", "zero"]
JACOBIAN_STEP_RAD = 1e-7  # central differences: error ~ step² (1e-14), rounding ~ 1e-16/step (1e-9)


@dataclass(frozen=True)
class Mounting:
    """The rotation an exporter writes, with its σ and what was assumed to get it."""

    rot_vs: Rotation
    sigma_rad: tuple[float | None, float | None, float | None]  # small rotations about vehicle x, y, z
    yaw_assumed_zero: bool
    notes: tuple[str, ...]

    @property
    def header(self) -> list[str]:
        """Lines every text format states first (as comments)."""
        lines = ["written by `mountcal export`; sensor frame = the IMU axes mountcal was calibrated on"]
        if self.yaw_assumed_zero:
            lines.append("YAW NOT DETERMINED by the calibration: yaw set to 0 on request (yaw policy: zero)")
        return lines + list(self.notes)


def mounting(cal: Calibration, yaw: YawPolicy = "refuse", accept_unconfident: bool = False) -> Mounting:
    """The rotation to export, or a refusal when yaw is not determined or the result not confident.

    The decision is taken on the result's yaw (None when not determined), never on its rotation
    matrix, which may hold a placeholder yaw.
    """
    notes: list[str] = []
    if not cal.confident:
        if not accept_unconfident:
            raise NotEnoughInformation(
                "the calibration is not confident: its residual shows structure the model does not explain "
                "(see `unexplained` in the result). Re-run the calibration, or export it anyway "
                f"({option('accept_unconfident', True)})."
            )
        notes.append("the calibration is NOT confident (unexplained residual structure); exported on request")
    sx, sy = _radians(cal.rotation_sigma_deg[0]), _radians(cal.rotation_sigma_deg[1])
    if cal.yaw_deg is None:
        if yaw != "zero":
            raise NotEnoughInformation(
                f"yaw is not determined by this calibration ({cal.yaw_reason or 'no reason given'}); every "
                "exported format needs all three angles. Calibrate with headings from the uphill direction "
                f"or driving data, or write yaw = 0 ({option('yaw_undetermined', 'zero')}; the tilt stays exact)."
            )
        rot = rot_vs_from_angles(np.radians(cal.roll_deg), np.radians(cal.pitch_deg), 0.0)
        return Mounting(rot, (sx, sy, None), True, tuple(notes))
    return Mounting(cal.rot_vs, (sx, sy, _radians(cal.rotation_sigma_deg[2])), False, tuple(notes))


def propagate_sigma(
    fn: Callable[[Rotation], FloatArray], mount: Mounting, periodic: FloatArray | None = None
) -> list[float | None]:
    """1σ of each output of ``fn`` (parameters of a rotation), to first order.

    ``periodic`` gives, per output, the period of an angle (its differences are wrapped) or 0.
    An output that depends on a rotation whose σ is unknown (an undetermined yaw) gets None.
    """
    base = np.asarray(fn(mount.rot_vs), dtype=float)
    period = np.zeros(base.size) if periodic is None else np.asarray(periodic, dtype=float)
    jac = np.empty((base.size, 3))
    for k in range(3):
        step = np.zeros(3)
        step[k] = JACOBIAN_STEP_RAD
        plus = np.asarray(fn(Rotation.from_rotvec(step) * mount.rot_vs), dtype=float)
        minus = np.asarray(fn(Rotation.from_rotvec(-step) * mount.rot_vs), dtype=float)
        diff = plus - minus
        wrap = period > 0
        diff[wrap] = (diff[wrap] + period[wrap] / 2) % period[wrap] - period[wrap] / 2
        jac[:, k] = diff / (2 * JACOBIAN_STEP_RAD)
    out: list[float | None] = []
    for row in jac:
        var = 0.0
        known = True
        for k in range(3):
            s = mount.sigma_rad[k]
            if s is None:
                known = known and abs(row[k]) < 1e-6  # this output does not depend on the unknown axis
            else:
                var += (row[k] * s) ** 2
        out.append(float(np.sqrt(var)) if known else None)
    return out


def number(value: float, decimals: int = 9) -> str:
    """A number as fixed-point text, trailing zeros dropped (no exponent, no ``-0``).

    Nine decimals of a degree (≤ 1e-11 rad) or of a quaternion keep round trips far below 1e-9.
    """
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "", "-") else text


def _radians(deg: float | None) -> float | None:
    return None if deg is None else float(np.radians(deg))
