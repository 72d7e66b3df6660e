"""The calibration result: a versioned value, saved as JSON, refused on load when unknown.

Computing a calibration (:mod:`mountcal.calibration.fit`) is separate from applying it
(:mod:`mountcal.apply.rotate`). The JSON states its conventions, units and provenance.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, is_dataclass, replace
from pathlib import Path
from typing import Any, Literal, get_args, get_type_hints

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.angles import ANGLE_NAMES
from mountcal.core.angles import Angles as Angles  # the result's angle types, imported from here too
from mountcal.core.angles import AngleValues as AngleValues
from mountcal.core.atomic import atomic_path
from mountcal.core.conventions import CONVENTIONS, FloatArray, levelled
from mountcal.core.driving_document import Combination, DrivingDocument
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.core.findings import Finding
from mountcal.core.option_names import option
from mountcal.core.result_file import check_document, read_json
from mountcal.core.sensor_limits import SensorLimits
from mountcal.core.typed_json import from_plain, schema_of, to_plain

FORMAT = "mountcal.calibration"
FORMAT_VERSION = 2  # 2: fit, observability, model selection, steps, effects, provenance typed (see Calibration)
VEHICLE_FRAME = "vehicle (ISO 8855: x forward, y left, z up)"
LEVELLED_FRAME = (
    "levelled (z up; x is the sensor's x axis on the horizontal: yaw not determined, so the heading is the "
    "sensor's own, not the vehicle's)"
)


@dataclass(frozen=True)
class FitQuality:
    """How well the model fits the stops, and the noise model behind the σ.

    ``chi2``/``dof``/``p_value``/``log10_p`` test the model when the stop noise is known (from the
    table); with the noise estimated from the residuals ``p_value`` is None and
    ``noise_scale_mps2`` is that estimate. The paper's method fills ``pairs``/``cos_slope``; a
    calibration that used driving says so in ``calibrated_from`` and keeps the driving fit's own
    document in ``driving`` (and, with stops, how the two were combined in ``combination``).
    """

    noise: str | None = None
    headings: Literal["uphill", "relative", "none"] | None = None
    chi2: float | None = None
    dof: int | None = None
    p_value: float | None = None
    log10_p: float | None = None
    noise_scale_mps2: float | None = None
    iterations: int | None = None
    excluded_stops: tuple[int, ...] = ()  # 1-based stop numbers left out as outliers
    birge_ratio: float = 1.0  # the σ are widened by this factor (>1 when structure is left unexplained)
    birge_note: str | None = None  # what the ratio was computed from, when not the whole χ²
    branch: str | None = None  # why the physical branch of the rotation is in doubt
    pairs: int | None = None
    cos_slope: float | None = None
    uncertainty: str | None = None  # how the σ were computed when not from the Fisher information
    calibrated_from: str | None = None
    driving: DrivingDocument | None = None
    combination: Combination | None = None
    driving_levelled_with_stops: DrivingDocument | None = None  # when the drive alone is used (they disagreed)


@dataclass(frozen=True)
class EffectValue:
    """A fitted effect: one value ± 1σ per component (``x, y, z`` of a vector, or named entries)."""

    name: str
    unit: str
    components: tuple[str, ...]
    value: tuple[float, ...]
    sigma: tuple[float | None, ...]


@dataclass(frozen=True)
class ModelStep:
    """One step of the model loop: what it added and why, its fit, angles and effects."""

    added: str
    reason: str
    terms: tuple[str, ...]
    excluded_stops: tuple[int, ...]
    gravity_mps2: float
    chi2: float
    dof: int
    residual_rms_mps2: float
    loo_rms_mps2: float | None
    angles: Angles
    moved: AngleValues | None  # None for the first step
    effects: tuple[EffectValue, ...] = ()


@dataclass(frozen=True)
class Declined:
    """An effect the loop considered and did not add, with the reason."""

    effect: str
    why: str


@dataclass(frozen=True)
class ModelSelection:
    """How the model was chosen: ``mode`` auto (the loop), fixed (by the user), or driving."""

    mode: str
    chosen: tuple[str, ...]
    alpha: float | None = None
    steps: tuple[str, ...] = ()
    declined: tuple[Declined, ...] = ()


@dataclass(frozen=True)
class Separability:
    """Whether these stops separate an effect the model does not have and, if not, which protocol would."""

    effect: str
    separable: bool
    why: str


@dataclass(frozen=True)
class Observability:
    """What the stops can determine: Fisher rank and conditioning, and the Cramér–Rao bounds per model."""

    parameters: tuple[str, ...]
    fisher_rank: int
    condition_number: float | None  # None: singular (some direction unobservable)
    crb_1sigma: dict[str, AngleValues | None]  # model (comma-joined terms) → bounds; None when singular
    crb_note: str
    separability: tuple[Separability, ...] = ()  # per effect not in the model


@dataclass(frozen=True)
class StopsFingerprint:
    """Sums that identify the stop table a result was fitted to (:func:`mountcal.stops.identity.fingerprint`)."""

    n: int
    acc_sum_mps2: tuple[float, float, float]
    acc_ranked_sum_mps2: tuple[float, float, float]
    beta_ranked_sum_deg: float | None


@dataclass(frozen=True)
class Convention:
    """One convention of the input (docs/conventions.md, "Conventions of the inputs"): its value, and
    whether it was stated (by whom), inferred from the data (from what), or assumed by default."""

    name: str  # heading_reference, heading_unit, acceleration_unit, axes, gravity, ...
    value: str
    how: Literal["stated", "inferred", "default"]
    by: str  # the option, column or file that stated it; what it was inferred from; or why the default


@dataclass(frozen=True)
class Check:
    """A plausibility check of the input's conventions or of the answer: passed, failed (the result is
    then not confident), or not tested (``passed`` None), each with the reason."""

    name: str
    passed: bool | None
    reason: str


@dataclass(frozen=True)
class Provenance:
    """Where a result came from: the input (with the SHA-256 of each file), the software, when, and the
    conventions of the input, each stated, inferred or assumed.

    ``input_kind`` says what the input was taken for and why (:mod:`mountcal.io.kind`);
    ``incomplete_inputs`` names the files read although cut short (``--allow-truncated``), or whose
    end could not be verified, with where each ends (:mod:`mountcal.io.whole`).
    """

    input: str
    software: str
    method: str
    model: tuple[str, ...]
    created_utc: str
    input_sha256: tuple[str, ...] = ()
    stops_fingerprint: StopsFingerprint | None = None
    input_kind: str = ""
    incomplete_inputs: tuple[str, ...] = ()
    conventions: tuple[Convention, ...] = ()


@dataclass(frozen=True)
class Systematic:
    """The two parts of every σ the result reports (1σ, degrees; the σ fields hold the total
    √(statistical² + systematic²)): the stop noise, and the sensor's limits the stops cannot see."""

    statistical: dict[str, float | None]
    systematic: dict[str, float | None]
    source: str  # what the sensor limits are: a default class, a spec file, a triad calibration
    limits: SensorLimits
    propagated: tuple[str, ...]  # the sensor errors mapped into the angles (those the final model does not fit)
    default_spec: bool
    dominant: bool  # the systematic part exceeds the statistical one for an angle

    # The two parts are the v2 file's flat keys (roll_deg … slope_deg, rotation_x_deg …): these convert them.
    @staticmethod
    def part(angles: AngleValues, rotation_xyz: tuple[float | None, ...]) -> dict[str, float | None]:
        """One part (σ of each angle, and of the rotation about each vehicle axis) as the file keeps it."""
        out = {Angles.value_column(name): value for name, value in angles.items()}
        return out | {f"rotation_{axis}_deg": s for axis, s in zip("xyz", rotation_xyz, strict=True)}

    @staticmethod
    def angles_of(part: dict[str, float | None]) -> AngleValues:
        """The σ of each angle in a part (:meth:`part`)."""
        return AngleValues(*(part.get(Angles.value_column(name)) for name in ANGLE_NAMES))

    @staticmethod
    def rotation_of(part: dict[str, float | None]) -> tuple[float | None, float | None, float | None]:
        """The σ about vehicle x, y, z in a part (:meth:`part`)."""
        x, y, z = (part.get(f"rotation_{axis}_deg") for axis in "xyz")
        return x, y, z

    @property
    def statistical_angles(self) -> AngleValues:
        return Systematic.angles_of(self.statistical)

    @property
    def systematic_angles(self) -> AngleValues:
        return Systematic.angles_of(self.systematic)


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
    fit: FitQuality
    observability: Observability | None  # None: not computed for this method
    model_selection: ModelSelection
    provenance: Provenance
    notes: tuple[str, ...] = ()
    model_steps: tuple[ModelStep, ...] = ()  # the before/after table of the loop
    unexplained: tuple[Finding, ...] = ()  # structure the model leaves
    diagnostics: tuple[Finding, ...] = ()  # every residual test of the final model
    effects: tuple[EffectValue, ...] = ()  # fitted effect values ± σ
    confident: bool = True  # False when the residual shows structure the model does not explain
    systematic: Systematic | None = None  # the statistical and systematic parts of the σ above (their total)
    checks: tuple[Check, ...] = ()  # plausibility checks (mountcal.loop.plausibility); a failed one: not confident

    def __post_init__(self) -> None:
        self.angles  # noqa: B018  (refuses a yaw or slope without its σ, whoever built the value)
        if self.yaw_deg is None:  # a yaw nobody determined is never kept, whoever built the value
            object.__setattr__(self, "rot_vs", levelled(self.rot_vs))

    @property
    def yaw_determined(self) -> bool:
        return self.yaw_deg is not None

    @property
    def angles(self) -> Angles:
        """Roll, pitch, yaw and slope with their σ, as a model step holds them."""
        return Angles(
            self.roll_deg,
            self.roll_sigma_deg,
            self.pitch_deg,
            self.pitch_sigma_deg,
            self.yaw_deg,
            self.yaw_sigma_deg,
            self.yaw_reason,
            self.slope_deg,
            self.slope_sigma_deg,
        )

    @staticmethod
    def angle_fields(angles: Angles) -> dict[str, Any]:
        """The calibration's fields of ``angles`` (its flat fields are the v2 file's): what the code that computes
        a calibration passes, ``Calibration(..., **Calibration.angle_fields(angles))``. A calibration always has
        roll and pitch with their σ: angles without them are refused."""
        if angles.roll_sigma_deg is None or angles.pitch_sigma_deg is None:
            raise ValueError(f"roll or pitch without its σ ({angles!r}): no calibration")
        return {field: getattr(angles, field) for field in Angles.__dataclass_fields__}

    def with_angles(self, angles: Angles) -> Calibration:
        """This calibration with ``angles`` in place of its own (rotation and the rest unchanged)."""
        return replace(self, **Calibration.angle_fields(angles))

    def effect(self, name: str) -> EffectValue | None:
        """The fitted effect of that name (e.g. ``bias_mps2``), None when the model has no such effect."""
        return next((e for e in self.effects if e.name == name), None)

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
            "provenance": to_plain(self.provenance),
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
            "fit": to_plain(self.fit),
            "observability": to_plain(self.observability),
            "model_selection": to_plain(self.model_selection),
            "stops": {
                "n": int(self.residual_s.shape[0]),
                "residual_s_mps2": [[float(v) if np.isfinite(v) else None for v in row] for row in self.residual_s],
            },
            "effects": to_plain(self.effects),
            "model_steps": to_plain(self.model_steps),
            "unexplained": to_plain(self.unexplained),
            "confident": self.confident,
            "diagnostics": to_plain(self.diagnostics),
            "notes": list(self.notes),
            "systematic": to_plain(self.systematic),
            "checks": to_plain(self.checks),
        }

    def document(self) -> dict[str, Any]:
        """:meth:`to_dict`, checked as the loader checks a file (:meth:`from_dict`): what mountcal
        writes, it reads back. A result with a value outside its range (docs/reliability.md) —
        an angle whose 1σ exceeds ten turns — is no usable calibration: not enough information."""
        doc = self.to_dict()
        try:
            Calibration.from_dict(doc, where="the result")
        except InputError as err:
            raise NotEnoughInformation(
                f"the result holds values no calibration can ({err.found}): the data do not determine the mounting. "
                "Park at more headings, on a steeper slope, or for longer."
            ) from err
        return doc

    def save(self, path: str | Path) -> None:
        """Write the JSON file atomically (:meth:`document`: only what reads back; a name ending in another
        format's suffix is refused)."""
        from mountcal.core.output_suffix import check_output_suffix

        check_output_suffix(option("output"), path, (".json",))
        text = json.dumps(self.document(), indent=2, allow_nan=False)
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
        if doc.get("format_version") == 1:  # its free-form parts cannot be read as the typed ones without guessing
            raise InputError(
                where,
                f"format_version {FORMAT_VERSION}",
                "format_version 1 (written by mountcal before its result was typed)",
                "Re-run `mountcal calibrate` on the same input (or its stop table) to write this version's file.",
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
                **{name: from_plain(_TYPED[name], doc[name], name) for name in _TYPED if name in doc},
                notes=tuple(doc.get("notes", ())),
                confident=bool(doc.get("confident", True)),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise InputError(
                where,
                "a complete calibration document",
                f"a missing or malformed field ({err})",
                "The file was altered or corrupted: re-create it with `mountcal calibrate`.",
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


def _typed_fields() -> dict[str, Any]:
    """The Calibration fields held as typed values (dataclasses), each with its type."""

    def typed(tp: Any) -> bool:
        return (isinstance(tp, type) and is_dataclass(tp)) or any(typed(a) for a in get_args(tp))

    return {name: tp for name, tp in get_type_hints(Calibration).items() if typed(tp)}


_TYPED = _typed_fields()


def schema_defs() -> dict[str, Any]:
    """The JSON Schema of the typed parts of a result (``$defs`` and the top-level properties using them).

    The published schema (``mountcal/schema/calibration.schema.json``) holds exactly these; a test
    fails when they drift apart (regenerate with ``python -m mountcal.core.result``).
    """
    defs: dict[str, Any] = {}
    properties = {name: schema_of(tp, defs) for name, tp in _TYPED.items()}
    return {"$defs": dict(sorted(defs.items())), "properties": properties}


def _list(a: FloatArray | None) -> list[float] | None:
    return None if a is None else [float(x) for x in a]


def _array(a: list[float] | None) -> FloatArray | None:
    return None if a is None else np.asarray(a, dtype=float)


if __name__ == "__main__":  # regenerate the typed parts of the published schema
    from mountcal.core.result_file import write_schema

    write_schema(schema_defs())
