"""Which column of a table holds what, in which unit: mountcal's own names, a column map, or a known export.

A **column map** names, for each quantity (a *role*), the table's column and optionally its unit::

    --columns time=ts:ms,ax=acc_x:g,ay=acc_y:g,az=acc_z:g,gx=gyr_x:deg/s,gy=gyr_y:deg/s,gz=gyr_z:deg/s

(the same ``ROLE = "COLUMN[:UNIT]"`` pairs under ``[columns]`` in the ``--mapping`` TOML). Roles:
``time``, ``ax ay az`` (required), ``gx gy gz`` (all three or none), ``speed``, ``heading``,
``temperature``, ``latitude``, ``longitude``, ``altitude``. Units (as in the CAN mapping):

- time: ``s``, ``ms``, ``us``, ``ns``, ``iso`` (date-time text; without a zone, UTC), ``clock`` (a time of
  day), or ``s/N`` — a sample index at N Hz (imucal's ``n_samples``); without a unit, inferred from the column's spacing
  (:mod:`mountcal.io.table.time_unit`, which also checks a stated one and reads typed Parquet times);
- acceleration: ``m/s2`` (default), ``g`` (9.80665 m/s²), ``mg``; gyro: ``rad/s`` (default), ``deg/s``;
  speed ``m/s``, ``km/h``, ``mph``, ``kn``; heading ``deg``, ``rad``; and any unit divided by a count,
  ``g/2048`` for a raw 16-bit reading at ±16 g.

Without a map, mountcal's own columns (``t_s, ax, ay, az`` in s and m/s², ``gx, gy, gz`` in rad/s) are
read, or one of the **known exports** is recognised by its exact column names and *stated* (the
notes say which export and which units were taken): imucal sessions, phyphox, Sensor Logger and
Physics Toolbox Sensor Suite (:data:`EXPORTS`); a whole Sensor Logger recording (its folder or zip) is
:mod:`mountcal.io.sensor_logger`'s, and its single files other than TotalAcceleration.csv are refused naming
it. A **gravity-free** ("linear") acceleration is
recognised too and marked: it reads, but calibration refuses it (the mounting is measured against
gravity).
"""

from __future__ import annotations

import re
import shlex
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.can.signals import G_N, UNIT_HINT, UNIT_KIND, UNITS, normalise_unit

if TYPE_CHECKING:
    from mountcal.core.result import Convention

ACC = ("ax", "ay", "az")
GYRO = ("gx", "gy", "gz")
CHANNELS = {
    "speed": "speed_mps",
    "heading": "heading_deg",
    "temperature": "temperature_c",
    "latitude": "lat_deg",
    "longitude": "lon_deg",
    "altitude": "alt_m",
}
ROLES = ("time", *ACC, *GYRO, *CHANNELS)
NATIVE = {"time": "t_s", **{r: r for r in (*ACC, *GYRO)}, **{r: c for r, c in CHANNELS.items()}}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}


@dataclass(frozen=True)
class Column:
    """A table column read as a role: SI value = value · scale + offset (time: ``unit`` says how)."""

    name: str
    unit: str  # as given or assumed ("" for the default)
    scale: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Layout:
    """How to read a table's samples."""

    columns: dict[str, Column]  # role → column; always time, ax, ay, az
    source: str  # "mountcal's own columns", "the column map", "a phyphox export", …
    notes: tuple[str, ...] = ()
    gravity_free: str = ""  # why the acceleration is known to lack gravity ("" when it has it)
    read_as: dict[str, str] = field(default_factory=dict)  # CSV reading options (sep, decimal)
    conventions: tuple[Convention, ...] = ()  # how its units are known (the time unit: io.table.time_unit)

    @property
    def native(self) -> bool:
        """Whether this is mountcal's own table, unconverted (read by the fast reader)."""
        return (
            all(
                c.name == NATIVE[r] and c.scale == 1.0 and c.offset == 0.0 and c.unit in ("", "s", "m/s2", "rad/s")
                for r, c in self.columns.items()
            )
            and not self.read_as
        )

    @property
    def time(self) -> Column:
        return self.columns["time"]


# --------------------------------------------------------------------------- units


def unit_scale(role: str, unit: str, where: str) -> tuple[float, float]:
    """(scale, offset) to SI of ``unit`` for ``role``; ``UNIT/N`` divides by N (counts of 1/N unit)."""
    text = unit.strip()
    base, _, count = text.rpartition("/")
    divisor = 1.0
    if base and re.fullmatch(r"\d+(\.\d*)?|\.\d+", count.strip()):
        divisor, text = float(count), base
    if role == "time":
        if text.lower() in TIME_UNITS and divisor > 0:
            return TIME_UNITS[text.lower()] / divisor, 0.0
        raise _unit_error(role, unit, where, "s, ms, us, ns, iso, clock, or s/N for a sample index at N Hz")
    found = UNITS[UNIT_KIND[role]].get(normalise_unit(text))
    if found is None or divisor <= 0:
        raise _unit_error(role, unit, where, UNIT_HINT[UNIT_KIND[role]] + ", optionally /N for counts of 1/N unit")
    return found[0] / divisor, found[1] / divisor


def _unit_error(role: str, unit: str, where: str, hint: str) -> InputError:
    return InputError(
        where, f"a unit for {role} ({hint})", repr(unit), f"Fix the unit in {option('columns')} or the mapping."
    )


def _column(role: str, spec: str, names: list[str], where: str) -> Column:
    """``COLUMN[:UNIT]`` for ``role``, the column checked to exist (a name may itself hold ':')."""
    name, unit = spec, ""
    if spec not in names and ":" in spec:
        name, _, unit = spec.rpartition(":")
    if name not in names:
        raise InputError(
            where,
            f"a column {name!r} (for {role})",
            f"columns {', '.join(map(repr, names))}",
            f"Name an existing column in {option('columns')}.",
        )
    if role == "time" and unit.strip().lower() in ("iso", "clock"):
        return Column(name, unit.strip().lower())
    scale, offset = unit_scale(role, unit, where) if unit else (1.0, 0.0)
    return Column(name, unit, scale, offset)


# --------------------------------------------------------------------------- the column map


def parse_columns(text: str) -> tuple[tuple[str, str], ...]:
    """``time=ts:ms,ax=acc_x`` → (("time", "ts:ms"), ("ax", "acc_x")); roles checked.

    Raises
    ------
    InputError
        An item without ``=``, an unknown or repeated role.
    """
    pairs = []
    for item in (i for i in text.split(",") if i.strip()):
        role, eq, spec = item.partition("=")
        if not eq or not spec.strip():
            raise InputError(
                option("columns"),
                "ROLE=COLUMN[:UNIT] pairs separated by commas",
                repr(item),
                "Write e.g. time=ts:ms,ax=acc_x,ay=acc_y,az=acc_z.",
            )
        pairs.append((role.strip(), spec.strip()))
    _check_roles([r for r, _ in pairs], option("columns"))
    return tuple(pairs)


def _check_roles(roles: list[str], where: str) -> None:
    unknown = [r for r in roles if r not in ROLES]
    repeated = sorted({r for r in roles if roles.count(r) > 1})
    if unknown or repeated:
        raise InputError(
            where,
            f"roles among {', '.join(ROLES)}, each once",
            f"{'unknown ' + ', '.join(map(repr, unknown)) if unknown else ''}"
            f"{'; ' if unknown and repeated else ''}{'repeated ' + ', '.join(repeated) if repeated else ''}",
            "Name each quantity once by its role.",
        )


def mapping_columns(path: str) -> tuple[tuple[str, str], ...]:
    """The ``[columns]`` table of a mapping TOML (the only key a table's mapping holds)."""
    from mountcal.core.paths import input_file

    where = str(path)
    text = input_file(path, "a mapping TOML").read_text(encoding="utf-8", errors="replace")
    try:
        spec = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise InputError(where, "a TOML mapping", f"a file that does not parse ({err})", "Fix the TOML.") from err
    extra = sorted(set(spec) - {"columns"})
    columns = spec.get("columns")
    if extra or not isinstance(columns, dict) or not all(isinstance(v, str) for v in columns.values()):
        raise InputError(
            where,
            'a table mapping: a [columns] table of ROLE = "COLUMN[:UNIT]"',
            f"keys {', '.join(extra)}" if extra else f"columns = {columns!r}"[:200],
            'Write e.g.\n[columns]\ntime = "ts:ms"\nax = "acc_x:g"',
        )
    _check_roles(list(columns), where)
    return tuple((str(k), str(v)) for k, v in columns.items())


# --------------------------------------------------------------------------- known exports


@dataclass(frozen=True)
class Export:
    """A known export: its exact columns (role → column, unit) and what to say about it."""

    name: str
    columns: dict[str, tuple[str, str]]
    gravity_free: str = ""
    file_name: str = ""  # the export's own file name, when its columns alone do not tell
    needs: str = ""  # what must be given to read it (e.g. the sampling rate)
    refuse: str = ""  # why it cannot be read, and what to read instead (no acceleration in it)


_PHYPHOX_ACC = {f"a{c}": (f"Acceleration {c} (m/s^2)", "m/s2") for c in "xyz"}
_PHYPHOX_GYRO = {f"g{c}": (f"Gyroscope {c} (rad/s)", "rad/s") for c in "xyz"}
_SENSOR_LOGGER = {"time": ("time", "ns"), **{f"a{c}": (c, "m/s2") for c in "xyz"}}
_RECORDING = "give the recording itself: {recording}"  # filled in with the file's folder (_recording_of)
_IMUCAL = {f"a{c}": (f"acc_{c}", "m/s2") for c in "xyz"} | {f"g{c}": (f"gyr_{c}", "deg/s") for c in "xyz"}

EXPORTS = (
    Export("a phyphox export ('Acceleration with g')", {"time": ("Time (s)", "s"), **_PHYPHOX_ACC, **_PHYPHOX_GYRO}),
    Export("a phyphox export ('Acceleration with g')", {"time": ("Time (s)", "s"), **_PHYPHOX_ACC}),
    Export(
        "a phyphox export ('Linear Acceleration')",
        {"time": ("Time (s)", "s"), **{f"a{c}": (f"Linear Acceleration {c} (m/s^2)", "m/s2") for c in "xyz"}},
        gravity_free="phyphox's 'Linear Acceleration' is the acceleration with gravity removed by the phone; "
        "record with phyphox's 'Acceleration with g' (columns 'Acceleration x (m/s^2)' …)",
    ),
    Export("a Sensor Logger TotalAcceleration.csv", _SENSOR_LOGGER, file_name="totalacceleration.csv"),
    Export(
        "a Sensor Logger Accelerometer.csv",
        _SENSOR_LOGGER,
        file_name="accelerometer.csv",
        gravity_free=f"Sensor Logger's Accelerometer.csv is the acceleration with gravity removed; {_RECORDING}",
    ),
    Export(
        "a Physics Toolbox Sensor Suite export (g-force)",
        {
            "time": ("time", "s"),
            **{f"a{c}": (f"gF{c}", "g") for c in "xyz"},
            **{f"g{c}": (f"w{c}", "rad/s") for c in "xyz"},
        },
    ),
    Export(
        "a Physics Toolbox Sensor Suite export (g-force)",
        {"time": ("time", "s"), **{f"a{c}": (f"gF{c}", "g") for c in "xyz"}},
    ),
    Export(
        "a Physics Toolbox Sensor Suite export (linear accelerometer)",
        {"time": ("time", "s"), **{f"a{c}": (f"a{c}", "m/s2") for c in "xyz"}, "aT": ("aT", "m/s2")},
        gravity_free="Physics Toolbox's linear accelerometer (columns ax, ay, az, aT) removes gravity; "
        "record with its g-force meter (columns gFx, gFy, gFz)",
    ),
    Export(
        "a Sensor Logger Gyroscope.csv",
        {"time": ("time", "ns"), **{f"g{c}": (c, "rad/s") for c in "xyz"}},
        file_name="gyroscope.csv",
        refuse=f"it holds the gyro only; {_RECORDING}",
    ),
    Export(
        "a Sensor Logger Gravity.csv",
        {"time": ("time", "ns"), **{f"a{c}": (c, "m/s2") for c in "xyz"}},
        file_name="gravity.csv",
        refuse=f"it holds the phone's estimate of gravity, not the accelerometer; {_RECORDING}",
    ),
    Export(
        "a phyphox gyroscope export",
        {"time": ("Time (s)", "s"), **_PHYPHOX_GYRO},
        refuse="it holds the gyro only; export phyphox's 'Acceleration with g' (columns 'Acceleration x (m/s^2)' …)",
    ),
    Export("an imucal session", {"time": ("n_samples", ""), **_IMUCAL}, needs="rate"),
    Export("an imucal session", {"time": ("samples", ""), **_IMUCAL}, needs="rate"),
)


def _export_role(key: str) -> str | None:
    """An export's column key → role (``ax`` → ax, ``gx`` → gx; ``aT`` and others → None)."""
    if key == "time":
        return "time"
    if len(key) == 2 and key[0] in "ag" and key[1] in "xyz":
        return key
    return None


def detect(names: list[str], path: Path) -> Export | None:
    """The known export whose columns ``names`` hold (the most specific first), or None."""
    have = set(names)
    for export in EXPORTS:
        if export.file_name and path.name.lower() != export.file_name:
            continue
        if all(col in have for col, _ in export.columns.values()):
            return export
    return None


# --------------------------------------------------------------------------- resolving a table's layout


def resolve(
    names: list[str],
    path: Path,
    *,
    columns: tuple[tuple[str, str], ...] | None = None,
    acc_unit: str | None = None,
) -> Layout | None:
    """The layout of a table with columns ``names``: from the column map, mountcal's own names, or a known
    export; None when there is none of these (the caller refuses, listing the columns).

    ``acc_unit`` (``--unit g``) gives the acceleration columns' unit where the table or map does not.

    Raises
    ------
    InputError
        A map naming a missing column or an unknown unit; an export that needs more (imucal's rate);
        a unit given twice.
    """
    where = str(path)
    if columns is not None:
        cols = {role: _column(role, spec, names, where) for role, spec in columns}
        missing = [r for r in ("time", *ACC) if r not in cols]
        if missing:
            raise InputError(
                where,
                "a column map naming time, ax, ay and az",
                f"no {', '.join(missing)} in {option('columns')}",
                f"Add them, e.g. {option('columns', 'time=ts,ax=acc_x,ay=acc_y,az=acc_z')}.",
            )
        layout = Layout(_with_acc_unit(cols, acc_unit, where), "the column map", gravity_free=_linear_named(cols))
    elif all(c in names for c in ("t_s", *ACC)):
        cols = {role: Column(col, "") for role, col in NATIVE.items() if col in names}
        layout = Layout(_with_acc_unit(cols, acc_unit, where), "mountcal's own columns")
    else:
        export = detect(names, path)
        if export is None:
            return None
        layout = _export_layout(export, names, path, acc_unit)
    _check_gyro(layout, where)
    return layout


def _export_layout(export: Export, names: list[str], path: Path, acc_unit: str | None) -> Layout:
    where = str(path)
    cols: dict[str, Column] = {}
    for key, (name, unit) in export.columns.items():
        role = _export_role(key)
        if role is None:
            continue
        scale, offset = (1.0, 0.0) if role == "time" or not unit else unit_scale(role, unit, where)
        if role == "time" and unit:
            scale = TIME_UNITS[unit]
        cols[role] = Column(name, unit, scale, offset)
    if export.refuse:
        raise InputError(
            where,
            "a table with an acceleration",
            f"{export.name}: {export.refuse.replace('{recording}', _recording_of(path))}",
            "Give that input instead.",
        )
    if export.needs == "rate":
        raise InputError(
            where,
            "the sampling rate of an imucal session (its time column counts samples)",
            f"{export.name}: columns {', '.join(c.name for c in cols.values())}, no time",
            f"Give the rate with a column map, e.g. {option('columns', _imucal_map(cols['time'].name))} "
            "(102.4 Hz for imucal's example session; acc in m/s², gyro in deg/s as imucal's examples).",
        )
    units = ", ".join(sorted({f"{c.unit}" for r, c in cols.items() if r != "time" and c.unit}))
    # the time's unit is said once, by the convention its column's type, text or spacing settles (io.table.time_unit)
    note = f"read as {export.name}: columns {', '.join(c.name for c in cols.values())}; units {units}"
    gravity_free = export.gravity_free.replace("{recording}", _recording_of(path))
    return Layout(_with_acc_unit(cols, acc_unit, where, export.name), export.name, (note,), gravity_free)


def _recording_of(path: Path) -> str:
    """The Sensor Logger recording a single file of it belongs to, as the input to give (both platforms:
    iOS logs no TotalAcceleration.csv, so its acceleration with gravity is Accelerometer + Gravity)."""
    folder = path.resolve().parent
    try:
        whole = any(p.name.lower() == "metadata.csv" for p in folder.iterdir())
    except OSError:
        whole = False
    if whole:
        return f"its folder {folder} (mountcal reads it as one log: the acceleration with gravity, gyro, location)"
    return (
        "the zip Sensor Logger exported, or the folder it unzips to (Metadata.csv with the sensors' CSVs; "
        f"{folder} has no Metadata.csv): mountcal reads it as one log (the acceleration with gravity, gyro, location)"
    )


def _imucal_map(time: str) -> str:
    gyro = ",".join(f"g{c}=gyr_{c}:deg/s" for c in "xyz")
    return f"time={time}:s/102.4,ax=acc_x,ay=acc_y,az=acc_z,{gyro}"


def _with_acc_unit(cols: dict[str, Column], acc_unit: str | None, where: str, export: str = "") -> dict[str, Column]:
    """``--unit`` applied to the acceleration columns (refused where the map or export gives their unit)."""
    if acc_unit is None or acc_unit in ("mps2", "m/s2"):
        return cols
    given = [r for r in ACC if cols[r].unit]
    if given:
        source = export or option("columns")
        raise InputError(
            where,
            "the acceleration unit given once",
            f"{option('unit', acc_unit)} and {', '.join(f'{r} in {cols[r].unit}' for r in given)} from {source}",
            f"Drop {option('unit')}" + ("" if export else f" or the units in {option('columns')}") + ".",
        )
    scale, offset = unit_scale("ax", acc_unit, where)
    return {r: Column(c.name, acc_unit, scale, offset) if r in ACC else c for r, c in cols.items()}


def _check_gyro(layout: Layout, where: str) -> None:
    have = [r for r in GYRO if r in layout.columns]
    if have and len(have) != 3:
        raise InputError(
            where,
            "gx, gy and gz together, or none",
            f"only {', '.join(have)}",
            f"Map all three in {option('columns')}.",
        )


def _linear_named(cols: dict[str, Column]) -> str:
    """Why the mapped acceleration columns lack gravity, when their names say so ("" otherwise)."""
    names = [cols[r].name for r in ACC]
    pattern = re.compile(r"linear|lin_?acc|user_?acc|useracceleration|gravity_?free|no_?gravity|without_?g", re.I)
    linear = [n for n in names if pattern.search(n)]
    if linear:
        return f"columns {', '.join(map(repr, linear))} are named as an acceleration with gravity removed"
    return ""


def refuse_unknown(names: list[str], path: Path) -> InputError:
    """The refusal of a table whose columns are neither mountcal's, mapped, nor a known export; where the
    column names say the roles and units (``ax [g]``, ``acc_x (m/s^2)``, ``gyro_x (dps)``, ``time (s)``), it
    names the column map that reads them (:func:`suggested_map`), to be checked and given."""
    from mountcal.core.option_names import flags_on

    shown = ", ".join(map(repr, names[:12])) + (" …" if len(names) > 12 else "")
    suggested = suggested_map(names)
    if suggested is not None:
        given = option("columns", shlex.quote(suggested) if flags_on() else suggested)
        todo = f"The column names read as: {given} (roles and units taken from the names: check them, then give it)."
    else:
        todo = f"Name the columns, e.g. {option('columns', 'time=ts:ms,ax=acc_x:g,ay=acc_y:g,az=acc_z:g')}"
    return InputError(
        str(path),
        "a sample table: columns t_s, ax, ay, az (s, m/s²), a known export (imucal, phyphox, Sensor Logger, "
        "Physics Toolbox), or a column map",
        f"columns {shown}",
        f"{todo}; a CAN log in CSV needs a DBC ({option('dbc')}).",
    )


# a column name's unit: in brackets or parentheses after it, or a suffix (accX_mg, time_ms)
_NAMED_UNIT = re.compile(
    r"(?P<base>.*?)\s*(?:[\[(](?P<bracketed>[^\])]+)[\])]|_(?P<suffix>mg|g|mps2|mps|kmh|dps|rads|deg|rad|ms|us|ns|s|c|m))\s*",
    re.I,
)
_ROLE_OF = (  # a column name (lower case, without spaces, '_' and '-') → a role
    (re.compile(r"(?:t|time|timestamp|stamp|secondselapsed|elapsed)"), "time"),
    (re.compile(r"(?:a|acc|accel|accelerometer|acceleration|gf)(?P<axis>[xyz])"), "a"),
    (re.compile(r"(?:g|w|gyr|gyro|gyroscope|rotationrate|angularvelocity)(?P<axis>[xyz])"), "g"),
    (re.compile(r"(?:speed|velocity)"), "speed"),
    (re.compile(r"(?:heading|bearing|course)"), "heading"),
    (re.compile(r"(?:temperature|temp)"), "temperature"),
    (re.compile(r"(?:lat|latitude)"), "latitude"),
    (re.compile(r"(?:lon|lng|longitude)"), "longitude"),
    (re.compile(r"(?:alt|altitude)"), "altitude"),
)


def suggested_map(names: list[str]) -> str | None:
    """The column map the names say (``time (s)`` → ``time=time (s):s``, ``ax [g]`` → ``ax=ax [g]:g``, a unit
    only where it is one mountcal reads for the role); None where they do not name time, ax, ay and az each
    once with a unit mountcal reads (two IMUs, ``ax1`` and ``ax2``, are for the user to choose), or a name
    holds a comma. A channel (speed, heading, …) named once with a readable unit (or none) is added."""
    found: dict[str, list[str]] = {}
    for name in names:
        match = _NAMED_UNIT.fullmatch(name)
        base, unit = (name, "") if match is None else (match["base"], match["bracketed"] or match["suffix"] or "")
        key = re.sub(r"[\s_\-]", "", base).lower()
        for pattern, role in _ROLE_OF:
            hit = pattern.fullmatch(key)
            if hit is not None:
                role = role[0] + hit["axis"] if role in ("a", "g") else role
                known = _known(role, unit)
                spec = f"{name}:{unit.strip()}" if known else name
                found.setdefault(role, []).append(spec if known or not unit.strip() else "")  # "": a unit not read
                break
    required = ["time", *ACC] + ([*GYRO] if any(r in found for r in GYRO) else [])
    if any(found.get(r, [""]) in ([], [""]) or len(found[r]) != 1 for r in required):
        return None
    extra = [r for r in CHANNELS if len(found.get(r, [])) == 1 and found[r][0]]  # a channel named once, readable
    if any("," in found[r][0] for r in (*required, *extra)):
        return None
    return ",".join(f"{r}={found[r][0]}" for r in (*required, *extra))


def _known(role: str, unit: str) -> bool:
    """Whether ``unit`` is one mountcal reads for ``role``."""
    if not unit.strip():
        return False
    if role == "time":
        return unit.strip().lower() in TIME_UNITS
    return normalise_unit(unit) in UNITS[UNIT_KIND[role]]


__all__ = [
    "ACC",
    "CHANNELS",
    "EXPORTS",
    "GYRO",
    "G_N",
    "ROLES",
    "Column",
    "Export",
    "Layout",
    "detect",
    "mapping_columns",
    "parse_columns",
    "refuse_unknown",
    "resolve",
    "suggested_map",
    "unit_scale",
]
