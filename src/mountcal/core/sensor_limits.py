"""The sensor limits a result states behind its systematic σ (light: the sensor spec reader uses it)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SensorLimits:
    """The sensor limits behind the systematic σ, as their source states them: a datasheet's ± limits
    (a spec file or the default class: ``scale``, ``cross_axis``, ``bias_mps2``), or a triad
    calibration's σ per fitted parameter (``triad_sigma``) with the datasheet's σ of those it did not fit
    (``from_spec``)."""

    source: str
    bias_tempco_mps2_per_c: float  # ± m/s² per °C
    heading_deg: float  # ± the protocol's headings against the fall line
    scale: float | None = None  # ± fraction
    cross_axis: float | None = None  # ± fraction
    bias_mps2: float | None = None  # ± m/s²
    triad_sigma: dict[str, float] | None = None  # 1σ by parameter name
    from_spec: dict[str, float] | None = None  # 1σ by parameter name
