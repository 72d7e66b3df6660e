"""The options of a calibration, as one typed value: each checked once, here, at the edge; one home for each default.

:class:`Options` (method, model, gravity, yaw threshold, sensor spec, triad, slope reference) is
what :func:`mountcal.calibration.fit.calibrate` reads, and what ``mountcal calibrate``, ``fleet``
and ``live`` build from their flags (:func:`mountcal.cli.options.fit_options`); the parsers take
their defaults from here (``--help`` shows them), so a flag's default, the dataclass's and the
library's cannot differ. A bad value is refused when the value is built — by the CLI or by a
library caller, with the same rule and a message naming the option (:func:`~mountcal.core.option_names.option`)
— and never decided again by a stage: ``Options.terms`` is ``model`` parsed.

Light (no numerical library at import): the CLI builds its parser with it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any, Literal

from mountcal.core import ranges
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.sensor_spec import DEFAULT as DEFAULT_SPEC
from mountcal.io.sensor_spec import SensorSpec
from mountcal.loop import terms as model_terms

if TYPE_CHECKING:
    from mountcal.estimate.triad import Triad
    from mountcal.loop.slope_reference import SlopeReference

Method = Literal["full", "paper"]
METHODS: tuple[Method, ...] = ("full", "paper")
BASE = model_terms.BASE
AUTO = "auto"
Use = Literal["auto", "stops", "driving"]
USES: tuple[Use, ...] = ("auto", "stops", "driving")
DEFAULT_USE: Use = "auto"  # a log's parked stops, its driving, or whatever it supports


@dataclass(frozen=True)
class Options:
    """Settings of a calibration run: the one home of their defaults (the CLI's ``--help`` shows these).

    Each is checked once, when the value is built, whoever builds it (the CLI from its flags, a
    fleet, a library caller); the stages read it and decide nothing again. ``terms`` is ``model``
    parsed: None for ``"auto"`` (the data choose), else the fixed terms.
    """

    method: Method = "full"
    model: str = AUTO
    gravity_mps2: float | None = None
    max_yaw_sigma_deg: float = 5.0
    selection_alpha: float = 0.001
    spec: SensorSpec = DEFAULT_SPEC  # the sensor's limits, for the systematic part of σ
    triad: Triad | None = None  # a triad calibration: applied to the stops, its covariance replaces the spec's
    slope_reference: SlopeReference | None = None  # checked against the stops' slope
    terms: tuple[str, ...] | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise InputError(option("method"), "paper or full", repr(self.method), "Choose one of them.")
        terms = parse_model(self.model)
        if self.method == "paper" and terms not in (None, BASE):
            raise InputError(
                option("model"),
                f"auto or rotation,slope with {option('method', 'paper')}",
                repr(self.model),
                f"The paper's method fits no bias; use {option('method', 'full')} for other models.",
            )
        if self.gravity_mps2 is not None:
            from mountcal.io.input_conventions import check_gravity_value

            check_gravity_value(float(self.gravity_mps2), option("gravity"))
        ranges.check("sigma_deg", self.max_yaw_sigma_deg, option("max_yaw_sigma"))
        object.__setattr__(self, "terms", terms)


def parse_model(spec: str) -> tuple[str, ...] | None:
    """``"auto"`` → None; a comma list of terms (:mod:`mountcal.loop.terms`), starting ``rotation,slope``."""
    if not isinstance(spec, str):
        raise InputError(option("model"), model_terms.help_text(), repr(spec), f"For example {option('model', AUTO)}.")
    terms = tuple(t.strip() for t in spec.split(",") if t.strip())
    if terms == (AUTO,):
        return None
    known = model_terms.by_name()
    unknown = [t for t in terms if t not in known]
    if terms[:2] != BASE or unknown or len(set(terms)) != len(terms):
        raise InputError(
            option("model"),
            f"{model_terms.help_text()} (installed: {', '.join(model_terms.optional())})",
            repr(spec) + (f" (unknown: {', '.join(unknown)})" if unknown else ""),
            f"For example {option('model', 'rotation,slope,bias')}.",
        )
    return terms


def check_use(use: str) -> None:
    """``use`` is one of :data:`USES`."""
    if use not in USES:
        raise InputError(option("use"), "auto, stops or driving", repr(use), "Choose one of them.")


def default(cls: type[Any], name: str) -> Any:
    """The default of the dataclass ``cls``'s field ``name``: what a parser shows and uses for its flag."""
    for f in fields(cls):
        if f.name == name:
            return f.default
    raise KeyError(name)


__all__ = [
    "AUTO",
    "BASE",
    "DEFAULT_USE",
    "METHODS",
    "USES",
    "Method",
    "Options",
    "Use",
    "check_use",
    "default",
    "parse_model",
]
