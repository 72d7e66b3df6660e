"""The registry of effects: the built-in ones (one module each, here) and those of other packages.

A package adds an effect by one class satisfying :class:`~mountcal.estimate.effects.base.Effect`,
declared in its metadata under the entry-point group ``mountcal.effects``::

    [project.entry-points."mountcal.effects"]
    quadratic = "my_package.quadratic:Quadratic"

The static model, the model-selection loop, ``--model``, the report and ``rotate`` then use it
with no other change. This module imports no numerical library, nor ``importlib.metadata`` until
asked for the effects of other packages: the CLI builds its parser with :data:`BUILTIN`.
"""

from __future__ import annotations

import importlib
from functools import cache
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterable

    from mountcal.core.conventions import FloatArray
    from mountcal.core.plugins import Plugin
    from mountcal.core.result import Calibration, EffectValue
    from mountcal.estimate.effects.base import Effect

GROUP = "mountcal.effects"
BASE: tuple[str, ...] = ("rotation", "slope")  # the terms of every model, before its effects (the paper's model)
# Built-in effects, in the order --model lists them: module mountcal.estimate.effects.<name>, class EFFECT.
BUILTIN = ("bias", "temperature", "gravity", "site_slope", "scale")


def names() -> tuple[str, ...]:
    """Every registered effect's name, without importing any of them."""
    from mountcal.core.plugins import entry_points_of  # importlib.metadata: more than the CLI's help may take

    extra = tuple(p.name for p in entry_points_of(GROUP) if p.name not in BUILTIN)
    return BUILTIN + extra


@cache
def _builtin() -> dict[str, Effect]:
    return {name: importlib.import_module(f"{__name__}.{name}").EFFECT for name in BUILTIN}


@cache
def registered() -> dict[str, Effect]:
    """Every effect by name: the built-in ones, then those of the ``mountcal.effects`` entry points."""
    from mountcal.core.plugins import entry_points_of

    out = dict(_builtin())
    for plugin in entry_points_of(GROUP):
        if plugin.name not in out:  # a built-in name cannot be replaced from outside
            out[plugin.name] = _effect(plugin)
    return out


def _effect(plugin: Plugin) -> Effect:
    """The effect a plugin names; a package whose effect cannot be used is refused by name."""
    from mountcal.core.errors import InputError

    obj = plugin.load()  # an import failure is refused by name there
    try:
        effect = obj() if isinstance(obj, type) else obj
    except TypeError as err:
        effect = err
    from mountcal.estimate.effects.base import Effect

    if not isinstance(effect, Effect) or effect.name != plugin.name:
        raise InputError(
            f"plugin {plugin.name!r} ({plugin.value}) of the package {plugin.package or '?'}",
            f"a mountcal effect named {plugin.name!r} (mountcal.estimate.effects.base.Effect)",
            repr(effect),
            "Fix or uninstall that package; mountcal cannot fit a model with an effect it cannot load.",
        )
    return effect


def get(name: str) -> Effect:
    builtin = _builtin()
    return builtin[name] if name in builtin else registered()[name]


def chain(terms: tuple[str, ...]) -> list[Effect]:
    """The effects among ``terms``, in the order the prediction applies them."""
    effects = registered()
    chosen = [effects[t] for t in terms if t in effects]
    return sorted(chosen, key=lambda e: e.order)


def _one(flag: str) -> Effect:
    """The built-in effect with ``flag`` set: a role one effect plays (another package's cannot take it)."""
    return next(e for e in _builtin().values() if getattr(e, flag))


def offset() -> Effect:
    """The constant offset every sensor has: the model a plan is made for, the one every other effect's
    separability is also judged with, and the one the v2 result's ``bias_mps2`` field holds."""
    return _one("offset")


def site_term() -> str:
    """The term that gives each site its own slope (a design on several slopes is fitted with it)."""
    return _one("slope_per_site").name


def gravity_term() -> str:
    """The term that fits local gravity (a result lists it too when gravity was known from the position)."""
    return next(e.name for e in _builtin().values() if e.gravity_index is not None)


def offset_fields(effects: Iterable[EffectValue], widen: float = 1.0) -> tuple[FloatArray | None, FloatArray | None]:
    """The v2 result's ``bias_mps2`` and ``uncertainty.bias_mps2`` (σ times ``widen``) from a fit's effect values:
    the one place that fills those fields (None, None: no offset fitted)."""
    import numpy as np

    found = next((e for e in effects if e.name == offset().report_key), None)
    if found is None:
        return None, None
    return np.array(found.value, dtype=float), np.array(found.sigma, dtype=float) * widen


def offset_of(calibration: Calibration) -> EffectValue | None:
    """The offset of a calibration as an ``effects`` entry: the one place that reads the v2 fields ``bias_mps2`` and
    ``uncertainty.bias_mps2`` (the σ there is the total one, widened by the Birge ratio; a file or a value built by
    hand may also hold the fields without the entry)."""
    from dataclasses import replace

    import numpy as np

    off = offset()
    if calibration.bias_mps2 is None:
        return calibration.effect(off.report_key)
    sigma = calibration.bias_sigma_mps2
    entry = off.report(calibration.bias_mps2, np.zeros(3) if sigma is None else sigma, ("x", "y", "z"))
    return replace(entry, sigma=(None, None, None)) if sigma is None else entry


def fitted(calibration: Calibration) -> dict[str, EffectValue]:
    """Every fitted effect of a calibration by its ``report_key``, the offset from the v2 fields when ``effects``
    lacks it."""
    out = {e.name: e for e in calibration.effects}
    off = offset_of(calibration)
    if off is not None:
        out.setdefault(off.name, off)
    return out


def reporting(keys: Iterable[str]) -> dict[str, Effect]:
    """The effects by their ``report_key``, every one of ``keys`` included when registered (the entry points are
    only scanned when a key is none of the built-in effects')."""
    effects = {e.report_key: e for e in _builtin().values()}
    if not set(keys) <= effects.keys():
        effects = {e.report_key: e for e in registered().values()}
    return effects


def summary_lines(calibration: Calibration) -> list[str]:
    """The text summary's line of every fitted effect that has one, in the order of the prediction."""
    off = offset_of(calibration)  # its σ as the result states it (the total)
    reported = {**fitted(calibration), **({off.name: off} if off is not None else {})}
    effects = reporting(reported)
    lines = []
    for effect in sorted((effects[k] for k in reported if k in effects), key=lambda e: e.order):
        line = effect.summary(reported[effect.report_key])
        if line is not None:
            lines.append(line)
    return lines


def owner(param: str, table_parameters: dict[str, tuple[str, ...]]) -> str:
    """The group a parameter belongs to (an effect's name, or rotation, slope, headings)."""
    for prefix, group in (("rot_", "rotation"), ("slope", "slope"), ("beta_", "headings")):
        if param.startswith(prefix):
            return group
    for name, params in table_parameters.items():
        if param in params:
            return name
    return param


def apply_corrections(acc_s: FloatArray, calibration: Calibration, *, inverse: bool = False) -> FloatArray:
    """Samples (n, 3, m/s², sensor frame) with every fitted sensor effect of ``calibration`` undone, in the
    reverse order of the prediction (what ``rotate`` applies before the rotation); with ``inverse``, put
    back in the order of the prediction (corrected samples as the sensor reads them).

    Raises
    ------
    InputError
        The calibration's ``effects`` cannot be applied (edited or damaged values).
    """
    from mountcal.core.errors import InputError

    reported = fitted(calibration)
    effects = reporting(reported)
    for effect in sorted(effects.values(), key=lambda e: e.order, reverse=not inverse):
        if effect.report_key in reported and effect.kind == "sensor":  # a property of the site is in no sample
            undo = effect.restore if inverse else effect.correct
            try:
                acc_s = undo(acc_s, reported[effect.report_key])
            except ValueError as err:
                raise InputError(
                    f"calibration of {calibration.provenance.input or 'unknown input'}",
                    f"fitted values of the effect {effect.name} that can be undone on samples",
                    str(err),
                    "Re-run calibrate to get an intact result file.",
                ) from err
    return acc_s


def __getattr__(name: str) -> Any:
    """``Effect`` on first use (it imports the result types, and with them numpy)."""
    if name == "Effect":
        from mountcal.estimate.effects.base import Effect

        return Effect
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "BASE",
    "BUILTIN",
    "GROUP",
    "Effect",
    "apply_corrections",
    "chain",
    "fitted",
    "get",
    "gravity_term",
    "names",
    "offset",
    "offset_fields",
    "offset_of",
    "registered",
    "reporting",
    "site_term",
    "summary_lines",
]
