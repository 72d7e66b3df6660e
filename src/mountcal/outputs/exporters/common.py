"""What every exporter shares: its declaration, the rotation to export, the refusals, σ propagation, number text.

An exporter is one module of this package (or of another package, through the entry-point group
``mountcal.exporters``: :mod:`mountcal.outputs.exporters`) holding ``EXPORTERS``, a tuple of
:class:`Exporter`: the ``--to`` name, the suffixes ``-o`` may end in, one line saying what it writes,
and the function writing it from a :class:`~mountcal.core.result.Calibration`. The registry imports
every module of this package to list the formats (``mountcal export --help``), so a module here
imports no numerical library at its top: numpy, scipy and the conventions are imported in the
functions that use them.

The result stores the σ of small rotations about the vehicle x, y, z axes (``rot_vs`` perturbed
as ``exp([δ]×) · rot_vs``, δ in the vehicle frame), not a full covariance: the exporters take
that covariance as diagonal and propagate it to each vendor's parameters to first order through
a numeric Jacobian.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from mountcal.core.errors import NotEnoughInformation
from mountcal.core.option_names import option

if TYPE_CHECKING:
    from collections.abc import Sequence

    from scipy.spatial.transform import Rotation

    from mountcal.core.conventions import FloatArray
    from mountcal.core.result import Calibration, Convention
    from mountcal.io.input_conventions import AxisMap

YawPolicy = Literal["refuse", "zero"]
JACOBIAN_STEP_RAD = 1e-7  # central differences: error ~ step² (1e-14), rounding ~ 1e-16/step (1e-9)
BODY_FRAME = "base_link"  # REP 105's name for the REP 103 body frame, and Autoware's
DEFAULT_CHILD = "imu_link"  # the IMU's frame when the calibration's log named none


@dataclass(frozen=True)
class ParentPose:
    """A parent frame's orientation in the body frame (``base_link``), as a URDF joint origin gives it.

    Only its rotation matters: the IMU's position is given in the parent frame itself.
    """

    rotation: Rotation  # maps parent coordinates to base_link coordinates
    source: str  # where it was read, for the output's comments


@dataclass(frozen=True)
class Frames:
    """Frame names, the IMU's position in the parent frame (m), and the parent's pose when it is not the body frame.

    ``child`` None: the frame the calibration's data were in, as their log names it, else ``imu_link``
    (:mod:`mountcal.outputs.exporters.child`, which fills ``said``: what the output says of the child's
    name, and ``warn``: the child given is not the frame the data were in).
    """

    parent: str = BODY_FRAME
    child: str | None = None
    translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    parent_pose: ParentPose | None = None  # None: the parent is a REP 103 body frame aligned with the vehicle
    said: tuple[str, ...] = ()
    warn: bool = False
    axes: str | None = None  # the calibration's --axes map, composed into the transform for the child's axes

    @property
    def child_name(self) -> str:
        """The child frame written."""
        return self.child or DEFAULT_CHILD

    def in_parent(self, rot_vs: Rotation) -> Rotation:
        """The IMU's orientation in the parent frame (maps IMU coordinates to parent coordinates)."""
        return rot_vs if self.parent_pose is None else self.parent_pose.rotation.inv() * rot_vs


@dataclass(frozen=True)
class ExportOptions:
    """How to export: what to do with an undetermined yaw or a result not confident, and the frames.

    ``frames`` is the format's own (:attr:`Exporter.frames`) unless the user named others; it is
    None for a format that names no frames.
    """

    yaw: YawPolicy = "refuse"
    accept_unconfident: bool = False
    frames: Frames | None = None

    def mounting(self, cal: Calibration) -> Mounting:
        """The rotation to write, with the refusals every format shares (:func:`mounting`); for a child
        frame whose axes are the data's as logged, the calibration's axis map composed in (``Frames.axes``)."""
        from dataclasses import replace

        found = mounting(cal, self.yaw, self.accept_unconfident)
        if self.frames is None:  # the format names no frame: its IMU frame must be the calibrated axes
            mapped = user_axes(cal.provenance.conventions)
            said = f"sensor frame = the log's axes after the calibration's axis map {mapped.text}" if mapped else None
            return found if said is None else replace(found, notes=(*found.notes, said))
        if self.frames.axes is None:
            return found

        from scipy.spatial.transform import Rotation

        from mountcal.io.input_conventions import parse_axes

        device_to_sensor = Rotation.from_matrix(parse_axes(self.frames.axes).matrix)  # a proper map (child.py)
        return replace(found, rot_vs=found.rot_vs * device_to_sensor)  # said with the child's name (Frames.said)


Writer = Callable[["Calibration", ExportOptions], "str | bytes"]


@dataclass(frozen=True)
class Exporter:
    """One ``--to`` format: what a module of exporters declares (in its ``EXPORTERS`` tuple).

    Attributes
    ----------
    name : str
        The ``--to`` name (``"novatel"``).
    suffixes : tuple of str
        The suffixes ``-o`` may end in (lower case, with the dot; its own first, ``.txt`` for any text
        format). A name ending in another data format's suffix is refused; empty: any name.
    description : str
        One line: the system and what it is given (``--help`` and docs/exporters.md).
    write : callable
        ``write(calibration, options) -> str | bytes``: the text (bytes for a binary format).
        ``options.mounting(calibration)`` gives the rotation with the shared refusals.
    frames : Frames, optional
        For a format that names frames (ROS, Autoware): its default parent, child and translation,
        which ``--parent``, ``--child``, ``--translation`` and ``--parent-pose`` change. None: the
        format names no frames, and giving them is refused.
    """

    name: str
    suffixes: tuple[str, ...]
    description: str
    write: Writer
    frames: Frames | None = None


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
    """The rotation to export, or a refusal when yaw is not determined, the result not confident, or
    it was made of samples mountcal had already rotated (:func:`mountcal.io.frame.refuse_leftover`).

    The decision is taken on the result's yaw (None when not determined), never on its rotation
    matrix, which may hold a placeholder yaw.
    """
    import numpy as np

    from mountcal.core.conventions import rot_vs_from_angles
    from mountcal.io.frame import refuse_leftover

    where = f"calibration of {cal.provenance.input or 'unknown input'}"
    refuse_leftover(cal.provenance.conventions, where, "export the sensor's mounting")
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


def user_axes(conventions: Sequence[Convention]) -> AxisMap | None:
    """The axis map stated for the calibration's log (``--axes``: a ROS log has no reader's map), unless identity."""
    from mountcal.io.input_conventions import axes_stated

    found = axes_stated(conventions)
    if found is None or found[0].how != "stated" or found[1].identity:
        return None
    return found[1]


def propagate_sigma(
    fn: Callable[[Rotation], FloatArray], mount: Mounting, periodic: FloatArray | None = None
) -> list[float | None]:
    """1σ of each output of ``fn`` (parameters of a rotation), to first order.

    ``periodic`` gives, per output, the period of an angle (its differences are wrapped) or 0.
    An output that depends on a rotation whose σ is unknown (an undetermined yaw) gets None.
    """
    import numpy as np
    from scipy.spatial.transform import Rotation

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
    return None if deg is None else math.radians(deg)
