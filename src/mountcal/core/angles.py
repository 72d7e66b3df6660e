"""The one value type of "the four mounting angles ± σ" (:class:`Angles`) and of one value per angle
(:class:`AngleValues`), with the one spelling of their flat columns where a table or message holds them flat.

Flat names (``roll_deg``, ``roll_sigma_deg``, …) are spelled here and in the formats' own modules only (the v2
result file in :mod:`mountcal.core.result`, the fleet tables' schema in :mod:`mountcal.fleet.store`); a test
(tests/test_typed_result.py) fails when a dict spelling appears elsewhere.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

AngleName = Literal["roll", "pitch", "yaw", "slope"]
ANGLE_NAMES: tuple[AngleName, ...] = ("roll", "pitch", "yaw", "slope")


@dataclass(frozen=True)
class Angles:
    """Roll, pitch, yaw and slope in degrees with 1σ; None where the data do not determine them.

    The one value type of "the four angles ± σ" (a calibration's :attr:`Calibration.angles`, a model step's, the
    drive's :attr:`mountcal.estimate.driving.DrivingFit.angles`, a fleet table's row). A yaw the data cannot
    determine is None with its σ and the reason; a yaw is never a number without its σ, nor a slope.

    Where the angles are flat columns of a table or message (the fleet Parquet files, ``mountcal live``'s
    events), :meth:`columns` and :meth:`from_columns` are the one spelling of those columns.
    """

    roll_deg: float
    roll_sigma_deg: float | None
    pitch_deg: float
    pitch_sigma_deg: float | None
    yaw_deg: float | None
    yaw_sigma_deg: float | None
    yaw_reason: str | None
    slope_deg: float | None
    slope_sigma_deg: float | None

    def __post_init__(self) -> None:
        if self.yaw_deg is None and self.yaw_sigma_deg is not None:
            raise ValueError(f"yaw undetermined with a σ of {self.yaw_sigma_deg!r} (expected none)")
        if self.yaw_deg is not None and self.yaw_sigma_deg is None:
            raise ValueError(f"yaw {self.yaw_deg!r} without its σ (an undetermined yaw is None, with the reason)")
        if self.slope_deg is not None and self.slope_sigma_deg is None:
            raise ValueError(f"slope {self.slope_deg!r} without its σ")

    @property
    def yaw_determined(self) -> bool:
        return self.yaw_deg is not None

    def value(self, name: AngleName) -> float | None:
        """The angle of that name, degrees (None: not determined)."""
        return {"roll": self.roll_deg, "pitch": self.pitch_deg, "yaw": self.yaw_deg, "slope": self.slope_deg}[name]

    def sigma(self, name: AngleName) -> float | None:
        """Its 1σ, degrees (None: not determined)."""
        sigmas = (self.roll_sigma_deg, self.pitch_sigma_deg, self.yaw_sigma_deg, self.slope_sigma_deg)
        return dict(zip(ANGLE_NAMES, sigmas, strict=True))[name]

    def widened(self, factor: float) -> Angles:
        """The same angles with every σ times ``factor`` (a Birge ratio)."""
        return self.with_sigmas(self.sigmas.times(factor))

    def with_sigmas(self, sigmas: AngleValues) -> Angles:
        """The same angles with these σ (refused, as ever, where a determined yaw or slope would lose its σ)."""
        return Angles(
            self.roll_deg,
            sigmas.roll_deg,
            self.pitch_deg,
            sigmas.pitch_deg,
            self.yaw_deg,
            sigmas.yaw_deg,
            self.yaw_reason,
            self.slope_deg,
            sigmas.slope_deg,
        )

    @property
    def values(self) -> AngleValues:
        """The angles without their σ."""
        return AngleValues(self.roll_deg, self.pitch_deg, self.yaw_deg, self.slope_deg)

    @property
    def sigmas(self) -> AngleValues:
        """The 1σ of each angle."""
        return AngleValues(self.roll_sigma_deg, self.pitch_sigma_deg, self.yaw_sigma_deg, self.slope_sigma_deg)

    @staticmethod
    def value_column(name: AngleName) -> str:
        """The flat column of an angle: ``roll_deg``."""
        return f"{name}_deg"

    @staticmethod
    def sigma_column(name: AngleName) -> str:
        """The flat column of its 1σ: ``roll_sigma_deg``."""
        return f"{name}_sigma_deg"

    @staticmethod
    def column_names(slope: bool = True, reason: bool = True) -> tuple[str, ...]:
        """The flat columns, in order: each angle then its σ, the yaw's reason after the yaw's (``reason``),
        the slope's last (``slope``: the fleet's consensus tables have none)."""
        out: list[str] = []
        for name in ANGLE_NAMES if slope else ANGLE_NAMES[:3]:
            out += [Angles.value_column(name), Angles.sigma_column(name)]
            if name == "yaw" and reason:
                out.append(YAW_REASON)
        return tuple(out)

    def columns(self, slope: bool = True, reason: bool = True) -> dict[str, float | str | None]:
        """The flat columns of a table row or message (:meth:`column_names`), plain values."""
        cells: dict[str, float | str | None] = {}
        for name in ANGLE_NAMES if slope else ANGLE_NAMES[:3]:
            cells[Angles.value_column(name)] = self.value(name)
            cells[Angles.sigma_column(name)] = self.sigma(name)
            if name == "yaw" and reason:
                cells[YAW_REASON] = self.yaw_reason
        return cells

    @classmethod
    def from_columns(cls, row: Mapping[str, Any]) -> Angles:
        """The angles of a table row or message written by :meth:`columns` (a missing or NaN cell: None; a
        yaw or slope without its σ is refused, as by the constructor)."""

        def cell(key: str) -> Any:
            v = row.get(key)
            return None if v is None or (isinstance(v, float) and math.isnan(v)) else v

        def number(key: str) -> float | None:
            v = cell(key)
            return None if v is None else float(v)

        roll, pitch = number(cls.value_column("roll")), number(cls.value_column("pitch"))
        if roll is None or pitch is None:
            raise ValueError(f"a row without roll or pitch ({roll!r}, {pitch!r}): no angles")
        reason = cell(YAW_REASON)
        return cls(
            roll,
            number(cls.sigma_column("roll")),
            pitch,
            number(cls.sigma_column("pitch")),
            number(cls.value_column("yaw")),
            number(cls.sigma_column("yaw")),
            None if reason is None else str(reason),
            number(cls.value_column("slope")),
            number(cls.sigma_column("slope")),
        )


YAW_REASON = "yaw_reason"  # the column (and Calibration field) saying why yaw is not determined


@dataclass(frozen=True)
class AngleValues:
    """One value per angle, degrees, None where not determined: how far each angle moved from the
    previous model step, or the Cramér–Rao bound of each."""

    roll_deg: float | None
    pitch_deg: float | None
    yaw_deg: float | None
    slope_deg: float | None

    def __getitem__(self, name: str) -> float | None:
        """The value of an angle by its name (``roll``) or its column (``roll_deg``); a KeyError for another."""
        short = name.removesuffix("_deg")
        if short not in ANGLE_NAMES:
            raise KeyError(name)
        return {"roll": self.roll_deg, "pitch": self.pitch_deg, "yaw": self.yaw_deg, "slope": self.slope_deg}[short]

    def get(self, name: str) -> float | None:
        """:meth:`__getitem__`, None for a name that is no angle."""
        try:
            return self[name]
        except KeyError:
            return None

    def items(self, names: tuple[AngleName, ...] = ANGLE_NAMES) -> list[tuple[AngleName, float | None]]:
        """``(name, value)`` of each angle in ``names``."""
        return [(n, self[n]) for n in names]

    def named(self) -> dict[str, float | None]:
        """The values keyed by the angles' short names (``roll``): a JSON answer's spelling (``mountcal plan``)."""
        return dict(self.items())

    def times(self, factor: float) -> AngleValues:
        """Each value times ``factor`` (an undetermined one stays None)."""
        return AngleValues(*(None if v is None else v * factor for _, v in self.items()))
