"""What an effect of the static model is: the :class:`Effect` protocol and a base with its defaults.

The static model predicts each stop's specific force as a chain: the base force ``p = R_vsᵀ f_v(α, β; g)``
goes through every effect of the model in ``order`` (lower first), each one mapping ``p`` to its
output. An effect says how (``apply``), with the derivatives the fit needs; everything else about it —
its stop-table columns, when the model-selection loop may try it, how it is reported, summarised and how
``rotate`` undoes it on samples, its datasheet limits for the systematic σ, the residual test that names it —
lives in the same class, in one file under :mod:`mountcal.estimate.effects`. Code outside that folder asks
these members and never tests an effect's name (tests/test_effect_registry.py scans for it).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from mountcal.core.result import EffectValue

if TYPE_CHECKING:
    from mountcal.core.conventions import FloatArray
    from mountcal.io.sensor_spec import SensorSpec
    from mountcal.stops.table import StopTable

    Applied = tuple[FloatArray, FloatArray, FloatArray | None]


@runtime_checkable
class Effect(Protocol):
    """One effect of the static model (docs/conventions.md §6)."""

    name: str  # the term ``--model`` names
    meaning: str  # one line for the CLI help and docs/commands.md
    needs: tuple[str, ...]  # stop-table columns it needs
    order: int  # its place in the prediction chain (gravity 0, scale 10, additive 20)
    requires: tuple[str, ...]  # terms added with it (a bias drift has an offset too)
    report_key: str  # its name in the result's ``effects``
    unit: str  # the unit of its reported values
    kind: str  # "sensor": an error of the accelerometer; "site": a property of the place the stops were made at
    offset: bool  # the constant offset every sensor has: the planner's model, and every effect is also judged with it
    slope_per_site: bool  # it gives each site its own slope (the designs of the observability check need it)
    gravity_index: int | None  # where its values hold local gravity (m/s²), if it fits gravity
    inseparable_note: str | None  # the note of the result when the loop declined it as not separable

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        """Names of its parameters (unique across effects)."""
        ...

    def initial(self, table: StopTable, g_mps2: float) -> FloatArray:
        """The values it starts from (no effect)."""
        ...

    def apply(self, table: StopTable, values: FloatArray, p: FloatArray, g0_mps2: float) -> Applied:
        """``p`` (n, 3) through the effect: the output, its derivative by the values (n, 3, k) and by ``p``
        ((3, 3) or (n, 3, 3); None for the identity)."""
        ...

    def candidate(self, table: StopTable, gravity_known: bool) -> bool:
        """May the model-selection loop try it on this table?"""
        ...

    def extra(self, table: StopTable) -> int:
        """The number of parameters it adds to the model."""
        ...

    def implausible(self, values: FloatArray, g_mps2: float) -> str | None:
        """Why fitted values are no such effect (a sign or unit error), or None."""
        ...

    def covered_by(self) -> tuple[str, str] | None:
        """(term, why): a term that explains the same thing when it is separable; it is tried instead."""
        ...

    def report(self, values: FloatArray, sigma: FloatArray, names: tuple[str, ...]) -> EffectValue:
        """The fitted values ± 1σ as the result's ``effects`` entry."""
        ...

    def correct(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        """Samples (n, 3) with the effect removed, from its ``report`` entry (what ``rotate`` applies)."""
        ...

    def restore(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        """The inverse of :meth:`correct`: corrected samples as the sensor reads them."""
        ...

    def unusable(self, table: StopTable) -> str | None:
        """Why a fixed model cannot fit it on a table that has its columns (``needs stops at …``), or None."""
        ...

    def spec_limits(self, spec: SensorSpec) -> dict[str, float]:
        """Its parameters' ± limits on a datasheet (the systematic σ's prior), by parameter name; empty: none."""
        ...

    def label(self, parameter: str) -> str:
        """What a person calls the error one of its parameters is (the systematic note lists them)."""
        ...

    def covariate(self, table: StopTable) -> tuple[str, FloatArray] | None:
        """(what, x): the residual test against a logged covariate that names it (its test carries the effect's
        name; x has one column per direction, one row per stop), or None."""
        ...

    def transfer(
        self, values: Mapping[str, FloatArray], fitted_on: StopTable, predict_on: StopTable
    ) -> dict[str, FloatArray]:
        """Values of the model (by effect) that predict ``predict_on`` as the fit did ``fitted_on`` (a subset of
        it), when its values are relative to the table they were fitted on; only those it changes."""
        ...

    def summary(self, reported: EffectValue) -> str | None:
        """Its line in the text summary of a calibration, or None (not shown)."""
        ...


class BaseEffect:
    """Defaults for an effect: no columns, always a candidate, plausible, and nothing to undo on samples."""

    name = ""
    meaning = ""
    needs: tuple[str, ...] = ()
    order = 20
    requires: tuple[str, ...] = ()
    report_key = ""
    unit = ""
    kind = "sensor"
    offset = False
    slope_per_site = False
    gravity_index: int | None = None
    inseparable_note: str | None = None

    def parameters(self, table: StopTable) -> tuple[str, ...]:
        raise NotImplementedError

    def candidate(self, table: StopTable, gravity_known: bool) -> bool:
        return True

    def extra(self, table: StopTable) -> int:
        return len(self.parameters(table))

    def implausible(self, values: FloatArray, g_mps2: float) -> str | None:
        return None

    def covered_by(self) -> tuple[str, str] | None:
        return None

    def report(self, values: FloatArray, sigma: FloatArray, names: tuple[str, ...]) -> EffectValue:
        return EffectValue(
            name=self.report_key,
            unit=self.unit,
            components=self.components(names),
            value=tuple(float(v) for v in values),
            sigma=tuple(float(s) for s in sigma),
        )

    def components(self, names: tuple[str, ...]) -> tuple[str, ...]:
        """The labels of the reported values: the sensor axes for a vector, else the parameter names."""
        return ("x", "y", "z") if len(names) == 3 else names

    def correct(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        return acc_s

    def restore(self, acc_s: FloatArray, reported: EffectValue) -> FloatArray:
        return acc_s

    def unusable(self, table: StopTable) -> str | None:
        return None

    def spec_limits(self, spec: SensorSpec) -> dict[str, float]:
        return {}

    def label(self, parameter: str) -> str:
        return self.name

    def covariate(self, table: StopTable) -> tuple[str, FloatArray] | None:
        return None

    def transfer(
        self, values: Mapping[str, FloatArray], fitted_on: StopTable, predict_on: StopTable
    ) -> dict[str, FloatArray]:
        return {}

    def summary(self, reported: EffectValue) -> str | None:
        """``name (v ± σ, …) unit (components)``: every value with its 1σ."""
        if any(s is None for s in reported.sigma):
            return None
        shown = ", ".join(f"{v:+.4g} ± {s:.2g}" for v, s in zip(reported.value, reported.sigma, strict=True))
        return f"{self.name} ({shown}) {self.unit or '1'} ({', '.join(reported.components)})"


def reported_vector(reported: EffectValue, size: int) -> FloatArray:
    """The values of a reported effect, checked (a result file may have been edited)."""
    import numpy as np

    value = np.asarray(reported.value, dtype=float)
    if value.shape != (size,) or not np.all(np.isfinite(value)):
        raise ValueError(f"effects {reported.name} must be {size} finite numbers, found {value.tolist()}")
    return value
