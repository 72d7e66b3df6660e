"""The one interface of a log format: :class:`LogReader`.

A format is a subclass naming its suffixes and reading a file into
:class:`~mountcal.samples.Samples`; :mod:`mountcal.io.registry` picks the reader of a path, for
reading whole (``read_log``), streaming in chunks (``rotate``), listing (``inspect``) and finding
logs in folders (``fleet``). A third-party format is one module with one such class, declared in
the entry-point group ``mountcal.readers`` (see :mod:`mountcal.io.registry`).

This module is light (no numpy at import): the registry lists formats without loading them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from mountcal.io.logs import LogOptions
    from mountcal.samples import LogSummary, Samples


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
        from mountcal.samples import slices

        yield from slices(self.read(path, options), max_samples)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        """What the log holds (``mountcal inspect``). The default reads it and lists one stream."""
        from mountcal.samples import summary

        return summary(self.read(path, options), self.name, self.name)


__all__ = ["LogReader"]
