"""The one interface of a log format: :class:`LogReader`.

A format is a subclass naming its suffixes and reading a file into
:class:`~mountcal.io.samples.Samples`; :mod:`mountcal.io.registry` picks the reader of a path, for
reading whole (``read_log``), streaming in chunks (``rotate``), listing (``inspect``) and finding
logs in folders (``fleet``). A third-party format is one module with one such class, declared in
the entry-point group ``mountcal.readers`` (see :mod:`mountcal.io.registry`).

This module is light (no numpy at import): the registry lists formats without loading them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Literal

if TYPE_CHECKING:
    from mountcal.io.folder import Folder
    from mountcal.io.samples import LogSummary, Samples

CHUNK_SAMPLES = (
    100_000  # samples per chunk of a streamed log (rotate --chunk, every reader's iter_chunks): the memory bound
)


@dataclass(frozen=True)
class LogOptions:
    """How to read a log: the DBC and mapping for CAN, the topic (and field) for MCAP and ROS bags, the
    column map and acceleration unit for tables (:mod:`mountcal.io.table.layout`); for every format, the
    axis map (``"x,-y,z"``: a signed permutation of the device's axes, applied after the reader's own)
    and the unit of the heading channel (``"deg"`` or ``"rad"``; unstated, degrees are checked)."""

    dbc: str | tuple[str, ...] | None = None  # several DBCs: their messages together (no clash allowed)
    mapping: str | None = None
    channel: int | None = None
    topic: str | None = None
    field: str | None = None  # the Imu or Vector3 inside the topic's message ("imu", "imu.linear_acceleration")
    columns: tuple[tuple[str, str], ...] | None = None  # a table's column map: (role, "COLUMN[:UNIT]") pairs
    unit: str | None = None  # a table's acceleration unit where neither the table nor the map gives it ("g")
    allow_truncated: bool = False  # read the whole part of a file cut short, and say so (mountcal.io.whole)
    axes: str | None = None  # every format: the device's axes onto the sensor frame
    heading_unit: Literal["deg", "rad"] | None = None  # every format: the heading channel's unit


class LogReader(ABC):
    """A log format: which paths it reads, and how.

    Class attributes
    ----------------
    name : str
        Short name (``"mcap"``, ``"can"``, ``"table"``); shown in messages.
    suffixes : tuple of str
        Lower-case file suffixes with the dot (``(".mcap",)``): how files are recognised.
    description : str
        What it reads, for the message about a file no reader takes (``"MCAP (ROS 2 Imu)"``).
    """

    name: ClassVar[str]
    suffixes: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""

    def claims(self, path: Path, options: LogOptions) -> bool:
        """Whether this reader takes ``path`` (by default: by its suffix). May look at the path,
        e.g. a folder's layout; must not be slow (fleet asks it of every file of a tree)."""
        return path.suffix.lower() in self.suffixes

    def claims_folder(self, folder: Folder, options: LogOptions) -> bool:
        """Whether this reader takes a folder holding these files as one log (a recording of several
        files), judged by the names alone: the same rule then finds such a folder on disk and under a
        prefix in object storage (``mountcal fleet s3://…``), where only the objects' names are known.
        By default no folder; a format that is a folder answers here and its :meth:`claims` of a local
        folder asks this (``claims_folder(LocalFolder(path), options)``)."""
        return False

    @abstractmethod
    def read(self, path: Path, options: LogOptions) -> Samples:
        """The whole log's samples, sorted by time; what was discarded counted in ``dropped``.

        Raises
        ------
        InputError
            A file this reader cannot read (named, with what to do).
        """

    def iter_chunks(self, path: Path, options: LogOptions, max_samples: int) -> Iterator[Samples]:
        """The log's samples in consecutive chunks of at most ``max_samples``.

        The default reads the whole log and hands it out in slices: correct, but its memory is the
        log's. A format that can stream overrides it to bound memory by ``max_samples``.
        """
        from mountcal.io.samples import slices

        yield from slices(self.read(path, options), max_samples)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        """What the log holds (``mountcal inspect``). The default reads it and lists one stream."""
        from mountcal.io.samples import summary

        return summary(self.read(path, options), self.name, self.name)


__all__ = ["LogOptions", "LogReader"]
