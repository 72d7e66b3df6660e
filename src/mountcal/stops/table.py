"""The stop table: one row per static stop, the input of every estimator.

In memory it is a :class:`StopTable` of SI arrays with the full 3×3 covariance of each stop mean;
on disk (only there) CSV or Parquet with the columns named in :data:`COLUMNS`. Reading validates
everything a fit needs and says what is wrong; :func:`checked` applies the same checks to a table
built in memory (:func:`mountcal.stops.headings.tabulate`).

The noise columns: ``sx, sy, sz`` are the standard deviations of each stop's samples and ``n`` their
count, so ``s²/n`` is the variance of the mean for independent, unquantised samples.
``sx_mean, sy_mean, sz_mean`` (written by ``mountcal stops``) are the 1σ of each stop mean itself,
including correlated vibration and the quantisation floor (:mod:`mountcal.stops.detect`); when present they
are used instead of ``s/√n``. ``rxy, rxz, ryz`` (optional, with them) are the correlations between
the axes of a stop mean: the off-diagonal of its covariance.
"""

from __future__ import annotations

import hashlib
import io
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from mountcal.core import budget
from mountcal.core.conventions import G_N, FloatArray
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.core.option_names import option
from mountcal.core.output_suffix import check_output_suffix
from mountcal.core.paths import read_input_bytes
from mountcal.core.ranges import check_values
from mountcal.core.result import Convention
from mountcal.io.frame import FRAME_COLUMN
from mountcal.io.input_conventions import (
    HEADING_REF,
    AxisMap,
    HeadingUnit,
    acceleration_unit,
    axes_convention,
    beta_from_compass,
    heading_reference,
    headings_in_degrees,
    parse_axes,
    stated_axes,
)
from mountcal.io.input_conventions import Headings as Headings  # one definition, imported from here by many
from mountcal.io.inputs import check_parquet_rows, csv_columns
from mountcal.io.table.mapped import check_text, dialect
from mountcal.io.whole import parquet_end, text_bytes_end
from mountcal.stops.convention_columns import NAMES as CONVENTION_COLUMNS
from mountcal.stops.convention_columns import convention_columns, conventions_from_columns

# Column names of the stop table file.
BETA = "beta_deg"
ACC = ("ax", "ay", "az")
STD = ("sx", "sy", "sz")  # standard deviation of the samples of a stop
COUNT = "n"  # samples averaged
STD_MEAN = ("sx_mean", "sy_mean", "sz_mean")  # 1σ of the stop mean; when given, it is used instead of s/√n
CORR = ("rxy", "rxz", "ryz")  # correlations between the axes of a stop mean (with STD_MEAN)
PAIRS = ((0, 1), (0, 2), (1, 2))  # the axes of each CORR column
DURATION = "duration_s"
HEADING = "heading_deg"
TEMPERATURE = "temperature_c"
TIME = "t_s"
SITE = "site"
LAT = "lat_deg"
LON = "lon_deg"
ALT = "alt_m"
REQUIRED = ACC
AXES = "axes"  # the axis map already applied to ax, ay, az (by `mountcal stops --axes`)
FRAME = FRAME_COLUMN  # the frame of ax, ay, az when mountcal rotate had put the log in the vehicle (levelled) frame
OPTIONAL = (
    BETA, HEADING_REF, *STD, COUNT, *STD_MEAN, *CORR, TIME, DURATION, TEMPERATURE, SITE, LAT, LON, ALT, HEADING, AXES,
    *CONVENTION_COLUMNS,
)  # fmt: skip  # the last: the input conventions' columns (frame, acceleration_sign, …: stops.convention_columns)
COLUMNS = (BETA, HEADING_REF, *ACC, *OPTIONAL[2:])

# the physical range of each optional column (mountcal.core.ranges; the noise columns are checked where read)
_QUANTITY = {
    TIME: "time_s",
    DURATION: "file_duration_s",
    TEMPERATURE: "temperature_c",
    LAT: "lat_deg",
    LON: "lon_deg",
    ALT: "alt_m",
    HEADING: "heading_deg",
}
Unit = Literal["mps2", "g"]
MIN_STOPS = 3
GRAVITY_BAND = (0.7, 1.3)  # a static reading outside this fraction of g is not gravity
_HEAD_BYTES = 1 << 16  # the bytes a CSV's delimiter and decimal mark are told from (its header and first row)
_NO_GUESS = "Fill or remove those rows; mountcal does not guess missing stops."


@dataclass(frozen=True)
class StopTable:
    """Static stops of one parking session, in SI units and the sensor frame.

    Attributes
    ----------
    acc_s : ndarray, shape (n, 3)
        Mean specific force of each stop, m/s², sensor frame.
    beta_rad : ndarray, shape (n,), or None
        Heading of each stop in radians; None when unknown.
    headings : {"uphill", "relative", "none"}
        "uphill": β is measured from the slope's uphill direction (docs/conventions.md §2), so yaw is
        observable; "relative": β has an unknown common offset, so yaw is not; "none": no β.
    cov_s : ndarray, shape (n, 3, 3), or None
        Covariance of each stop mean, (m/s²)², when the table gives sample spreads and counts.
    std_s : ndarray, shape (n, 3), or None
        Standard deviation of each stop's samples (what a user sees in the data), m/s².
    count : ndarray, shape (n,), or None
        Samples averaged in each stop.
    temperature_c, t_s, duration_s, heading_deg, lat_deg, lon_deg, alt_m : ndarray, shape (n,), or None
    site : ndarray of str, shape (n,), or None
    source : str
        Where the table came from; ``sha256`` is the hash of that file's bytes.
    conventions : tuple of Convention
        How the table's conventions (heading reference and unit, acceleration unit, axes) are known:
        stated, inferred or assumed (:mod:`mountcal.io.input_conventions`); the result's provenance keeps them.
    """

    acc_s: FloatArray
    beta_rad: FloatArray | None = None
    headings: Headings = "uphill"
    cov_s: FloatArray | None = None
    temperature_c: FloatArray | None = None
    t_s: FloatArray | None = None
    site: np.ndarray | None = None
    lat_deg: FloatArray | None = None
    alt_m: FloatArray | None = None
    lon_deg: FloatArray | None = None
    std_s: FloatArray | None = None
    count: FloatArray | None = None
    duration_s: FloatArray | None = None
    heading_deg: FloatArray | None = None
    source: str = "<memory>"
    sha256: str = ""
    notes: tuple[str, ...] = field(default=())
    incomplete: tuple[str, ...] = ()  # the input was cut short and read in part (mountcal.io.whole)
    conventions: tuple[Convention, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.beta_rad is None and self.headings != "none":
            object.__setattr__(self, "headings", "none")

    def __len__(self) -> int:
        return int(self.acc_s.shape[0])

    def subset(self, keep: np.ndarray) -> StopTable:
        """The table restricted to the rows where ``keep`` is true (or to the given indices)."""

        n = len(self)
        picked = {
            f.name: getattr(self, f.name)[keep]
            for f in fields(self)
            if isinstance(getattr(self, f.name), np.ndarray) and getattr(self, f.name).shape[:1] == (n,)
        }
        return replace(self, **picked)

    def to_frame(self) -> pd.DataFrame:
        """The table as a DataFrame with the file's column names (m/s², degrees), for writing it."""
        columns: dict[str, Any] = {}
        if self.beta_rad is not None:  # with what it is measured from: a column survives a spreadsheet
            columns[BETA] = np.degrees(self.beta_rad)
            columns[HEADING_REF] = self.headings
        columns |= dict(zip(ACC, self.acc_s.T, strict=True))
        if self.cov_s is not None:
            sigma = np.sqrt(np.diagonal(self.cov_s, axis1=1, axis2=2))
            if self.std_s is not None and self.count is not None:
                columns |= dict(zip(STD, self.std_s.T, strict=True)) | {COUNT: self.count}
                columns |= dict(zip(STD_MEAN, sigma.T, strict=True))
            else:  # the 1σ of the mean as the spread of one sample
                columns |= dict(zip(STD, sigma.T, strict=True)) | {COUNT: 1}
            if any(np.any(self.cov_s[:, i, j] != 0) for i, j in PAIRS):
                with np.errstate(invalid="ignore", divide="ignore"):
                    corr = [self.cov_s[:, i, j] / (sigma[:, i] * sigma[:, j]) for i, j in PAIRS]
                columns |= {name: np.nan_to_num(r) for name, r in zip(CORR, corr, strict=True)}
        for name, values in (
            (TIME, self.t_s),
            (DURATION, self.duration_s),
            (TEMPERATURE, self.temperature_c),
            (SITE, self.site),
            (LAT, self.lat_deg),
            (LON, self.lon_deg),
            (ALT, self.alt_m),
            (HEADING, self.heading_deg),
        ):
            if values is not None:
                columns[name] = values
        applied = stated_axes(self.conventions)
        if applied is not None and not applied.identity:  # the frame of ax, ay, az, for whoever reads it next
            columns[AXES] = applied.text
        columns.update(convention_columns(self.conventions))  # what qualified the log's readings comes back
        return pd.DataFrame(columns)


def read_stop_table(
    path: str | Path,
    unit: Unit | None = None,
    headings: Headings | None = None,
    heading_unit: HeadingUnit | None = None,
    axes: AxisMap | None = None,
    uphill_azimuth_deg: float | None = None,
) -> StopTable:
    """Read and validate a stop table file (CSV, or Parquet by its ``.parquet`` suffix).

    Parameters
    ----------
    path : str or Path
    unit : {"mps2", "g"}, optional
        Unit of ``ax, ay, az`` (and ``sx, sy, sz``) in the file; m/s² when not stated (checked by |a|).
    headings : {"uphill", "relative", "none"}, optional
        What ``beta_deg`` is measured from; by default what the table's ``heading_ref`` column states,
        else uphill (and the result says it was assumed). See
        :func:`mountcal.io.input_conventions.heading_reference`.
    heading_unit : {"deg", "rad"}, optional
        Unit of ``beta_deg``; when not stated, degrees, checked (values all within ±2π are refused).
    axes : AxisMap, optional
        The device's axes onto the sensor frame (``--axes``), applied to the means and their covariances.
    uphill_azimuth_deg : float, optional
        Compass azimuth of the slope's uphill direction: β from the table's compass column ``heading_deg``.
    """
    path = Path(path)
    where = str(path)
    raw = read_input_bytes(path, "a stop table file")  # a regular file, size bounded
    cut = None  # a CSV's last row without its line break: cut short, read to the row before (if allowed)
    if path.suffix.lower() in (".parquet", ".pq"):
        parquet_end(raw=raw, where=where)
        _check_stop_count(check_parquet_rows(path) or 0, where, "rows")
    else:  # a million columns or stops are refused before pandas parses them
        check_text(raw, where)  # UTF-16: refused as such (its last line break is two bytes: not a cut file)
        cut = text_bytes_end(raw, where)
        csv_columns(raw, where)
        _check_stop_count(raw.count(b"\n"), where, "lines")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            df = pd.read_parquet(io.BytesIO(raw))
        else:
            rows = raw if cut is None else memoryview(raw)[: cut.whole]
            read_as = dialect(raw[:_HEAD_BYTES], where)[1]  # ";" with decimal commas, as every table's reader
            df = pd.read_csv(io.BytesIO(rows), skipinitialspace=True, **{"comment": "#", **read_as})
    except Exception as err:  # pandas/pyarrow raise many types for malformed files
        raise InputError(
            where,
            "a CSV or Parquet stop table",
            f"a file that does not parse ({err})",
            "Write one row per stop with columns beta_deg, ax, ay, az.",
        ) from err
    table = stop_table_from_frame(
        df, unit, headings, source=where, heading_unit=heading_unit, axes=axes, uphill_azimuth_deg=uphill_azimuth_deg
    )
    incomplete = () if cut is None else (cut.sentence,)
    return replace(table, sha256=hashlib.sha256(raw).hexdigest(), incomplete=incomplete)


def stop_table_from_frame(
    df: pd.DataFrame,
    unit: Unit | None = None,
    headings: Headings | None = None,
    source: str = "<DataFrame>",
    heading_unit: HeadingUnit | None = None,
    axes: AxisMap | None = None,
    uphill_azimuth_deg: float | None = None,
) -> StopTable:
    """Validate a DataFrame with the stop-table columns and convert it to a :class:`StopTable`
    (the parameters as :func:`read_stop_table`'s)."""
    df = df.rename(columns=lambda c: str(c).strip())
    missing = [c for c in REQUIRED if c not in df.columns]
    if missing:
        raise InputError(
            source,
            f"columns {', '.join(REQUIRED)} (and optionally {', '.join(OPTIONAL)})",
            f"no column {', '.join(missing)}; the columns are {', '.join(map(str, df.columns))}",
            "Rename the columns or write the stop table with `mountcal stops`.",
        )
    check_count(len(df), source)
    budget.charge("stops", len(df), source, "stops (stop table rows)")
    conventions = [acceleration_unit(unit or "mps2", unit is not None)]
    unit = unit or "mps2"
    scale = G_N if unit == "g" else 1.0
    with np.errstate(over="ignore"):  # a huge value becomes inf here and is refused by the gravity check
        acc = _numeric(df, list(ACC), source) * scale
    _check_gravity(acc, unit, source)
    check_values("acc_mps2", acc, source, ", ".join(ACC), scale=scale)

    beta = None
    marker = df[HEADING_REF].tolist() if HEADING_REF in df.columns else None
    reference: Headings = "none"
    if uphill_azimuth_deg is not None and headings != "none":
        compass = None
        if HEADING in df.columns:
            compass, unit_known = _in_degrees(df, HEADING, heading_unit, source)
            conventions.append(unit_known)
        beta_deg, from_compass = beta_from_compass(compass, uphill_azimuth_deg, source)
        if BETA in df.columns and marker is not None and heading_reference(marker, None, source)[0] == "uphill":
            _check_same_beta(_numeric(df, [BETA], source, "heading_deg")[:, 0], beta_deg, uphill_azimuth_deg, source)
        beta, reference = np.radians(beta_deg), "uphill"
        conventions += from_compass
    elif BETA in df.columns and headings != "none":
        compass = _numeric(df, [HEADING], source, "heading_deg")[:, 0] if HEADING in df.columns else None
        beta_read = _numeric(df, [BETA], source, "heading_deg")[:, 0]
        reference, stated = heading_reference(marker, headings, source, beta_read, compass)
        if reference != "none":
            beta_deg, unit_known = _in_degrees(df, BETA, heading_unit, source)
            beta = np.radians(beta_deg)
            conventions += [stated, unit_known]
    if beta is None:
        why = option("headings", "none") if BETA in df.columns else "the table has no beta_deg"
        conventions.append(Convention("heading_reference", "none", "stated", why))
    cov = sample_std = sample_count = None
    noise_columns = [c for c in (*STD, COUNT) if c in df.columns]
    if noise_columns and not all(c in df.columns for c in STD):
        raise InputError(
            source,
            f"the stop noise as {', '.join(STD)} together (and optionally {COUNT})",
            f"only {', '.join(noise_columns)}",
            f"Add the missing ones, or drop {', '.join(noise_columns)} to estimate the noise from the residuals.",
        )
    if all(c in df.columns for c in STD):
        std = _numeric(df, list(STD), source, "sample_std_mps2", scale)
        count = _numeric(df, [COUNT], source, "sample_count")[:, 0] if COUNT in df.columns else np.ones(len(df))
        cov = _diagonal(
            std**2 / count[:, None],
            np.any(std <= 0, axis=1) | (count < 1),
            source,
            "sample standard deviations sx, sy, sz > 0 and counts n ≥ 1",
            "Fix those rows, or drop the sx, sy, sz, n columns to estimate the noise.",
        )
        sample_std, sample_count = std, (count if COUNT in df.columns else None)
    if all(c in df.columns for c in STD_MEAN):  # the mean's own uncertainty (correlation, quantisation)
        sigma = _numeric(df, list(STD_MEAN), source, "mean_std_mps2", scale)
        cov = _diagonal(
            sigma**2,
            np.any(sigma <= 0, axis=1),
            source,
            "uncertainties of the stop means sx_mean, sy_mean, sz_mean > 0",
            "Fix those rows, or drop the sx_mean, sy_mean, sz_mean columns to use s/√n.",
        )
    if any(c in df.columns for c in CORR):
        cov = _with_correlations(cov, _numeric(df, [c for c in CORR if c in df.columns], source), df, source)
    applied = _applied_axes(df, source)
    conventions += conventions_from_columns(df, source)
    if axes is not None and not axes.identity:  # the device's axes onto the sensor frame, as for a log
        acc = axes.apply(acc)
        cov = None if cov is None else axes.apply_cov(cov)
        sample_std = None if sample_std is None else np.abs(axes.apply(sample_std))
    if applied is not None:  # ax, ay, az were mapped when the table was written
        total = applied if axes is None else axes.after(applied)
        conventions.append(
            Convention("axes", total.describe(), "stated", f"{option('axes')} {applied.text} (the table's column axes)")
        )
    elif axes is not None:
        conventions.append(axes_convention(axes, "x,y,z", ""))

    def optional(name: str) -> FloatArray | None:
        quantity = _QUANTITY.get(name)
        return _numeric(df, [name], source, quantity)[:, 0] if name in df.columns else None

    lat = optional(LAT)  # in ±90° (mountcal.core.ranges): local gravity comes from it
    return StopTable(
        acc_s=acc,
        beta_rad=beta,
        headings=reference if beta is not None else "none",
        cov_s=cov,
        temperature_c=optional(TEMPERATURE),
        t_s=optional(TIME),
        site=df[SITE].astype(str).to_numpy() if SITE in df.columns else None,
        lat_deg=lat,
        alt_m=optional(ALT),
        lon_deg=optional(LON),
        std_s=sample_std,
        count=sample_count,
        duration_s=optional(DURATION),
        heading_deg=optional(HEADING),
        source=source,
        conventions=tuple(conventions),
        notes=_unread(df, source),
    )


def _unread(df: pd.DataFrame, source: str) -> tuple[str, ...]:
    """The note naming the columns of a stop table that no column of :data:`COLUMNS` is (a heading column
    renamed in a spreadsheet, 'beta', loses yaw: said, not silent); none for pandas' unnamed index."""
    unread = [str(c) for c in df.columns if c not in COLUMNS and not str(c).startswith("Unnamed:")]
    if not unread:
        return ()
    shown = ", ".join(map(repr, unread[:8])) + (" …" if len(unread) > 8 else "")
    return (f"{source}: columns not read: {shown} (a stop table's are {', '.join(COLUMNS)}; β only from {BETA})",)


def _applied_axes(df: pd.DataFrame, source: str) -> AxisMap | None:
    """The axis map a table's column ``axes`` says was applied to its means (one value in every row)."""
    if AXES not in df.columns:
        return None
    values = {str(v).strip() for v in df[AXES]}
    if len(values) != 1:
        raise InputError(
            source,
            f"one axis map in the column {AXES}",
            ", ".join(sorted(values)),
            "Give every row the map that was applied to ax, ay, az, or drop the column.",
        )
    return parse_axes(values.pop(), f"{source}: column {AXES}")


def _in_degrees(df: pd.DataFrame, column: str, unit: HeadingUnit | None, source: str) -> tuple[FloatArray, Convention]:
    """A heading column in degrees (its unit stated, or checked), within the headings' physical range
    (:mod:`mountcal.core.ranges`) once in degrees."""
    degrees, known = headings_in_degrees(_numeric(df, [column], source)[:, 0], unit, source, column)
    check_degrees(degrees, known, source, column)
    return degrees, known


def check_degrees(degrees: FloatArray, known: Convention, source: str, column: str) -> None:
    """Refuse headings outside their physical range once in degrees; when they were stated to be
    radians, the message shows the file's numbers and names the option that said so."""
    if known.value == "deg":
        check_values("heading_deg", degrees, source, column)
        return
    check_values(
        "heading_deg",
        degrees,
        source,
        f"{column} read as radians ({option('heading_unit', 'rad')})",
        scale=float(np.degrees(1.0)),
        todo=f"If {column} holds degrees, drop {option('heading_unit', 'rad')}; else fix or remove those rows.",
    )


def _check_same_beta(beta_deg: FloatArray, from_compass: FloatArray, azimuth: float, source: str) -> None:
    """Refuse an uphill azimuth that contradicts the table's own β from uphill (beyond 1°)."""
    off = np.abs((from_compass - beta_deg + 180.0) % 360.0 - 180.0)
    if np.max(off) > 1.0:
        implied = float(np.degrees(np.angle(np.mean(np.exp(1j * np.radians(beta_deg + (azimuth - from_compass)))))))
        raise InputError(
            f"{source} with {option('uphill_azimuth', f'{azimuth:g}')}",
            f"β from the compass column heading_deg that agree with the table's beta_deg ({HEADING_REF} uphill)",
            f"differences up to {np.max(off):.1f}° (the table's β imply an uphill azimuth of {implied % 360.0:.1f}°)",
            f"Leave {option('uphill_azimuth')} out to use the table's β, or correct one of them.",
        )


def checked(table: StopTable, min_stops: int = MIN_STOPS) -> StopTable:
    """The checks of a table read from a file, for a table built in memory: enough stops (a log's
    table may hold fewer than a fit needs: ``min_stops``), finite means near gravity, covariances
    finite and positive definite."""
    check_count(len(table), table.source, min_stops)
    bad = np.flatnonzero(~np.all(np.isfinite(table.acc_s), axis=1))
    if bad.size:
        raise InputError(table.source, "finite stop means", f"non-finite values in stops {_rows(bad)}", _NO_GUESS)
    _check_gravity(table.acc_s, "mps2", table.source)
    if table.cov_s is not None:
        finite = np.all(np.isfinite(table.cov_s), axis=(1, 2))
        smallest = np.full(len(table), -1.0)
        smallest[finite] = np.linalg.eigvalsh(table.cov_s[finite])[:, 0]
        bad = np.flatnonzero(smallest <= 0)
        if bad.size:
            raise InputError(
                table.source,
                "a positive definite covariance of every stop mean",
                f"a zero, negative or non-finite spread in stops {_rows(bad)}",
                "The stops' samples do not vary (a stuck or constant sensor): check the log.",
            )
    return table


def _check_stop_count(n: int, source: str, what: str) -> None:
    """Refuse a file of more than the run's budget of stops (``n`` lines: a bound on its rows) before
    it is parsed: a stop costs a fit memory and time, and a protocol has tens of them."""
    limit = budget.setting("stops")
    if n > limit + 1:  # the header line
        raise budget.over(
            "stops", source, f"at most {limit} stops", f"{n} {what}", "A stop table holds one row per stop."
        )


def check_count(n: int, source: str, min_stops: int = MIN_STOPS) -> None:
    """Refuse a table with fewer than ``min_stops`` stops (a fit needs ``MIN_STOPS``)."""
    if n < min_stops:
        raise NotEnoughInformation(
            f"{source}: expected at least {min_stops} stops, found {n}. "
            "Park at more headings (12 evenly spread is the paper's protocol)."
        )


def _diagonal(variance: FloatArray, bad: np.ndarray, source: str, expected: str, todo: str) -> FloatArray:
    """Covariances with the given variances on the diagonal, refusing the ``bad`` rows."""
    if bad.any():
        raise InputError(source, expected, f"non-positive values in rows {_rows(np.flatnonzero(bad))}", todo)
    cov = np.zeros((variance.shape[0], 3, 3))
    cov[:, [0, 1, 2], [0, 1, 2]] = variance
    return cov


def _with_correlations(cov: FloatArray | None, corr: FloatArray, df: pd.DataFrame, source: str) -> FloatArray:
    """The covariances with the correlations ``rxy, rxz, ryz`` between axes; all three or none."""
    if cov is None:
        raise InputError(
            source,
            f"the correlations {', '.join(CORR)} with the spreads they correlate ({', '.join(STD)} or the _mean ones)",
            "correlations without spreads",
            "Add the spreads, or drop the correlations.",
        )
    if corr.shape[1] != len(CORR):
        raise InputError(
            source,
            f"the correlations {', '.join(CORR)} together",
            f"only {', '.join(c for c in CORR if c in df.columns)}",
            "Add the missing ones, or drop them to treat the axes of a stop mean as independent.",
        )
    sigma = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    out = cov.copy()
    for k, (i, j) in enumerate(PAIRS):
        out[:, i, j] = out[:, j, i] = corr[:, k] * sigma[:, i] * sigma[:, j]
    bad = np.flatnonzero((np.abs(corr) >= 1).any(axis=1) | (np.linalg.eigvalsh(out)[:, 0] <= 0))
    if bad.size:
        raise InputError(
            source,
            f"correlations {', '.join(CORR)} in (−1, 1) that make a positive definite covariance",
            f"impossible correlations in rows {_rows(bad)}",
            "Fix those rows, or drop the rxy, rxz, ryz columns.",
        )
    return out


def write_stop_table(table: StopTable, path: str | Path) -> None:
    """Write a stop table as CSV or Parquet (by suffix), atomically."""
    from mountcal.core.atomic import atomic_path

    path = Path(path)
    check_output_suffix(option("output"), path, (".csv", ".parquet", ".pq"))  # another format's name: refused
    df = table.to_frame()
    with atomic_path(path) as tmp:
        if path.suffix.lower() in (".parquet", ".pq"):
            df.to_parquet(tmp, index=False)
        else:
            df.to_csv(tmp, index=False, float_format="%.15g")


def _numeric(
    df: pd.DataFrame, cols: list[str], source: str, quantity: str | None = None, scale: float = 1.0
) -> FloatArray:
    """The columns as finite floats times ``scale`` (to SI), each within ``quantity``'s physical range
    (:mod:`mountcal.core.ranges`); anything else is refused naming the rows."""
    with np.errstate(over="ignore"):
        values = np.asarray(df[cols].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float) * scale, np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        rows, cs = np.nonzero(bad)
        found = ", ".join(f"row {r + 1} column {cols[c]}" for r, c in list(zip(rows, cs, strict=True))[:5])
        more = f" and {bad.sum() - 5} more" if bad.sum() > 5 else ""
        raise InputError(
            source,
            f"finite numbers in {', '.join(cols)}",
            f"missing or non-numeric values at {found}{more}",
            _NO_GUESS,
        )
    if quantity is not None:
        check_values(quantity, values, source, ", ".join(cols), scale=scale)
    return values


def _check_gravity(acc: FloatArray, unit: Unit, source: str) -> None:
    mag = np.hypot(np.hypot(acc[:, 0], acc[:, 1]), acc[:, 2])  # no overflow below 1e308
    lo, hi = GRAVITY_BAND
    bad = np.flatnonzero((mag < lo * G_N) | (mag > hi * G_N))
    if bad.size == 0:
        return
    shown = "m/s²" if unit == "mps2" else "g"
    scale = 1.0 if unit == "mps2" else G_N
    found = ", ".join(f"row {i + 1}: |a| = {mag[i] / scale:.4g} {shown}" for i in bad[:5])
    hint = (
        f"Check the unit: add {option('unit', 'g')} if the table is in g."
        if unit == "mps2"
        else (f"Check the unit: drop {option('unit', 'g')} if the table is in m/s².")
    )
    if np.median(mag) / scale < 2.0 and unit == "mps2":
        hint = f"The magnitudes look like g: add {option('unit', 'g')}."
    elif np.median(mag) / scale > 5.0 and unit == "g":
        hint = f"The magnitudes look like m/s²: drop {option('unit', 'g')}."
    with np.errstate(over="ignore"):
        other = mag[bad] * (G_N if unit == "mps2" else 1.0 / G_N)  # the bad rows read in the other unit
    hopeless = bad[~(np.isfinite(other) & (other >= lo * G_N) & (other <= hi * G_N))]
    if hopeless.size == bad.size:  # the unit explains none of them: advising a unit would be wrong
        hint = "Those rows are no static reading in either unit (huge, overflowing or near-zero): fix or remove them."
    elif hopeless.size:
        hint += f" Rows {_rows(hopeless)} are no static reading in either unit: fix or remove them."
    raise InputError(source, f"static readings of magnitude near gravity ({lo:g}–{hi:g} g)", found, hint)


def _rows(idx: np.ndarray) -> str:
    return ", ".join(str(i + 1) for i in idx[:10]) + (" …" if idx.size > 10 else "")
