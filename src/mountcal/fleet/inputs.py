"""Fleet inputs: folders, globs and manifest CSVs → one :class:`FleetJob` per log.

- A **folder** is searched recursively (hidden files and folders skipped); every file a reader
  takes (:func:`mountcal.io.registry.is_log`: the suffixes of the built-in and plugin formats) is
  one log and its vehicle id is its parent folder's name (as found: a link's folder, not its target's). A
  folder a reader takes itself (a Sensor Logger recording, a ROS 2 bag, a comma2k19 segment) is one log,
  given or found inside a folder, keyed by its files' contents; its files are not searched. A sheet named
  ``<log name>.protocol.csv`` beside a log is that log's protocol sheet.
- A **glob** (``'fleet/*/*.mcap'``, quoted so that mountcal expands it) names logs the same way.
- A **manifest** is a CSV with the columns :data:`MANIFEST_COLUMNS` (``vehicle_id`` and ``log``
  required); ``log`` may be a glob matching the split files of one log. Relative paths are
  relative to the manifest's folder; empty cells take the command-line defaults.
- Any other file is one log of the vehicle named by its parent folder.
- A **URL** (``s3://bucket/LOG``, any fsspec protocol) is listed like a folder
  (:mod:`mountcal.fleet.storage`, :mod:`mountcal.fleet.storage_logs`): a prefix that is one log is one log,
  as a local folder is; its objects are keyed by their ETag, size and time, and fetched by the worker
  that calibrates them.

Folders, globs and URLs are read in a **layout** (:mod:`mountcal.fleet.layout`): ``folders`` (each
file one log of its parent folder's vehicle) or ``canedge`` (``<device>/<session>/<split>.MF4``: the
splits of a session joined into one log of the device), stated or inferred from the names.

Stop tables (CSV/Parquet with ``beta_deg, ax, ay, az``) are accepted wherever a log is.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass, field, replace
from glob import glob
from pathlib import Path
from typing import Any, Literal

import pandas as pd

from mountcal.calibration.job import LogJob
from mountcal.calibration.options import DEFAULT_USE, Options, Use
from mountcal.core.errors import InputError
from mountcal.core.option_names import flags_on
from mountcal.core.paths import input_file, special_kind
from mountcal.fleet.layout import Found, Grouped, Layout, group, infer_layout, natural_key, unreadable_split
from mountcal.fleet.storage import RemoteObject, is_url, list_objects
from mountcal.fleet.storage_logs import storage_logs
from mountcal.io.frame import written_by_mountcal
from mountcal.io.inputs import csv_columns
from mountcal.io.reader import LogOptions
from mountcal.io.registry import is_log, log_suffixes
from mountcal.io.table.mapped import dialect
from mountcal.stops.detect import StopDetection
from mountcal.stops.table import Headings

PROTOCOL_SUFFIX = ".protocol.csv"
MANIFEST_REQUIRED = ("vehicle_id", "log")
MANIFEST_COLUMNS = (
    *MANIFEST_REQUIRED,
    "protocol_sheet",
    "dbc",
    "mapping",
    "channel",
    "topic",
    "uphill_azimuth_deg",
    "start_time",
)
_GLOB_CHARS = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class JobDefaults:
    """Settings every log gets unless its manifest row says otherwise (the command-line options)."""

    log: LogOptions = field(default_factory=LogOptions)
    detection: StopDetection = field(default_factory=StopDetection)
    uphill_azimuth_deg: float | None = None
    options: Options = field(default_factory=Options)
    headings: Headings | None = None  # what a stop table's beta_deg is from (None: its heading_ref, else uphill)
    use: Use = DEFAULT_USE  # a log's parked stops, its driving, or whatever it supports (as `mountcal calibrate`)


COMPUTED_BY = "_computed_by"  # in a worker's record of a job: the mountcal version that computed it (the run checks it)


@dataclass(frozen=True)
class FleetJob:
    """One log of one vehicle, ready for a worker.

    Attributes
    ----------
    vehicle_id : str
    log : str
        The log as the results name it: its path as found (split files joined with ``" + "``).
    job : LogJob
        What :func:`mountcal.calibration.pipeline.calibrate_job` needs, with absolute paths, so that a worker
        on another machine of a shared file system finds the files.
    headings : {"uphill", "relative", "none"} or None
        What ``beta_deg`` of a stop table is measured from (None: as its ``heading_ref`` column states, else
        uphill; logs find their own headings).
    start_time : str or None
        The log's start (ISO 8601, UTC) from the manifest; None to take it from the log's clock.
    origin : str
        Where the job came from (a folder, a glob, a manifest row), for messages.
    layout : str
        ``folders``, ``canedge`` or ``manifest``.
    session : str or None
        The CANedge session folder's name; None in the other layouts.
    shown : tuple of str
        Each of ``job.paths`` as the user sees it (as given, or the object's URL): messages use these.
    stamps : tuple of str or None
        Per path, the listed version of an object in storage (its ETag, size and time: the resume
        key); None for a local file, whose bytes are hashed. Empty: all local.
    storage : tuple of (str, value)
        fsspec options for the paths that are URLs.
    folder_objects : tuple of RemoteObject
        For a log that is a prefix in storage (a folder of objects: one path, the prefix's URL), its objects
        with their paths below it; the worker fetches them into one local folder. Empty otherwise.
    flags : bool
        Messages spell options as command-line flags (the job came from the command line).
    """

    vehicle_id: str
    log: str
    job: LogJob
    headings: Headings | None = None
    start_time: str | None = None
    origin: str = ""
    layout: str = "folders"
    session: str | None = None
    shown: tuple[str, ...] = ()
    stamps: tuple[str | None, ...] = ()
    storage: tuple[tuple[str, Any], ...] = ()
    flags: bool = False
    folder_objects: tuple[RemoteObject, ...] = ()


def collect_jobs(
    inputs: Sequence[str | Path],
    defaults: JobDefaults | None = None,
    exclude: Collection[str | Path] = (),
    set_aside: list[Path] | None = None,
    layout: Layout = "auto",
    storage_options: dict[str, Any] | None = None,
    discarded: dict[str, int] | None = None,
) -> list[FleetJob]:
    """The jobs of folders, globs, log files and manifests, in input order.

    A log reached twice (a folder and a glob over it) is listed twice; :func:`run_fleet` keeps the
    first and counts the others.

    Parameters
    ----------
    inputs : sequence of str or Path
    defaults : JobDefaults, optional
    exclude : collection of paths
        Files and folders never taken as logs (the fleet's own outputs).
    set_aside : list, optional
        Receives the files of folders and globs that were not taken because mountcal wrote them
        (:func:`written_by_mountcal`: fleet tables, rotated logs), whatever their names.
    layout : {"auto", "canedge", "folders", "manifest"}
        How folders, globs and URLs map to vehicles and logs (:mod:`mountcal.fleet.layout`);
        ``manifest`` accepts manifests only.
    storage_options : dict, optional
        fsspec options for URL inputs (``endpoint_url``, ``anon`` …).
    discarded : dict, optional
        Receives the files the layout set aside, counted by reason.

    Raises
    ------
    InputError
        An input names nothing, a manifest is malformed, or no log is found at all.
    """
    defaults = defaults or JobDefaults()
    skip = {_resolved(Path(p)) for p in exclude}
    context = _Context(
        defaults, skip, [] if set_aside is None else set_aside, layout, dict(storage_options or {}), flags_on()
    )
    jobs = [job for item in inputs for job in _jobs_of_input(str(item), context)]
    for reason, n in context.discarded.items():
        if discarded is not None:
            discarded[reason] = discarded.get(reason, 0) + n
    if not jobs:
        found = "no log"
        if context.ours:  # a folder holding only mountcal's own outputs: say why nothing was taken
            found += f"; set aside {len(context.ours)} file(s) mountcal wrote, e.g. {context.ours[0]}"
        raise InputError(
            ", ".join(map(str, inputs)) or "INPUTS",
            "log files (" + ", ".join(sorted(log_suffixes())) + "), log folders (a Sensor Logger recording, a "
            "ROS 2 bag, a comma2k19 segment), folders of them, globs or a manifest CSV",
            found,
            "Check the paths; a folder is searched recursively for logs.",
        )
    return jobs


@dataclass
class _Context:
    defaults: JobDefaults
    skip: set[Path]
    ours: list[Path]
    layout: Layout
    storage: dict[str, Any]
    flags: bool
    discarded: dict[str, int] = field(default_factory=dict)


def _resolved(path: Path) -> Path:
    """The absolute path with symlinks resolved; as it is where they loop (a loop fails its own row)."""
    try:
        return path.resolve()
    except (OSError, RuntimeError):
        return Path(os.path.abspath(path))


def _jobs_of_input(item: str, ctx: _Context) -> Iterator[FleetJob]:
    path = Path(item)
    if ctx.layout == "manifest" and not (path.is_file() and _is_manifest(path)):
        raise InputError(
            item,
            "a manifest CSV (columns vehicle_id, log, …), as --layout manifest says",
            special_kind(path) or ("a folder" if path.is_dir() else "a file without those columns"),
            "Pass the manifest, or choose another --layout.",
        )
    if is_url(item):  # its logs as a local folder's: a prefix that is one log is one log
        objects = list_objects(item, ctx.storage)
        found, set_aside = storage_logs(objects, ctx.defaults.log, lambda p: _is_candidate(Path(p), ctx))
        for reason, n in set_aside.items():
            ctx.discarded[reason] = ctx.discarded.get(reason, 0) + n
        if not found:
            raise InputError(
                item,
                "log objects (" + ", ".join(sorted(log_suffixes())) + ") or log folders (a Sensor Logger recording, "
                "a ROS 2 bag, a comma2k19 segment)",
                "none",
                "Check the URL.",
            )
        yield from _grouped_jobs(found, item, ctx, origin=f"storage {item}")
    elif path.is_dir() and is_log(path, ctx.defaults.log):  # a log that is a folder (a comma2k19 segment)
        yield _file_job(Found(item, str(_resolved(path))), ctx, origin=item)
    elif path.is_dir():
        files = []
        for file in _walk_logs(path, ctx.skip, ctx.defaults.log):
            if file.is_file() and written_by_mountcal(file):
                ctx.ours.append(file)
                continue
            files.append(Found(str(file), str(_resolved(file))))
        yield from _grouped_jobs(files, item, ctx, origin=f"folder {item}")
    elif path.is_file():
        if _resolved(path) in ctx.skip:
            raise InputError(
                item,
                "an input other than the fleet's own output",
                "the output table (or its vehicles table) named as an input",
                "Choose another -o path; mountcal never overwrites its input.",
            )
        if _is_manifest(path):
            yield from read_manifest(path, ctx.defaults)
        elif written_by_mountcal(path):
            raise InputError(
                item,
                "a log as recorded",
                "a file mountcal wrote (a fleet table, or a log already rotated into the vehicle frame)",
                "Pass the original log.",
            )
        else:
            yield _file_job(Found(item, str(_resolved(path))), ctx, origin=item)
    elif _GLOB_CHARS.search(item):
        matches = [Path(m) for m in sorted(glob(item, recursive=True), key=natural_key)]
        matched = [m for m in matches if m.is_file() and _resolved(m) not in ctx.skip and not _is_protocol(m)]
        if not matched:
            raise InputError(item, "a glob matching log files", "no match", "Check the pattern (quote it).")
        taken = []
        for file in matched:
            if written_by_mountcal(file):
                ctx.ours.append(file)
                continue
            taken.append(Found(str(file), str(_resolved(file))))
        yield from _grouped_jobs(taken, item, ctx, origin=f"glob {item}")
    else:
        kind = special_kind(path)
        raise InputError(
            item,
            "a log file, a folder of logs, a glob, a manifest CSV or a storage URL (s3://bucket/LOG)",
            kind or "nothing at this path",
            "Check the path." if kind is None else "Pass a regular file; mountcal reads no devices or FIFOs.",
        )


def _is_candidate(path: Path, ctx: _Context) -> bool:
    """A file some reader takes, or a CANedge split the layout counts as unreadable."""
    return (is_log(path, ctx.defaults.log) or unreadable_split(path.name)) and not _is_protocol(path)


def _grouped_jobs(files: Sequence[Found], item: str, ctx: _Context, origin: str) -> Iterator[FleetJob]:
    """The jobs of a folder's, glob's or URL's files in the chosen (or inferred) layout."""
    layout: Literal["canedge", "folders"] = (
        "canedge" if ctx.layout == "canedge" else "folders" if ctx.layout == "folders" else infer_layout(files, item)
    )
    grouped: Grouped = group(files, layout)
    for reason, n in grouped.set_aside.items():
        ctx.discarded[reason] = ctx.discarded.get(reason, 0) + n
    for single in grouped.singles:
        yield _file_job(single, ctx, origin=origin)
    for session in grouped.sessions:
        splits = session.splits
        yield FleetJob(
            vehicle_id=session.device,
            log=session.folder,
            job=LogJob(
                paths=tuple(f.path for f in splits),
                log=ctx.defaults.log,
                detection=ctx.defaults.detection,
                protocol=None,
                uphill_azimuth_deg=ctx.defaults.uphill_azimuth_deg,
                options=ctx.defaults.options,
                use=ctx.defaults.use,
            ),
            headings=ctx.defaults.headings,
            origin=origin,
            layout="canedge",
            session=session.session,
            shown=tuple(f.shown for f in splits),
            stamps=tuple(f.stamp for f in splits) if any(f.stamp for f in splits) else (),
            storage=tuple(sorted(ctx.storage.items())) if any(f.stamp for f in splits) else (),
            flags=ctx.flags,
        )


def _walk_logs(folder: Path, skip: set[Path], options: LogOptions) -> Iterator[Path]:
    """The logs under ``folder``: files a reader takes, and folders that are one log (a Sensor Logger recording,
    a ROS 2 bag, a comma2k19 segment), whose files are the log's parts and not logs of their own."""
    for root, dirs, files in os.walk(folder):
        here = Path(root)
        subfolders = sorted(
            (d for d in dirs if not d.startswith(".") and _resolved(here / d) not in skip), key=natural_key
        )
        logs = [d for d in subfolders if is_log(here / d, options)]
        yield from (here / d for d in logs)
        dirs[:] = [d for d in subfolders if d not in logs]
        for name in sorted(files, key=natural_key):
            file = here / name
            if (
                not name.startswith(".")
                and (is_log(file, options) or unreadable_split(name))
                and not _is_protocol(file)
                and _resolved(file) not in skip
            ):
                yield file


def _is_protocol(path: Path) -> bool:
    return path.name.lower().endswith(PROTOCOL_SUFFIX)


def _file_job(found: Found, ctx: _Context, origin: str) -> FleetJob:
    """One file (or a log folder), one log of the vehicle named by its parent folder."""
    defaults = ctx.defaults
    remote = found.stamp is not None
    path = Path(found.path.split("://", 1)[1]) if remote else Path(found.path)
    sheet = path.with_name(path.name.rsplit(".", 1)[0] + PROTOCOL_SUFFIX)
    # the folder as the user's layout names it (a link's folder, not its target's)
    vehicle = "" if remote else Path(found.shown).parent.name
    return FleetJob(
        vehicle_id=vehicle or path.parent.name,
        log=found.shown,
        job=LogJob(
            paths=(found.path,),
            log=defaults.log,
            detection=defaults.detection,
            protocol=str(sheet) if not remote and sheet.is_file() else None,
            uphill_azimuth_deg=defaults.uphill_azimuth_deg,
            options=defaults.options,
            use=defaults.use,
        ),
        headings=defaults.headings,
        origin=origin,
        shown=(found.shown,),
        stamps=(found.stamp,) if remote else (),
        storage=tuple(sorted(ctx.storage.items())) if remote else (),
        flags=ctx.flags,
        folder_objects=found.objects,
    )


def _is_manifest(path: Path) -> bool:
    if path.suffix.lower() != ".csv":
        return False
    if path.is_file():  # a header of a million columns is refused before pandas reads it
        csv_columns(path, str(path), charge=False)
    try:
        columns = pd.read_csv(path, nrows=0, skipinitialspace=True, **_read_as(path)).columns
    except Exception:  # unreadable: not a manifest; the log reader will say what is wrong with it
        return False
    return all(c in {str(col).strip() for col in columns} for c in MANIFEST_REQUIRED)


def _read_as(path: Path) -> dict[str, str]:
    """How to read a manifest: the dialect every table is read in (``,``, ``;`` or tab; ``#`` lines above the
    header; :func:`mountcal.io.table.mapped.dialect`). A spreadsheet saved in a German or French locale writes ``;``."""
    with path.open("rb") as f:
        head = f.read(1 << 16)
    return {"comment": "#", **dialect(head, str(path))[1]}


def read_manifest(path: str | Path, defaults: JobDefaults | None = None) -> list[FleetJob]:
    """The jobs of a manifest CSV (columns :data:`MANIFEST_COLUMNS`), in row order.

    Raises
    ------
    InputError
        A required column is missing, a column is unknown (a typo would silently lose a setting),
        or a cell cannot be read (the message names the row).
    """
    path = input_file(path, "a manifest CSV")
    defaults = defaults or JobDefaults()
    try:
        read_as = _read_as(path)
        df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True, **read_as)
    except InputError:
        raise
    except Exception as err:  # pandas raises many types for malformed files
        raise InputError(str(path), "a manifest CSV", f"a file that does not parse ({err})", "Fix the CSV.") from err
    df = df.rename(columns=lambda c: str(c).strip())
    missing = [c for c in MANIFEST_REQUIRED if c not in df.columns]
    unknown = [c for c in df.columns if c not in MANIFEST_COLUMNS]
    if missing or unknown:
        raise InputError(
            str(path),
            f"manifest columns {', '.join(MANIFEST_REQUIRED)} and optionally "
            + ", ".join(MANIFEST_COLUMNS[len(MANIFEST_REQUIRED) :]),
            (f"no column {', '.join(missing)}" if missing else f"unknown column(s) {', '.join(unknown)}"),
            "Rename the columns (a misspelt column would silently lose its setting).",
        )
    base = path.resolve().parent
    flags = flags_on()
    jobs = []
    for i, row in enumerate(df.to_dict("records")):
        where = f"{path} row {i + 2}"  # the header is line 1
        cells = {k: str(v).strip() for k, v in row.items()}
        vehicle = cells["vehicle_id"]
        if not vehicle or not cells["log"]:
            raise InputError(where, "a vehicle_id and a log", "an empty cell", "Fill the row or delete it.")
        paths = _manifest_log_paths(cells["log"], base)
        log_options = replace(
            defaults.log,
            dbc=_rel(cells.get("dbc"), base) or defaults.log.dbc,
            mapping=_rel(cells.get("mapping"), base) or defaults.log.mapping,
            channel=_int(cells["channel"], where, "channel") if cells.get("channel") else defaults.log.channel,
            topic=cells.get("topic") or defaults.log.topic,
        )
        if "sep" in read_as:  # `;` or tab between cells: a comma in a number is a decimal comma (30,5)
            cells["uphill_azimuth_deg"] = cells.get("uphill_azimuth_deg", "").replace(",", ".")
        azimuth = (
            _float(cells["uphill_azimuth_deg"], where, "uphill_azimuth_deg")
            if cells.get("uphill_azimuth_deg")
            else defaults.uphill_azimuth_deg
        )
        jobs.append(
            FleetJob(
                vehicle_id=vehicle,
                log=" + ".join(str(p) for p in paths),
                job=LogJob(
                    paths=tuple(str(p.resolve()) for p in paths),
                    log=log_options,
                    detection=defaults.detection,
                    protocol=_rel(cells.get("protocol_sheet"), base),
                    uphill_azimuth_deg=azimuth,
                    options=defaults.options,
                    use=defaults.use,
                ),
                headings=defaults.headings,
                start_time=parse_start_time(cells["start_time"], where) if cells.get("start_time") else None,
                origin=where,
                layout="manifest",
                shown=tuple(_as_given(p, base, path.parent) for p in paths),
                flags=flags,
            )
        )
    return jobs


def _manifest_log_paths(entry: str, base: Path) -> list[Path]:
    """The files of a manifest's ``log`` cell; an unmatched name is kept so that its row fails clearly."""
    pattern = entry if Path(entry).is_absolute() else str(base / entry)
    if _GLOB_CHARS.search(entry):
        matches = sorted((Path(m) for m in glob(pattern, recursive=True) if Path(m).is_file()), key=natural_key)
        return matches or [Path(pattern)]
    return [Path(pattern)]


def _as_given(file: Path, base: Path, given_base: Path) -> str:
    """A manifest's file as the user would write it: below the manifest's folder as they named it."""
    try:
        return str(given_base / file.relative_to(base))
    except ValueError:
        return str(file)


def _rel(value: str | None, base: Path) -> str | None:
    if not value:
        return None
    return str(Path(value) if Path(value).is_absolute() else (base / value).resolve())


def _float(value: str, where: str, column: str) -> float:
    try:
        out = float(value)
    except ValueError:
        out = math.nan
    if not math.isfinite(out):
        raise InputError(where, f"a number in {column}", repr(value), "Write a finite number or leave it empty.")
    return out


def _int(value: str, where: str, column: str) -> int:
    try:
        return int(value)
    except ValueError as err:
        raise InputError(where, f"an integer in {column}", repr(value), "Write an integer or leave it empty.") from err


def parse_start_time(value: str, where: str) -> str:
    """ISO 8601 UTC of a manifest's ``start_time`` (a time without a zone is taken as UTC)."""
    try:
        stamp = pd.Timestamp(value)
    except (ValueError, TypeError) as err:
        raise InputError(
            where, "start_time as ISO 8601 (2024-05-01T08:30:00Z)", repr(value), "Fix the cell or leave it empty."
        ) from err
    if stamp is pd.NaT:
        raise InputError(where, "start_time as ISO 8601", repr(value), "Fix the cell or leave it empty.")
    stamp = stamp.tz_localize("UTC") if stamp.tzinfo is None else stamp.tz_convert("UTC")
    return str(stamp.isoformat())
