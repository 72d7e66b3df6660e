"""The conventions of the inputs: each stated, checked or inferred here, once, for every reader and command.

A number that crosses into mountcal carries a convention its file may not spell out: what a heading
is measured from (the slope's uphill direction, an unknown common offset, or north as a compass
heading with the slope's uphill azimuth), in which unit a heading is (degrees or radians), an
acceleration (m/s² or g), gravity (m/s²) and a noise (mg); and which way the sensor's axes point (a
signed permutation that maps the device's axes onto a right-handed sensor frame). Each function
here returns the value in mountcal's convention (docs/conventions.md) together with a
:class:`~mountcal.core.result.Convention` saying whether it was **stated** (and by what option, column or
file), **inferred** from the data (and from what), or assumed by **default** (and that it was); the
summary prints them and the result keeps them in ``provenance.conventions``. An inference the data
cannot support is refused with the option that states the convention.

The frames and angles themselves (and the only Euler conversion) are :mod:`mountcal.core.conventions`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from mountcal.core.conventions import G_N, FloatArray
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.ranges import QUANTITIES
from mountcal.core.result import Convention

Headings = Literal["uphill", "relative", "none"]
HeadingUnit = Literal["deg", "rad"]

# --------------------------------------------------------------------------- axes


@dataclass(frozen=True)
class AxisMap:
    """A signed permutation from the device's axes to the sensor frame: sensor axis i = ``matrix[i] · device``.

    ``text`` is its canonical spelling (``"x,-y,z"``: sensor x is device x, sensor y is device −y, …).
    A map with determinant −1 is a reflection: it states that the device's own triad is left-handed
    (one axis reversed, as NovAtel RAWIMU's y), and makes it right-handed.
    """

    text: str
    matrix: FloatArray

    @property
    def identity(self) -> bool:
        return bool(np.array_equal(self.matrix, np.eye(3)))

    @property
    def reflection(self) -> bool:
        return bool(np.linalg.det(self.matrix) < 0)

    def apply(self, vectors: FloatArray) -> FloatArray:
        """Vectors (n, 3) in device axes → sensor axes (a column copy with signs: exact)."""
        return np.asarray(vectors, dtype=float) @ self.matrix.T

    def apply_cov(self, cov: FloatArray) -> FloatArray:
        """Covariances (n, 3, 3) in device axes → sensor axes."""
        return np.asarray(np.einsum("ij,njk,lk->nil", self.matrix, cov, self.matrix), dtype=np.float64)

    def after(self, first: AxisMap) -> AxisMap:
        """This map applied to what ``first`` produced (``first`` then this)."""
        return axis_map_of(self.matrix @ first.matrix)

    def describe(self) -> str:
        return self.text + (" (a reflection: the device's own triad is left-handed)" if self.reflection else "")


IDENTITY_AXES = "x,y,z"


def parse_axes(text: str, where: str = "--axes") -> AxisMap:
    """A signed permutation of x, y, z such as ``"x,-y,z"`` or ``"-y,x,z"`` (sensor axes x, y, z in turn).

    Raises
    ------
    InputError
        Not three distinct letters x, y, z each with an optional sign.
    """
    tokens = [t.strip().lower() for t in str(text).split(",")]
    parsed = [re.fullmatch(r"([+-]?)([xyz])", t) for t in tokens]
    letters = [m.group(2) for m in parsed if m]
    if len(tokens) != 3 or not all(parsed) or sorted(letters) != ["x", "y", "z"]:
        raise InputError(
            where,
            'axes as a signed permutation of x, y, z such as "x,-y,z" or "-y,x,z"',
            repr(text),
            "List, for the sensor axes x, y, z in turn, the device axis (with its sign) that points along it.",
        )
    matrix = np.zeros((3, 3))
    for row, match in enumerate(parsed):
        assert match is not None
        matrix[row, "xyz".index(match.group(2))] = -1.0 if match.group(1) == "-" else 1.0
    return axis_map_of(matrix)


def axis_map_of(matrix: FloatArray) -> AxisMap:
    """The :class:`AxisMap` of a signed permutation matrix."""
    parts = []
    for row in np.asarray(matrix, dtype=float):
        j = int(np.argmax(np.abs(row)))
        parts.append(("-" if row[j] < 0 else "") + "xyz"[j])
    return AxisMap(",".join(parts), np.asarray(matrix, dtype=float))


def negated(axis: int) -> AxisMap:
    """The map that reverses one sensor axis (0, 1, 2: x, y, z)."""
    m = np.eye(3)
    m[axis, axis] = -1.0
    return axis_map_of(m)


def axes_convention(given: AxisMap | None, reader_map: str, by: str) -> Convention:
    """How the sensor frame was made from the device's axes: ``--axes`` (after the reader's map; ``x,y,z`` states
    that the axes as logged are right-handed), the reader's own map (a CAN mapping's ``axes``, a format's documented
    frame), or the axes as logged, assumed right-handed."""
    if given is not None:
        before = "" if reader_map == IDENTITY_AXES else f", after the reader's {reader_map}"
        return Convention("axes", given.describe(), "stated", f"{option('axes')}{before}")
    if reader_map != IDENTITY_AXES:
        return Convention("axes", reader_map, "stated", by)
    return Convention(
        "axes",
        IDENTITY_AXES,
        "default",
        f"the axes as logged, taken as right-handed ({option('axes')} states another map; checked where the "
        "data can tell: the stops' headings, turns)",
    )


# --------------------------------------------------------------------------- heading reference

HEADING_REF = "heading_ref"  # the stop table's column stating what beta_deg is measured from
_STRENGTH = {"none": 0, "relative": 1, "uphill": 2}


def heading_reference(
    marker: Iterable[object] | None,
    given: Headings | None,
    where: str,
    beta_deg: FloatArray | None = None,
    compass_deg: FloatArray | None = None,
) -> tuple[Headings, Convention]:
    """What a stop table's ``beta_deg`` is measured from: its ``heading_ref`` column and/or the option.

    An option may say less than the column (``relative`` or ``none`` for a table marked ``uphill``:
    information is dropped, never invented); one that says more (``uphill`` for a ``relative`` table)
    contradicts the table and is refused. A table without the column is read from its content when
    it shows how β were made — β = azimuth − ``heading_deg`` exactly in every row (what ``mountcal stops``
    wrote before the column existed: azimuth 0 for relative headings) — else (by hand) as from uphill,
    and the result says that this was assumed.
    """
    stated: Headings | None = None
    if marker is not None:
        values = {str(v).strip().lower() for v in marker}
        if len(values) != 1 or not values <= {"uphill", "relative", "none"}:
            raise InputError(
                where,
                f"one value in the column {HEADING_REF}: uphill or relative",
                ", ".join(sorted(values)) or "an empty column",
                f"Give every row the same {HEADING_REF} (uphill: beta_deg from the slope's uphill direction; relative: "
                f"with an unknown common offset), or drop the column and say it with {option('headings')}.",
            )
        stated = values.pop()  # type: ignore[assignment]
    if stated is None and given is None and beta_deg is not None and compass_deg is not None:
        inferred = _from_compass(np.asarray(beta_deg, dtype=float), np.asarray(compass_deg, dtype=float))
        if inferred is not None:
            return inferred
    if stated is None and given is None:
        return "uphill", Convention(
            "heading_reference",
            "uphill",
            "default",
            f"the table states no {HEADING_REF}: beta_deg taken as from the slope's uphill direction, "
            f"counter-clockwise (state it: {option('headings', 'uphill')}, {option('headings', 'relative')} if it is "
            f"not, or a {HEADING_REF} column)",
        )
    if stated is None:
        assert given is not None
        return given, Convention("heading_reference", given, "stated", option("headings"))
    if given is None or given == stated:
        return stated, Convention("heading_reference", stated, "stated", f"the table's column {HEADING_REF}")
    if _STRENGTH[given] < _STRENGTH[stated]:
        return given, Convention(
            "heading_reference", given, "stated", f"{option('headings')} (the table's {HEADING_REF} says {stated})"
        )
    raise InputError(
        where,
        f"headings as the table's column {HEADING_REF} states them ({stated})",
        f"{option('headings', given)}, which contradicts it",
        f"If beta_deg really is measured from the slope's uphill direction, set {HEADING_REF} to {given} in the "
        f"table; relative headings with the compass column heading_deg become uphill with {option('uphill_azimuth')}.",
    )


def _from_compass(beta: FloatArray, compass: FloatArray) -> tuple[Headings, Convention] | None:
    """β made from the compass column by β = azimuth − heading (to rounding): relative for azimuth 0."""
    total = np.exp(1j * np.radians(beta + compass))
    azimuth = float(np.degrees(np.angle(total.mean())) % 360.0)
    if not np.all(np.abs(np.angle(total * np.exp(-1j * np.radians(azimuth)))) < 1e-8):
        return None
    if min(azimuth, 360.0 - azimuth) < 1e-6:
        return "relative", Convention(
            "heading_reference",
            "relative",
            "inferred",
            f"beta_deg = −heading_deg in every row (no {HEADING_REF} column): relative headings as `mountcal stops` "
            "writes them without the slope's uphill azimuth",
        )
    return "uphill", Convention(
        "heading_reference",
        "uphill",
        "inferred",
        f"beta_deg = {azimuth:.6g} − heading_deg in every row (no {HEADING_REF} column): β from the compass heading "
        f"with an uphill azimuth of {azimuth:.6g}°",
    )


def compass_to_beta(heading_deg: FloatArray, uphill_azimuth_deg: float) -> FloatArray:
    """β (counter-clockwise from uphill) from compass headings (clockwise from north)."""
    return (uphill_azimuth_deg - np.asarray(heading_deg, dtype=float)) % 360.0


def uphill_azimuth(azimuth_deg: float, channel: str) -> tuple[Convention, Convention]:
    """The conventions of β computed from compass headings (``channel``) and the slope's uphill azimuth."""
    return (
        Convention(
            "heading_reference",
            "uphill",
            "stated",
            f"{option('uphill_azimuth')} {azimuth_deg:g} with {channel} (a compass heading, clockwise from north)",
        ),
        Convention(
            "uphill_azimuth",
            f"{azimuth_deg:g}",
            "stated",
            f"{option('uphill_azimuth')}, taken from the same north as {channel} (true or magnetic north: they differ "
            "by the local declination, which turns yaw by as much; the data cannot tell)",
        ),
    )


def beta_from_compass(
    heading_deg: FloatArray | None, uphill_azimuth_deg: float, where: str
) -> tuple[FloatArray, tuple[Convention, ...]]:
    """β of a stop table from its compass column ``heading_deg`` and the slope's uphill azimuth."""
    if heading_deg is None:
        raise InputError(
            where,
            f"the compass column heading_deg with {option('uphill_azimuth')}",
            "no heading_deg column",
            f"Give beta_deg from the uphill direction instead, or leave {option('uphill_azimuth')} out.",
        )
    return compass_to_beta(heading_deg, uphill_azimuth_deg), uphill_azimuth(
        uphill_azimuth_deg, "the column heading_deg"
    )


# --------------------------------------------------------------------------- heading unit

TWO_PI = 2.0 * math.pi
_RADIAN_SLACK = 1e-6


def headings_in_degrees(
    values: FloatArray, unit: HeadingUnit | None, where: str, column: str = "beta_deg"
) -> tuple[FloatArray, Convention]:
    """Headings in degrees, and how their unit is known.

    Stated (``heading_unit``): converted when radians. Not stated: the column's name says degrees, and
    that is checked — headings that all lie within ±2π while differing are radians, or headings that span
    under 6.3° (no circle a calibration can use): either way they are refused with the option.
    """
    v = np.asarray(values, dtype=float)
    if unit == "rad":
        return np.degrees(v), Convention("heading_unit", "rad", "stated", option("heading_unit", "rad"))
    if unit == "deg":
        return v, Convention("heading_unit", "deg", "stated", option("heading_unit", "deg"))
    finite = v[np.isfinite(v)]
    if np.unique(np.round(finite, 9)).size >= 2 and np.all(np.abs(finite) <= TWO_PI + _RADIAN_SLACK):
        span = float(np.ptp(finite))
        raise InputError(
            where,
            f"headings {column} in degrees",
            f"values that all lie within ±2π (from {finite.min():.4g} to {finite.max():.4g}): radians, it seems",
            f"State the unit: {option('heading_unit', 'rad')} converts them; {option('heading_unit', 'deg')} keeps "
            f"them as degrees (they then span only {span:.3g}°, too little for a calibration).",
        )
    return v, Convention(
        "heading_unit",
        "deg",
        "stated",
        f"the column name {column} (checked: not all within ±2π, as radians would be)",
    )


def heading_channel_unit(
    t_s: FloatArray, heading: FloatArray, yaw_turned_deg: float | None, unit: HeadingUnit | None, where: str
) -> tuple[float, Convention]:
    """The factor that puts a log's heading channel in degrees, and how its unit is known.

    Not stated: a channel that stays within ±2π is radians when it wraps by 2π (a step of more than π
    between neighbouring samples) or when the gyro turned the vehicle by more than 30° while the channel
    moved less than 2π; then it is refused with the option. ``yaw_turned_deg``: the span of the gyro's
    integrated rate about the mean gravity (None without a gyro).
    """
    if unit == "rad":
        return math.degrees(1.0), Convention("heading_unit", "rad", "stated", option("heading_unit", "rad"))
    if unit == "deg":
        return 1.0, Convention("heading_unit", "deg", "stated", option("heading_unit", "deg"))
    h = np.asarray(heading, dtype=float)
    h = h[np.isfinite(h)]
    if h.size >= 2 and np.ptp(h) > 0 and np.all(np.abs(h) <= TWO_PI + _RADIAN_SLACK):
        steps = np.abs(np.diff(h))
        wraps = bool(np.any((steps > math.pi) & (steps <= TWO_PI + _RADIAN_SLACK)))
        turned = yaw_turned_deg is not None and yaw_turned_deg > 30.0
        if wraps or turned:
            why = "it wraps by 2π" if wraps else f"the gyro turned the vehicle by {yaw_turned_deg:.0f}°"
            raise InputError(
                where,
                "a heading channel heading_deg in degrees (compass, clockwise from north)",
                f"values within ±2π (from {h.min():.4g} to {h.max():.4g}) while {why}: radians, it seems",
                f"State the unit: {option('heading_unit', 'rad')} converts it; {option('heading_unit', 'deg')} keeps "
                "it as degrees.",
            )
    return 1.0, Convention(
        "heading_unit", "deg", "inferred", "the heading channel's range (not within ±2π while the vehicle turns)"
    )


# --------------------------------------------------------------------------- quantities with units

# An acceleration option: a number with an optional unit suffix. A bare number is in the option's unit
# and must lie in its plausible range: outside it, the unit is asked for (1 is g, not m/s²).
_ACC_UNITS = {"m/s2": 1.0, "m/s²": 1.0, "mps2": 1.0, "m/s^2": 1.0, "g": G_N, "mg": 1e-3 * G_N, "ug": 1e-6 * G_N}
_ACC_UNITS["µg"] = _ACC_UNITS["ug"]
GRAVITY_RANGE_MPS2 = (QUANTITIES["gravity_mps2"].lo, QUANTITIES["gravity_mps2"].hi)  # 9.70–9.90: anywhere on roads
NOISE_RANGE_MG = (0.05, 200.0)  # a bare --noise (mg per sample): below is a g or m/s² value, above no sensor


@dataclass(frozen=True)
class Quantity:
    """An acceleration option with units: its key (for :func:`option`), unit, plausible range, an example."""

    key: str
    what: str
    unit: str  # the unit of a bare number, one of _ACC_UNITS
    plausible: tuple[float, float]  # in ``unit``
    suffix_plausible: bool  # whether a value given with a unit must also lie in ``plausible``
    example: str
    limit: str  # its physical range in mountcal.core.ranges (in ``unit``): any value, with a unit or not, lies in it


GRAVITY = Quantity("gravity", "local gravity", "m/s2", GRAVITY_RANGE_MPS2, True, "9.81", "gravity_mps2")
NOISE = Quantity("noise", "the noise per sample (1σ per axis)", "mg", NOISE_RANGE_MG, False, "5", "noise_mg")


def parse_quantity(text: str | float, q: Quantity) -> tuple[float, Convention]:
    """The value of ``q`` in its unit from ``"9.81"``, ``"1g"``, ``"5 mg"``, ``"0.05m/s2"``.

    Raises
    ------
    InputError
        Not a finite positive number; an unknown unit; a bare number outside the plausible range
        (the message asks for the unit and names the one the number fits).
    """
    raw = str(text).strip()
    match = re.fullmatch(r"([-+0-9.eE]+)\s*([a-zA-Zµ/²^0-9]*)", raw)
    try:
        number = float(match.group(1)) if match else float("nan")
    except ValueError:
        number = float("nan")
    suffix = match.group(2).lower() if match else ""
    lo, hi = q.plausible
    expected = f"{q.what} in {q.unit}: a bare number from {lo:g} to {hi:g}, or a number with its unit (g, mg, m/s2)"
    if not math.isfinite(number) or number <= 0 or (suffix and suffix not in _ACC_UNITS):
        raise InputError(option(q.key), expected, repr(raw), f"For example {option(q.key, q.example)}.")
    value = number * _ACC_UNITS[suffix or q.unit] / _ACC_UNITS[q.unit]
    if not suffix and not lo <= value <= hi:
        fits = [
            u for u in ("g", "m/s2", "mg") if u != q.unit and lo <= number * _ACC_UNITS[u] / _ACC_UNITS[q.unit] <= hi
        ]
        if fits:
            as_unit = number * _ACC_UNITS[fits[0]] / _ACC_UNITS[q.unit]
            found = f"{raw}, outside that range; in {fits[0]} it would be {as_unit:.4g} {q.unit}"
            todo = f"Write it with its unit: {option(q.key, raw + fits[0])}."
        elif QUANTITIES[q.limit].holds(value):
            found = f"{raw}, outside that range in any unit"
            todo = f"Check the value; if it really is {raw} {q.unit}, write {option(q.key, raw + q.unit)}."
        else:
            found = f"{raw}, outside that range in any unit"
            todo = f"Check the value: {q.what} is {QUANTITIES[q.limit].expected()}."
        raise InputError(option(q.key), expected, found, todo)
    if suffix and q.suffix_plausible and not lo <= value <= hi:
        raise InputError(
            option(q.key), f"{q.what} from {lo:g} to {hi:g} {q.unit}", f"{raw} = {value:.5g} {q.unit}", "Check it."
        )
    limit = QUANTITIES[q.limit]
    if not limit.holds(value):  # a unit can carry a number out of any physical range ("1e308g")
        raise InputError(option(q.key), f"{q.what}: {limit.expected()}", f"{raw} = {value:.5g} {q.unit}", "Check it.")
    by = f"{option(q.key)} {raw}" + ("" if suffix else f" (a bare number: {q.unit}, checked to lie in {lo:g}–{hi:g})")
    return value, Convention(q.key, f"{value:.6g} {q.unit}", "stated", by)


def check_gravity_value(g: float, where: str) -> None:
    """Refuse a given local gravity outside :data:`GRAVITY_RANGE_MPS2` (a value in g, or no Earth gravity)."""
    lo, hi = GRAVITY_RANGE_MPS2
    if not (math.isfinite(g) and lo <= g <= hi):
        hint = " (1 g is 9.80665 m/s²)" if math.isfinite(g) and 0.9 <= g <= 1.1 else ""
        raise InputError(
            where,
            f"local gravity in m/s², between {lo:g} and {hi:g}",
            f"{g!r}{hint}",
            f"Give it in m/s² (e.g. {option('gravity', '9.81')}), or with its unit ({option('gravity', '1g')}).",
        )


# --------------------------------------------------------------------------- acceleration unit of a stop table


def acceleration_unit(unit: str, stated: bool) -> Convention:
    """The unit of a stop table's ``ax, ay, az`` (and ``sx, sy, sz``): stated, or the default m/s²;
    either way checked by the magnitudes (a static reading is |g|)."""
    if stated:
        return Convention("acceleration_unit", unit, "stated", f"{option('unit', unit)} (checked: |a| ≈ 1 g)")
    return Convention(
        "acceleration_unit",
        unit,
        "default",
        f"m/s² unless {option('unit', 'g')} (checked: the stops' |a| lies near 9.8 m/s², not near 1)",
    )


def axes_stated(conventions: Sequence[Convention], where: str = "axes") -> tuple[Convention, AxisMap] | None:
    """The ``axes`` convention among ``conventions`` and the map its value states (its text before any
    description: ``"x,-y,z (a reflection: …)"``), or None without one; ``where`` names it in a refusal."""
    c = next((c for c in conventions if c.name == "axes"), None)
    return None if c is None else (c, parse_axes(c.value.split(" ")[0], where))


def stated_axes(conventions: Sequence[Convention]) -> AxisMap | None:
    """The ``axes`` map a result was made with (None: the axes as read)."""
    found = axes_stated(conventions)
    if found is None or found[0].how != "stated" or not found[0].by.startswith(option("axes")):
        return None
    return found[1]


def check_same_axes(conventions: Sequence[Convention], given: AxisMap | None, where: str) -> None:
    """Refuse applying a calibration to samples read with other axes than the ones it was made with."""
    made = stated_axes(conventions)
    same = (made is None or made.identity) if given is None else (made is not None and made.text == given.text)
    if not same and not (made is None and given is not None and given.identity):
        was = "the axes as logged" if made is None else made.text
        now = "the axes as logged" if given is None or given.identity else given.text
        raise InputError(
            where,
            f"the log read with the axes the calibration was made with ({was})",
            now,
            f"Give the same map: {option('axes', made.text) if made is not None else 'no ' + option('axes')}.",
        )


def stop_table_reading(conventions: Sequence[Convention]) -> dict[str, object]:
    """The arguments of :func:`mountcal.stops.table.read_stop_table` that read a stop table again as a result's
    ``provenance.conventions`` say it was read (what was stated is stated again; defaults stay defaults)."""
    by = {c.name: c for c in conventions}
    out: dict[str, object] = {}
    if (c := by.get("acceleration_unit")) is not None and c.how == "stated":
        out["unit"] = c.value
    if (c := by.get("uphill_azimuth")) is not None:
        out["uphill_azimuth_deg"] = float(c.value)
    elif (c := by.get("heading_reference")) is not None and c.how != "default":
        out["headings"] = c.value
    if (c := by.get("heading_unit")) is not None and c.by.startswith(option("heading_unit")):
        out["heading_unit"] = c.value
    if (c := by.get("axes")) is not None and c.how == "stated":
        out["axes"] = parse_axes(c.value.split(" ")[0])
    return out


def merged(*groups: Sequence[Convention]) -> tuple[Convention, ...]:
    """The conventions of several sources, the later replacing an earlier one of the same name."""
    out: dict[str, Convention] = {}
    for group in groups:
        for c in group:
            out[c.name] = c
    return tuple(out.values())


__all__ = [
    "HEADING_REF",
    "AxisMap",
    "Headings",
    "axes_convention",
    "beta_from_compass",
    "check_gravity_value",
    "compass_to_beta",
    "heading_channel_unit",
    "heading_reference",
    "headings_in_degrees",
    "merged",
    "parse_axes",
    "parse_quantity",
]
