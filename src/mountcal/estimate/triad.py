"""A triad calibration (bias, scale, cross-axis with their covariance), applied to stops before the mounting fit.

It comes from a multi-position session fitted by :mod:`mountcal.estimate.sphere` (``mountcal
triad``), saved as a ``mountcal.estimate.triad`` JSON. The correction is the sphere model's
``a ← (I + E)⁻¹ (a − b)``; what remains uncertain of b and E (their covariance) is a systematic
error common to every stop, which :mod:`mountcal.loop.systematic` carries into the angles in place of
the datasheet's scale, cross-axis and bias limits.

A triad describes the sensor's own axes, after the axis map the session was read with: the JSON states
that map (``conventions``), applying it to stops read with another map is refused, and so are samples
mountcal rotate already put in the vehicle frame, for fitting a triad and for applying one
(:func:`mountcal.io.frame.refuse_rotated`).

The JSON states the acceleration's sign too, where the session's reading stated one (a Sensor Logger recording:
``acceleration_sign``). The sphere fit sees magnitudes only: an acceleration negated in all three axes (a
reflection, which no symmetric ``I + E`` near I can hold: its determinant stays positive) fits as well, with the
bias negated. So a triad whose sign was only the app's default has a bias whose sign rests on that default; it
is said when fitted, and applying it to stops read with the other sign is refused naming the setting.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mountcal.core.atomic import atomic_path
from mountcal.core.conventions import FloatArray
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.output_suffix import check_output_suffix
from mountcal.core.ranges import check_values
from mountcal.core.result import Convention
from mountcal.core.result_file import read_json
from mountcal.core.sensor_limits import SensorLimits
from mountcal.estimate import sphere
from mountcal.estimate.effects.scale import SCALE_NAMES
from mountcal.estimate.sensor_errors import BIAS_NAMES, TEMP_NAMES, SensorErrors, from_spec, heading_u
from mountcal.estimate.triad_session import MIN_STOP_S, TRIM_S
from mountcal.io.frame import refuse_rotated, rotated_of
from mountcal.io.input_conventions import IDENTITY_AXES, axes_convention, axes_stated, parse_axes
from mountcal.io.kind import Declared
from mountcal.io.sensor_logger import SETTING, SIGN, acceleration_sign
from mountcal.io.sensor_spec import SensorSpec
from mountcal.stops.table import StopTable, Unit, read_stop_table

if TYPE_CHECKING:
    from mountcal.io.reader import LogOptions

FORMAT = "mountcal.estimate.triad"
FORMAT_VERSION = 1
# The sphere fit's parameter order (bias, scale, cross-axis), in the static model's names.
NAMES = BIAS_NAMES + SCALE_NAMES


@dataclass(frozen=True)
class Triad:
    """b (m/s², sensor frame), E (xx, yy, zz, xy, xz, yz) and their 9×9 covariance in the order of ``NAMES``."""

    bias_mps2: FloatArray
    scale_e: FloatArray
    cov: FloatArray  # rows and columns of names not in ``fitted`` are zero
    source: str
    fitted: tuple[str, ...] = NAMES  # what the session determined; the others keep the sensor spec's limits
    conventions: tuple[Convention, ...] = ()  # the session's axis map ("axes"); () in a file that states none

    @property
    def matrix(self) -> FloatArray:
        """I + E."""
        e = self.scale_e
        return np.eye(3) + np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]], dtype=np.float64)

    def correct(self, table: StopTable) -> StopTable:
        """The stops as the calibrated sensor reads them, ``(I + E)⁻¹ (a − b)``, their covariance mapped alike.

        Raises
        ------
        InputError
            The stops are in mountcal's vehicle frame, or read with another axis map than the triad's session.
        """
        todo = (
            f"Calibrate the original log with {option('triad')}, or leave {option('triad')} out."  # named when raised
        )
        refuse_rotated(rotated_of(table.conventions), table.source, _APPLY_ROTATED, todo)
        made, now = _axes_text(self.conventions), _axes_text(table.conventions)
        if made is not None and made != (now or IDENTITY_AXES):  # a file that states no map cannot be checked
            fix = option("axes", made) if made != IDENTITY_AXES else f"no {option('axes')}"
            raise InputError(
                table.source,
                f"stops read with the axes the triad calibration was made with ({made})",
                now or "the axes as logged",
                f"Read the log with the same map: {fix}.",
            )
        _check_sign(self, table)
        inv = np.linalg.inv(self.matrix)
        cov = None if table.cov_s is None else np.einsum("ij,njk,lk->nil", inv, table.cov_s, inv)
        return replace(table, acc_s=(table.acc_s - self.bias_mps2) @ inv.T, cov_s=cov)

    def errors(self, spec: SensorSpec) -> SensorErrors:
        """What remains uncertain after the correction: the triad's covariance, and the spec's bias drift per °C."""
        cov = np.zeros((12, 12))
        cov[:9, :9] = self.cov
        spec_u2 = from_spec(spec)  # names BIAS, TEMP, SCALE: the datasheet's rectangular variances
        for i, name in enumerate(NAMES):
            if name not in self.fitted:
                j = spec_u2.names.index(name)
                cov[i, i] = spec_u2.cov[j, j]
        cov[9:, 9:] = np.eye(3) * spec.bias_tempco_mps2_per_c**2 / 3.0
        sigma = np.sqrt(np.diag(self.cov))
        limits = SensorLimits(
            source=f"triad calibration {self.source}",
            triad_sigma={n: float(s) for n, s in zip(NAMES, sigma, strict=True) if n in self.fitted},
            from_spec={n: float(np.sqrt(cov[i, i])) for i, n in enumerate(NAMES) if n not in self.fitted},
            bias_tempco_mps2_per_c=spec.bias_tempco_mps2_per_c,
            heading_deg=spec.heading_deg,
        )
        return SensorErrors(
            NAMES + TEMP_NAMES, cov, f"triad calibration {self.source}", limits, heading_u(spec.heading_deg)
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "source": self.source,
            "model": "a_calibrated = (I + E)^-1 (a_raw - b), E symmetric",
            "names": list(NAMES),
            "fitted": list(self.fitted),
            "values": [*map(float, self.bias_mps2), *map(float, self.scale_e)],
            "covariance": self.cov.tolist(),
            "conventions": [{"name": c.name, "value": c.value, "how": c.how, "by": c.by} for c in self.conventions],
        }

    def save(self, path: str | Path) -> None:
        check_output_suffix(option("output"), path, (".json",))
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n", encoding="utf-8")


def from_sphere(fit: sphere.SphereFit, source: str, conventions: tuple[Convention, ...] = ()) -> Triad:
    """A triad from a sphere fit (of bias and scale, or of all three terms); ``conventions`` are the
    session's (its axis map is kept)."""
    values, cov = np.zeros(9), np.zeros((9, 9))
    idx = [_SPHERE_TO_MODEL[n] for n in fit.names]
    values[idx] = fit.values
    cov[np.ix_(idx, idx)] = fit.cov
    axes = tuple(c for c in conventions if c.name == AXES) or (axes_convention(None, IDENTITY_AXES, ""),)
    signs = tuple(c for c in conventions if c.name == SIGN)  # the bias's sign rests on it (module docstring)
    return Triad(values[:3], values[3:], cov, source, tuple(NAMES[i] for i in idx), axes + signs)


# sphere.py names → positions in NAMES (bias_x…, scale_xx…, cross_xy…)
_SPHERE_TO_MODEL = {
    **{f"bias_{a}": i for i, a in enumerate("xyz")},
    **{f"scale_{a}": 3 + i for i, a in enumerate("xyz")},
    **{f"cross_{p}": 6 + i for i, p in enumerate(("xy", "xz", "yz"))},
}


def load(path: str | Path) -> Triad:
    """Read a ``mountcal.estimate.triad`` JSON; anything else, or an unusable value, is refused naming the file."""
    doc = read_json(Path(path))
    todo = "Pass a file written by `mountcal triad -o` (an imucal JSON first goes through `mountcal triad`)."
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("format_version") != FORMAT_VERSION:
        found = doc.get("cal_type", doc.get("format")) if isinstance(doc, dict) else type(doc).__name__
        raise InputError(str(path), f"a {FORMAT} JSON, version {FORMAT_VERSION}", repr(found), todo)
    fitted = doc.get("fitted", list(NAMES))
    unknown = [n for n in fitted if n not in NAMES] if isinstance(fitted, list) else [fitted]
    if unknown:  # a parameter the triad model does not have: refused, never dropped or guessed at
        raise InputError(
            str(path),
            f"fitted parameters among {', '.join(NAMES)}",
            f"the unknown parameter{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}",
            todo,
        )
    try:
        values = np.asarray(doc["values"], dtype=float)
        cov = np.asarray(doc["covariance"], dtype=float)
        ok = values.shape == (9,) and cov.shape == (9, 9)
    except (KeyError, TypeError, ValueError):
        ok = False
    if ok:  # each number in its range (mountcal.core.ranges) before any arithmetic on them
        check_values("triad_bias_mps2", values[:3], str(path), "values (the bias)")
        check_values("triad_covariance", cov, str(path), "covariance")
        ok = bool(np.allclose(cov, cov.T)) and bool(np.all(np.linalg.eigvalsh(cov) > -1e-12 * cov.max()))
        ok = ok and bool(np.all(np.abs(values[3:]) < 0.5))
    if not ok:
        raise InputError(str(path), "9 finite values (|E| < 0.5) and a symmetric 9×9 covariance", "other values", todo)
    conventions = _conventions(doc.get("conventions", []), str(path), todo)
    return Triad(values[:3], values[3:], cov, str(doc.get("source", path)), tuple(str(n) for n in fitted), conventions)


def _conventions(items: object, path: str, todo: str) -> tuple[Convention, ...]:
    """The ``conventions`` of a triad JSON: the session's axis map, as ``mountcal triad`` wrote it."""
    keys = ("name", "value", "how", "by")
    out: list[Convention] = []
    for item in items if isinstance(items, list) else [None]:
        if not (isinstance(item, dict) and all(isinstance(item.get(k), str) for k in keys) and item["how"] in _HOWS):
            raise InputError(path, "conventions as mountcal triad writes them (name, value, how, by)", repr(item), todo)
        out.append(Convention(item["name"], item["value"], item["how"], item["by"]))
    try:  # an axis map that does not parse is refused here, not when the triad is applied
        _axes_text(out)
    except InputError as err:
        raise InputError(path, "conventions as mountcal triad writes them: an axis map", err.found, todo) from err
    return tuple(out)


def _axes_text(conventions: Sequence[Convention]) -> str | None:
    """The axis map an ``axes`` convention states (``x,y,z`` for the axes as logged), or None."""
    found = axes_stated(conventions, AXES)
    return None if found is None else found[1].text


def _check_sign(triad: Triad, table: StopTable) -> None:
    """Refuse stops read with the other acceleration sign than a triad whose sign was only the app's default:
    its bias would apply negated if both sessions were recorded with the same setting (module docstring)."""
    made = acceleration_sign(triad.conventions)
    now = acceleration_sign(table.conventions)
    if made is None or now is None or made.how != "default" or made.value == now.value:
        return
    raise InputError(
        f"{table.source} with {option('triad')} {triad.source}",
        f"stops read with the acceleration sign the triad's bias was fitted with: {made.value} (the app's default)",
        f"{now.value} ({now.how}: {now.by})",
        f"The triad's session assumed the app's default for {SETTING!r}; if it was recorded with the setting as "
        "these stops were, its bias has the wrong sign. Fit the triad again on a session whose sign is known "
        "(record AccelerometerUncalibrated with it, or state the sign in its stop table's column acceleration_sign).",
    )


def sign_note(triad: Triad) -> list[str]:
    """A note for ``mountcal triad`` where the session's acceleration sign was only the app's default."""
    sign = acceleration_sign(triad.conventions)
    if sign is None or sign.how != "default":  # every sphere fit has a bias (module docstring)
        return []
    return [
        f"  note: the acceleration was read {sign.value}, {sign.by}, which a triad session cannot confirm (the "
        "sphere fit sees magnitudes only): the bias's sign rests on it, the scale and cross-axis do not; calibrating "
        "with this triad refuses stops read with the other sign"
    ]


AXES = "axes"  # the one convention a triad keeps: the axis map of its session
_HOWS = ("stated", "inferred", "default")
_FIT_ROTATED = "a triad calibration describes the sensor's own axes, and these are the vehicle's"
_FIT_TODO = "Fit the triad on the original log, the one mountcal rotate read."
_APPLY_ROTATED = "a triad calibration corrects the sensor's own axes, and these are the vehicle's"

MIN_STOPS = 6  # six parameters (bias, scale): the six faces, with each stop's noise given
AGREE_SIGMA = 5.0  # imucal's values within this many σ of mountcal's fit of the same session


def fit_all(acc: FloatArray, g: float, cov: FloatArray | None, where: str) -> Any:
    """The sphere fit of bias, scale and cross-axis together, or of bias and scale when the stops see no
    cross-axis (the six faces alone: the couplings then keep the sensor spec's limits); refused below that."""
    for terms in (sphere_terms(), sphere_terms()[:2]):
        fit, loose = _fit(acc, g, cov, terms)
        if not loose:  # a χ² beyond its dof (stops less still, or a model short of the sensor) widens the σ
            return replace(fit, cov=fit.cov * max(1.0, fit.chi2 / fit.dof)) if fit.dof > 0 else fit
    raise InputError(
        where,
        f"stops that separate bias and scale (at least {MIN_STOPS} in different orientations)",
        f"{acc.shape[0]} stops leaving {', '.join(loose)} undetermined",
        _TODO_POSITIONS,
    )


def sphere_terms() -> tuple[str, ...]:
    return sphere.TERMS


def _fit(acc: FloatArray, g: float, cov: FloatArray | None, terms: tuple[str, ...]) -> tuple[Any, list[str]]:
    n_par = 3 * len(terms)
    if acc.shape[0] < n_par + (0 if cov is not None else 3):  # an estimated noise needs residual dof
        return None, [f"{n_par} parameters from {acc.shape[0]} stops"]
    fit = sphere.fit(acc, g, terms, cov)
    sig = fit.sigma()
    kinds = np.repeat(terms, 3)
    loose = [n for n, s, t in zip(fit.names, sig, kinds, strict=True) if not s <= sphere.PLAUSIBLE[t]]
    return fit, loose


_TODO_POSITIONS = (
    "Hold the sensor still in many orientations (at least the six faces and some in between), e.g. "
    "the six-position test of imucal or IMU-TK's hand-held session."
)


def session_stops(
    paths: list[str],
    unit: Unit,
    min_stop_s: float = MIN_STOP_S,
    trim_s: float = TRIM_S,
    log: LogOptions | None = None,
    *,
    declared: Declared = "auto",
) -> tuple[FloatArray, FloatArray | None, tuple[Convention, ...]]:
    """Stop means (n, 3) in m/s², their covariances and the input's conventions, from a stop table or from
    logs (read as ``log`` says, its ``axes`` too for a stop table; ``unit`` is a stop table's, and a sample
    table's where ``log`` gives none). :func:`mountcal.io.kind.kind_of_input` decides which; ``declared``
    is ``--input-kind``.

    Raises
    ------
    InputError
        Among others: samples (or a stop table's) that mountcal rotate put in the vehicle frame.
    """
    from mountcal.io.kind import kind_of_input
    from mountcal.io.logs import read_log
    from mountcal.io.reader import LogOptions
    from mountcal.io.samples import with_gravity
    from mountcal.io.whole import reading
    from mountcal.stops.detect import StopDetection, detect_stops

    log = log or LogOptions()
    if kind_of_input(paths, log, declared).stop_table:
        axes = None if log.axes is None else parse_axes(log.axes, option("axes"))
        with reading(log.allow_truncated):  # a cut CSV: refused, or its whole rows read
            table = read_stop_table(paths[0], unit=unit, headings="none", axes=axes)
        refuse_rotated(rotated_of(table.conventions), table.source, _FIT_ROTATED, _FIT_TODO)
        return table.acc_s, table.cov_s, table.conventions
    if log.unit is None and unit != "mps2":
        log = replace(log, unit=unit)
    samples = with_gravity(read_log(paths, log))
    refuse_rotated(samples.rotated, samples.source, _FIT_ROTATED, _FIT_TODO)
    stops = detect_stops(samples, StopDetection(min_duration_s=min_stop_s, trim_s=trim_s))
    if not stops:
        raise InputError(" + ".join(paths), "a session with still periods", "no stop", _TODO_POSITIONS)
    return np.array([s.acc_mean_s for s in stops]), np.array([s.acc_cov_mean_s for s in stops]), samples.conventions


def with_imucal_values(triad: Any, path: str) -> Any:
    """imucal's bias and (symmetric part of the) scale/cross-axis matrix, with mountcal's covariance of the session.

    imucal corrects ``a = R_a⁻¹ K_a⁻¹ (raw − b_a)``: raw = K_a R_a a + b_a. The left polar
    decomposition K_a R_a = P U leaves P = I + E (symmetric) and a rotation U that the mounting
    rotation absorbs.
    """
    from scipy.linalg import polar

    doc = read_json(Path(path))
    todo = "Pass the JSON imucal's FerrarisCalibrationInfo.to_json_file wrote (acc in m/s², acc_unit 'm/s^2')."
    try:
        ok = isinstance(doc, dict) and doc.get("cal_type") == "Ferraris" and doc.get("acc_unit") == "m/s^2"
        k_a, r_a, b_a = (np.asarray(doc[k], dtype=float) for k in ("K_a", "R_a", "b_a"))
        ok = ok and k_a.shape == (3, 3) and r_a.shape == (3, 3) and b_a.shape == (3,)
        ok = ok and bool(np.all(np.isfinite(k_a)) and np.all(np.isfinite(r_a)) and np.all(np.isfinite(b_a)))
    except (KeyError, TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(path, "an imucal Ferraris calibration JSON with K_a, R_a, b_a", "other content", todo)
    check_values("imucal_matrix", np.concatenate([k_a, r_a]), path, "K_a, R_a (rows 1–3: K_a, 4–6: R_a)")
    check_values("triad_bias_mps2", b_a, path, "b_a")
    _, p = polar(k_a @ r_a, side="left")
    e = p - np.eye(3)
    values = np.concatenate([b_a, np.diag(e), [e[0, 1], e[0, 2], e[1, 2]]])
    ours = np.concatenate([triad.bias_mps2, triad.scale_e])
    fitted = [NAMES.index(n) for n in triad.fitted]  # the couplings, when the session cannot see them, keep the spec
    z = np.abs(values - ours)[fitted] / np.sqrt(np.diag(triad.cov)[fitted])
    if np.max(z) > AGREE_SIGMA:
        raise InputError(
            path,
            f"values within {AGREE_SIGMA:g}σ of this session's fit",
            f"a difference of {np.max(z):.1f}σ",
            "Pass the session the imucal calibration was made from (its covariance comes from that session), with "
            "the gravity imucal used (9.81 m/s² is its default).",
        )
    return replace(
        triad, bias_mps2=values[:3], scale_e=values[3:], source=f"imucal {path} (covariance from {triad.source})"
    )


def describe(triad: Any, fit: Any) -> list[str]:
    sig = np.sqrt(np.diag(triad.cov))
    values = np.concatenate([triad.bias_mps2, triad.scale_e])
    rms = float(np.sqrt(np.mean(fit.residual_mps2**2)))
    birge = np.sqrt(max(1.0, fit.chi2 / fit.dof)) if fit.dof > 0 else 1.0
    lines = [
        f"mountcal triad — {len(fit.residual_mps2)} stops, |a| residual RMS {rms:.4g} m/s², "
        f"χ² = {fit.chi2:.1f} on {fit.dof} dof (σ widened ×{birge:.2f})"
    ]
    lines += [
        f"  {n:<9} {v:+.5f} ± {s:.5f}" if n in triad.fitted else f"  {n:<9} not seen by these stops: the spec's limit"
        for n, v, s in zip(NAMES, values, sig, strict=True)
    ]
    if fit.dof == 0:
        lines.append("  note: as many stops as parameters: the values fit exactly and nothing checks the model")
    lines += sign_note(triad)
    lines.append("  (bias in m/s², scale and cross-axis as fractions; 1σ)")
    return lines
