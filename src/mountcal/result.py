"""The calibration result: a versioned value, saved as JSON, refused on load when unknown.

Computing a calibration (:mod:`mountcal.calibrate`) is separate from applying it
(:mod:`mountcal.apply.rotate`). The JSON states its conventions, units and provenance.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.atomic import atomic_path
from mountcal.conventions import CONVENTIONS, FloatArray, levelled
from mountcal.errors import InputError
from mountcal.result_file import check_document, read_json

FORMAT = "mountcal.calibration"
FORMAT_VERSION = 1
VEHICLE_FRAME = "vehicle (ISO 8855: x forward, y left, z up)"
LEVELLED_FRAME = (
    "levelled (z up; x is the sensor's x axis on the horizontal: yaw not determined, so the heading is the "
    "sensor's own, not the vehicle's)"
)


STRUCTURE_P = 1e-3  # a residual structure (or a fit χ²) this improbable under the model counts as unexplained


@dataclass(frozen=True)
class Finding:
    """One residual test: what it looks for, how big the structure is, and how improbable."""

    test: str
    what: str
    size: str
    statistic: float | None  # None (with ``reason``) when the test does not exist for these data
    dof: int
    p_value: float | None
    log10_p: float | None
    reason: str | None = None

    @property
    def significant(self) -> bool:
        return self.p_value is not None and self.p_value < STRUCTURE_P

    def to_dict(self) -> dict[str, Any]:
        return {
            "test": self.test,
            "what": self.what,
            "size": self.size,
            "statistic": self.statistic,
            "dof": self.dof,
            "p_value": self.p_value,
            "log10_p": self.log10_p,
            **({"reason": self.reason} if self.reason else {}),
        }


@dataclass(frozen=True)
class Calibration:
    """A mounting calibration with its uncertainty.

    Angles in degrees, accelerations in m/s², uncertainties 1σ. ``yaw_deg`` and its σ are None
    when the data cannot determine yaw; ``yaw_reason`` then says why. ``slope_deg`` likewise.
    """

    method: str
    model: tuple[str, ...]
    rot_vs: Rotation
    roll_deg: float
    pitch_deg: float
    yaw_deg: float | None
    roll_sigma_deg: float
    pitch_sigma_deg: float
    yaw_sigma_deg: float | None
    yaw_reason: str | None
    slope_deg: float | None
    slope_sigma_deg: float | None
    rotation_sigma_deg: tuple[float | None, float | None, float | None]  # about vehicle x, y, z
    bias_mps2: FloatArray | None
    bias_sigma_mps2: FloatArray | None
    gravity_mps2: float
    gravity_source: str
    residual_rms_mps2: float
    residual_s: FloatArray  # shape (n, 3), per-stop residual, m/s², sensor frame
    fit: dict[str, Any]
    observability: dict[str, Any]
    model_selection: dict[str, Any]
    provenance: dict[str, Any]
    notes: tuple[str, ...] = field(default=())
    model_steps: list[dict[str, Any]] = field(default_factory=list)  # the before/after table of the loop
    unexplained: list[dict[str, Any]] = field(default_factory=list)  # structure the model leaves
    diagnostics: list[dict[str, Any]] = field(default_factory=list)  # every residual test of the final model
    effects: dict[str, Any] = field(default_factory=dict)  # fitted effect values ± σ
    confident: bool = True  # False when the residual shows structure the model does not explain

    def __post_init__(self) -> None:
        if self.yaw_deg is None:  # a yaw nobody determined is never kept, whoever built the value
            object.__setattr__(self, "rot_vs", levelled(self.rot_vs))

    @property
    def yaw_determined(self) -> bool:
        return self.yaw_deg is not None

    @property
    def frame(self) -> str:
        """The frame ``rot_vs`` maps into: the vehicle's, or (yaw not determined) the levelled one."""
        return VEHICLE_FRAME if self.yaw_determined else LEVELLED_FRAME

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (plain types)."""
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "conventions": CONVENTIONS,
            "provenance": self.provenance,
            "method": self.method,
            "model": list(self.model),
            "mounting": {"roll_deg": self.roll_deg, "pitch_deg": self.pitch_deg, "yaw_deg": self.yaw_deg},
            "uncertainty": {
                "level": "1 sigma",
                "roll_deg": self.roll_sigma_deg,
                "pitch_deg": self.pitch_sigma_deg,
                "yaw_deg": self.yaw_sigma_deg,
                "slope_deg": self.slope_sigma_deg,
                "bias_mps2": _list(self.bias_sigma_mps2),
                "rotation_about_vehicle_xyz_deg": list(self.rotation_sigma_deg),
            },
            "yaw": {"determined": self.yaw_determined, "reason": self.yaw_reason},
            "rotation": {
                "quaternion_xyzw": self.rot_vs.as_quat().tolist(),
                "matrix_vs": self.rot_vs.as_matrix().tolist(),
                "yaw": "vehicle" if self.yaw_determined else "sensor's own",
                "frame": self.frame,
            },
            "slope_deg": self.slope_deg,
            "bias_mps2": _list(self.bias_mps2),
            "gravity": {"value_mps2": self.gravity_mps2, "source": self.gravity_source},
            "residual_rms_mps2": self.residual_rms_mps2,
            "fit": self.fit,
            "observability": self.observability,
            "model_selection": self.model_selection,
            "stops": {
                "n": int(self.residual_s.shape[0]),
                "residual_s_mps2": [[float(v) if np.isfinite(v) else None for v in row] for row in self.residual_s],
            },
            "effects": self.effects,
            "model_steps": self.model_steps,
            "unexplained": self.unexplained,
            "confident": self.confident,
            "diagnostics": self.diagnostics,
            "notes": list(self.notes),
        }

    def save(self, path: str | Path) -> None:
        """Write the JSON file atomically."""
        text = json.dumps(self.to_dict(), indent=2, allow_nan=False)
        with atomic_path(path) as tmp:
            tmp.write_text(text + "\n", encoding="utf-8")

    @classmethod
    def from_dict(cls, doc: dict[str, Any], where: str = "<dict>") -> Calibration:
        """Rebuild a calibration from its JSON document; unknown formats or versions are refused."""
        if doc.get("format") != FORMAT:
            raise InputError(
                where,
                f"a {FORMAT} JSON document",
                f"format {doc.get('format')!r}",
                "Pass a file written by `mountcal calibrate`.",
            )
        if doc.get("format_version") != FORMAT_VERSION:
            raise InputError(
                where,
                f"format_version {FORMAT_VERSION}",
                f"format_version {doc.get('format_version')!r}",
                "Re-run `mountcal calibrate` with this version of mountcal, or upgrade mountcal.",
            )
        check_document(doc, where)  # types, finiteness, ranges, shapes, rotation against angles
        try:
            unc, mount = doc["uncertainty"], doc["mounting"]
            if doc["yaw"].get("determined") is False:  # never trust a number the document itself disowns
                mount, unc = {**mount, "yaw_deg": None}, {**unc, "yaw_deg": None}
            return cls(
                method=doc["method"],
                model=tuple(doc["model"]),
                rot_vs=Rotation.from_quat(doc["rotation"]["quaternion_xyzw"]),
                roll_deg=mount["roll_deg"],
                pitch_deg=mount["pitch_deg"],
                yaw_deg=mount["yaw_deg"],
                roll_sigma_deg=unc["roll_deg"],
                pitch_sigma_deg=unc["pitch_deg"],
                yaw_sigma_deg=unc["yaw_deg"],
                yaw_reason=doc["yaw"]["reason"],
                slope_deg=doc["slope_deg"],
                slope_sigma_deg=unc["slope_deg"],
                rotation_sigma_deg=tuple(unc["rotation_about_vehicle_xyz_deg"]),
                bias_mps2=_array(doc["bias_mps2"]),
                bias_sigma_mps2=_array(unc["bias_mps2"]),
                gravity_mps2=doc["gravity"]["value_mps2"],
                gravity_source=doc["gravity"]["source"],
                residual_rms_mps2=doc["residual_rms_mps2"],
                residual_s=np.array(
                    [[np.nan if v is None else v for v in row] for row in doc["stops"]["residual_s_mps2"]], dtype=float
                ).reshape(-1, 3),
                fit=doc["fit"],
                observability=doc["observability"],
                model_selection=doc["model_selection"],
                provenance=doc["provenance"],
                notes=tuple(doc.get("notes", ())),
                model_steps=list(doc.get("model_steps", [])),
                unexplained=list(doc.get("unexplained", [])),
                diagnostics=list(doc.get("diagnostics", [])),
                effects=dict(doc.get("effects", {})),
                confident=bool(doc.get("confident", True)),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise InputError(
                where,
                "a complete calibration document",
                f"a missing or malformed field ({err})",
                "Re-create it with `mountcal calibrate`.",
            ) from err

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a calibration JSON file."""
        path = Path(path)
        doc = read_json(path)  # a regular file, size- and depth-bounded, no NaN literals
        if not isinstance(doc, dict):
            raise InputError(
                str(path), "a JSON object", type(doc).__name__, "Pass a file written by `mountcal calibrate`."
            )
        return cls.from_dict(doc, where=str(path))


def _list(a: FloatArray | None) -> list[float] | None:
    return None if a is None else [float(x) for x in a]


def _array(a: list[float] | None) -> FloatArray | None:
    return None if a is None else np.asarray(a, dtype=float)
