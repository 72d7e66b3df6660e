"""Which reader reads a path: the built-in formats and those of installed plugins.

Built-in readers (in this order; the first that claims a path reads it):

- ``mcap``: ``.mcap``, ROS 2 Imu in CDR or JSON (:mod:`mountcal.io.mcap`);
- ``bag``: ``.bag`` (ROS 1), a ROS 2 bag folder (``metadata.yaml``) or ``.db3`` (:mod:`mountcal.io.bag`);
- ``can``: ``.blf .asc .log .trc .mf4 .mdf``, and ``.csv`` when a DBC is given (:mod:`mountcal.io.can`);
- ``sensor-logger``: a Sensor Logger recording, its ``.zip`` or its folder (:mod:`mountcal.io.sensor_logger`);
- ``table``: ``.csv .parquet .pq`` sample tables (:mod:`mountcal.io.table`);
- ``comma2k19``: a comma2k19 segment folder (:mod:`mountcal.io.comma2k19`).

**Plugins.** A package adds a format by declaring, in its metadata, an entry point in the group
``mountcal.readers`` naming a :class:`~mountcal.io.reader.LogReader` subclass (or instance)::

    [project.entry-points."mountcal.readers"]
    imutxt = "mountcal_imutxt:ImuTxtReader"

Plugins are loaded when a path is claimed by no built-in reader, or the whole list is asked for
(``mountcal --help`` and reading a built-in format load none), and come after the built-in readers.
A plugin that fails to load is reported once (a warning naming it) and left
out; a file only it could have read is then refused with its name and the cause.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.core.errors import InputError, MountcalError
from mountcal.core.plugins import Plugin, entry_points_of, output_to_stderr
from mountcal.io.magic import check_named_for_content, decompress_hint
from mountcal.io.reader import LogReader

if TYPE_CHECKING:
    from mountcal.io.folder import Folder
    from mountcal.io.reader import LogOptions
    from mountcal.io.samples import LogSummary, Samples

GROUP = "mountcal.readers"
BUILTIN = (
    "mountcal.io.mcap.reader:McapReader",
    "mountcal.io.bag.reader:BagReader",
    "mountcal.io.can.reader:CanReader",
    "mountcal.io.sensor_logger:SensorLoggerReader",
    "mountcal.io.table.reader:TableReader",
    "mountcal.io.comma2k19:Comma2k19Reader",
)
_log = logging.getLogger("mountcal")


def _load_builtin(spec: str) -> LogReader:
    module, _, name = spec.partition(":")
    cls: type[LogReader] = getattr(importlib.import_module(module), name)
    return cls()


def _as_reader(plugin: Plugin) -> LogReader:
    obj = plugin.load()
    try:
        reader = obj() if isinstance(obj, type) and issubclass(obj, LogReader) else obj
    except (Exception, SystemExit) as err:
        raise plugin.failed("a reader class that can be made, as an", err) from err
    if not isinstance(reader, LogReader):
        raise InputError(
            plugin.where,
            "a mountcal.io.reader.LogReader subclass or instance",
            f"{type(obj).__name__} {obj!r}"[:200],
            "Point the entry point at the reader class.",
        )
    return _PluginReader(reader, plugin)


class _PluginReader(LogReader):
    """A plugin's reader, whose every call is isolated: an exception of the plugin's own (a bug, a
    ``sys.exit``) is an InputError naming the plugin and the file, its prints go to stderr."""

    def __init__(self, reader: LogReader, plugin: Plugin) -> None:
        self._reader, self._plugin = reader, plugin
        self.name, self.suffixes, self.description = reader.name, reader.suffixes, reader.description  # type: ignore[misc]

    @contextlib.contextmanager
    def _call(self, what: str, path: Path | Folder) -> Iterator[None]:
        try:
            with output_to_stderr(self._plugin.where):
                yield
        except MountcalError:
            raise
        except (Exception, SystemExit) as err:
            raise self._plugin.failed(f"a reader that can {what} {path}, as an", err) from err

    def claims(self, path: Path, options: LogOptions) -> bool:
        with self._call("judge", path):
            return bool(self._reader.claims(path, options))

    def claims_folder(self, folder: Folder, options: LogOptions) -> bool:
        with self._call("judge the folder", folder):
            return bool(self._reader.claims_folder(folder, options))

    def read(self, path: Path, options: LogOptions) -> Samples:
        with self._call("read", path):
            return self._reader.read(path, options)

    def iter_chunks(self, path: Path, options: LogOptions, max_samples: int) -> Iterator[Samples]:
        with self._call("read", path):
            yield from self._reader.iter_chunks(path, options, max_samples)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        with self._call("list", path):
            return self._reader.inspect(path, options)


@cache
def _builtin() -> tuple[LogReader, ...]:
    return tuple(_load_builtin(spec) for spec in BUILTIN)


@cache
def _registry() -> tuple[tuple[LogReader, ...], tuple[InputError, ...]]:
    readers = list(_builtin())
    broken = []
    for plugin in entry_points_of(GROUP):
        try:
            readers.append(_as_reader(plugin))
        except InputError as err:
            _log.warning("a log-format plugin is left out: %s", err)
            broken.append(err)
    return tuple(readers), tuple(broken)


def readers() -> tuple[LogReader, ...]:
    """Every reader: the built-in ones, then those of plugins, in the order they are tried."""
    return _registry()[0]


def log_suffixes() -> frozenset[str]:
    """The suffixes of every reader (with the dot, lower case)."""
    return frozenset(s for r in readers() for s in r.suffixes)


def _claimant(path: Path, options: LogOptions) -> LogReader | None:
    """The first reader claiming ``path``: the entry points are scanned only when no built-in reader claims it."""
    for reader in _builtin():
        if reader.claims(path, options):
            return reader
    for reader in readers()[len(BUILTIN) :]:  # the plugins' readers, after the built-in ones
        if reader.claims(path, options):
            return reader
    return None


def is_log(path: Path, options: LogOptions) -> bool:
    """Whether some reader takes ``path`` (fleet's test of which files of a folder are logs)."""
    return _claimant(path, options) is not None


def is_log_folder(folder: Folder, options: LogOptions) -> bool:
    """Whether some reader takes a folder as one log, judged by its files' names (:meth:`LogReader.claims_folder`):
    fleet's test of which prefixes in object storage are one log, as :func:`is_log` of a local folder."""
    if any(reader.claims_folder(folder, options) for reader in _builtin()):
        return True
    return any(reader.claims_folder(folder, options) for reader in readers()[len(BUILTIN) :])


def reader_for(path: Path, options: LogOptions) -> LogReader:
    """The first reader claiming ``path``.

    Raises
    ------
    InputError
        No reader claims it: the message lists the formats, and any plugin that failed to load.
    """
    reader = _claimant(path, options)
    if reader is not None:
        check_named_for_content(path)  # an MF4 named .blf, a Parquet file named .csv: not read as its name says
        return reader
    formats = "; ".join(f"{r.description} ({' '.join(r.suffixes)})" for r in readers() if r.suffixes)
    broken = _registry()[1]
    todo = decompress_hint(path) or "Convert it, or name it by its format."
    if broken:
        todo += " These format plugins failed to load: " + "; ".join(str(b) for b in broken)
    found = "a folder no reader takes" if path.is_dir() else f"a file ending in {path.suffix or '(nothing)'}"
    raise InputError(str(path), f"a log mountcal reads: {formats}", found, todo)


__all__ = ["BUILTIN", "GROUP", "is_log", "is_log_folder", "log_suffixes", "reader_for", "readers"]
