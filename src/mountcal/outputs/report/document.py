"""Reading a calibration result for display: angles ± σ, model steps, unexplained structure.

The result JSON (:mod:`mountcal.result`) is the source of truth. Entries added by later analyses
(``model_steps``, ``unexplained``: the closing-the-loop work) are read tolerantly: what is absent
is reported as absent, what has an unexpected shape is shown as it is rather than dropped.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from mountcal.result import Calibration

ANGLES = ("roll", "pitch", "yaw", "slope")


@dataclass(frozen=True)
class Estimate:
    """A value with its 1σ; ``value`` None when not determined (``reason`` then says why)."""

    value: float | None
    sigma: float | None
    reason: str | None = None

    @property
    def determined(self) -> bool:
        return self.value is not None


def angle_estimates(entry: Calibration | Mapping[str, Any]) -> dict[str, Estimate]:
    """Roll, pitch, yaw and slope in degrees with their 1σ, from a calibration or a model step.

    Parameters
    ----------
    entry : Calibration or mapping
        A :class:`~mountcal.result.Calibration`, its JSON document, or one model step. A step may
        hold the angles flat (``roll_deg`` with ``roll_sigma_deg`` or ``sigma_roll_deg``), nested
        like the result (``mounting``/``uncertainty``), or under ``angles``/``angles_deg`` as
        ``{"roll": [value, sigma]}`` or ``{"roll_deg": {"value": v, "sigma": s}}``.

    Returns
    -------
    dict of str to Estimate
        Keys ``roll``, ``pitch``, ``yaw``, ``slope``; degrees.
    """
    if isinstance(entry, Calibration):
        return {
            "roll": Estimate(entry.roll_deg, entry.roll_sigma_deg),
            "pitch": Estimate(entry.pitch_deg, entry.pitch_sigma_deg),
            "yaw": Estimate(entry.yaw_deg, entry.yaw_sigma_deg, entry.yaw_reason),
            "slope": Estimate(
                entry.slope_deg,
                entry.slope_sigma_deg,
                None if entry.slope_deg is not None else "not determined (see the notes)",
            ),
        }
    return {name: _angle_from_mapping(entry, name) for name in ANGLES}


def _angle_from_mapping(doc: Mapping[str, Any], name: str) -> Estimate:
    key = f"{name}_deg"
    mounting = doc.get("mounting")
    if isinstance(mounting, Mapping):  # the result document's own layout
        uncertainty = doc.get("uncertainty")
        value = _number(doc.get(key) if name == "slope" else mounting.get(key))
        sigma = _number(uncertainty.get(key)) if isinstance(uncertainty, Mapping) else None
        reason = None
        if value is None:
            yaw = doc.get("yaw")
            given = yaw.get("reason") if name == "yaw" and isinstance(yaw, Mapping) else None
            reason = _text(given) or "not determined (see the notes)"
        return Estimate(value, sigma, reason)
    for group in ("angles", "angles_deg"):
        nested = doc.get(group)
        if isinstance(nested, Mapping):
            item = nested.get(key, nested.get(name))
            if isinstance(item, Mapping):  # {"roll_deg": {"value": v, "sigma": s}}
                return Estimate(
                    _number(item.get("value", item.get("deg"))),
                    _number(item.get("sigma", item.get("sigma_deg"))),
                    _text(item.get("reason")),
                )
            if isinstance(item, Sequence) and not isinstance(item, str) and len(item) == 2:  # {"roll": [v, s]}
                return Estimate(_number(item[0]), _number(item[1]))
            if key in nested or name in nested:  # {"roll_deg": v, "roll_sigma_deg": s}
                return _flat(nested, name)
    if key in doc:
        return _flat(doc, name)
    return Estimate(None, None, "not given")


def _flat(doc: Mapping[str, Any], name: str) -> Estimate:
    value = _number(doc.get(f"{name}_deg", doc.get(name)))
    sigma = _number(doc.get(f"{name}_sigma_deg", doc.get(f"sigma_{name}_deg")))
    reason = _text(doc.get(f"{name}_reason"))
    return Estimate(value, sigma, reason or (None if value is not None else "not determined"))


def _number(x: Any) -> float | None:
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    return float(x) if math.isfinite(x) else None


def _text(x: Any) -> str | None:
    return None if x is None else str(x)


@dataclass(frozen=True)
class ModelStep:
    """One step of a model search: what it added and why, its fit quality, angles and effects.

    ``moved`` is the change of each angle from the previous step (degrees), ``effects`` the fitted
    effect values ± σ, ``excluded_stops`` the stop numbers (1-based) left out; ``extra`` holds
    whatever else the step carries, shown as it is.
    """

    label: str
    terms: tuple[str, ...]
    reason: str | None
    residual_rms_mps2: float | None
    chi2: float | None
    dof: int | None
    p_value: float | None
    angles: dict[str, Estimate]
    moved_deg: dict[str, float]
    effects: dict[str, Any]
    excluded_stops: tuple[int, ...]
    extra: dict[str, Any]


_STEP_KEYS = {
    "added",
    "label",
    "name",
    "step",
    "reason",
    "terms",
    "model",
    "residual_rms_mps2",
    "chi2",
    "dof",
    "p_value",
    "mounting",
    "uncertainty",
    "angles",
    "angles_deg",
    "yaw",
    "moved",
    "effects",
    "excluded_stops",
    *(f"{a}_deg" for a in ANGLES),
    *(f"{a}_sigma_deg" for a in ANGLES),
    *(f"sigma_{a}_deg" for a in ANGLES),
    *(f"{a}_reason" for a in ANGLES),
}


def model_steps(doc: Mapping[str, Any]) -> list[ModelStep] | None:
    """The before/after model steps of a result document; None when it carries none."""
    raw = doc.get("model_steps")
    if not isinstance(raw, Sequence) or isinstance(raw, str):
        return None
    steps = []
    previous: dict[str, Estimate] | None = None
    for i, item in enumerate(raw):
        if not isinstance(item, Mapping):
            item = {"value": item}
        terms = item.get("terms", item.get("model", ()))
        terms_t = (terms,) if isinstance(terms, str) else tuple(str(t) for t in terms or ())
        added = item.get("added")
        label = item.get("label", item.get("name", item.get("step")))
        if label is None:
            label = f"{i + 1}. {'+ ' if i and added else ''}{added}" if added else f"step {i + 1}"
        angles = angle_estimates(item)
        moved = item.get("moved")
        moved_deg: dict[str, float] = {}
        for a in ANGLES:
            given = _number(moved.get(f"{a}_deg", moved.get(a))) if isinstance(moved, Mapping) else None
            now, before = angles[a].value, None if previous is None else previous[a].value
            if given is not None:
                moved_deg[a] = given
            elif not isinstance(moved, Mapping) and now is not None and before is not None:
                moved_deg[a] = now - before  # not given: the change from the previous step
        effects = item.get("effects")
        excluded = item.get("excluded_stops")
        dof = item.get("dof")
        steps.append(
            ModelStep(
                label=str(label),
                terms=terms_t,
                reason=_text(item.get("reason")),
                residual_rms_mps2=_number(item.get("residual_rms_mps2")),
                chi2=_number(item.get("chi2")),
                dof=int(dof) if isinstance(dof, int | float) and not isinstance(dof, bool) else None,
                p_value=_number(item.get("p_value")),
                angles=angles,
                moved_deg=moved_deg,
                effects=dict(effects) if isinstance(effects, Mapping) else {},
                excluded_stops=tuple(int(k) for k in excluded if isinstance(k, int | float))
                if isinstance(excluded, Sequence) and not isinstance(excluded, str)
                else (),
                extra={k: v for k, v in item.items() if k not in _STEP_KEYS},
            )
        )
        previous = angles
    return steps


def format_effect(name: str, entry: Any) -> str:
    """An effect's value ± σ as text: ``{"value": [..], "sigma": [..]}`` per component, or as given.

    The unit is taken from the name's suffix (``bias_mps2`` → m/s²).
    """
    units = {"_mps2_per_c": " m/s²/°C", "_mps2": " m/s²", "_deg": "°", "_ppm": " ppm", "_pct": " %"}
    unit = next((u for suffix, u in units.items() if name.endswith(suffix)), "")
    if not isinstance(entry, Mapping) or "value" not in entry:
        return str(entry)
    value, sigma = entry.get("value"), entry.get("sigma")
    if isinstance(value, Sequence) and not isinstance(value, str):
        sig = list(sigma) if isinstance(sigma, Sequence) and not isinstance(sigma, str) else [None] * len(value)
        parts = [_pm_plain(_number(v), _number(s)) for v, s in zip(value, sig, strict=False)]
        return f"({', '.join(parts)}){unit}"
    return _pm_plain(_number(value), _number(sigma)) + unit


def _pm_plain(value: float | None, sigma: float | None) -> str:
    if value is None:
        return "—"
    return format_pm(value, sigma, "") if sigma is not None else f"{value:.4g}"


def unexplained(doc: Mapping[str, Any]) -> list[dict[str, Any]] | None:
    """The structures the best model leaves unexplained; None when the result has no such analysis."""
    raw = doc.get("unexplained")
    if not isinstance(raw, Sequence) or isinstance(raw, str):
        return None
    return [dict(item) if isinstance(item, Mapping) else {"what": str(item)} for item in raw]


def format_pm(value: float | None, sigma: float | None, unit: str = "°") -> str:
    """``value ± σ`` with as many decimals as two significant digits of σ; "not determined" for None."""
    if value is None:
        return "not determined"
    if sigma is None or not math.isfinite(sigma) or sigma <= 0:
        return f"{value:.4g}{unit}"
    decimals = min(max(1 - math.floor(math.log10(sigma)), 0), 8)
    return f"{value:.{decimals}f}{unit} ± {sigma:.{decimals}f}{unit}"
