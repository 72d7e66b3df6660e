"""A folder as a reader judges whether it is one log (:meth:`~mountcal.io.reader.LogReader.claims_folder`):
the names of its files and subfolders, nothing of their contents.

The same rule then judges a local folder (:class:`LocalFolder`) and a prefix in object storage, whose
objects are only listed (:class:`Listing`): a Sensor Logger recording, a ROS 2 bag or a comma2k19 segment
uploaded to a bucket is one log there as it is on disk.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol


class Folder(Protocol):
    """What a folder's claim may ask: relative paths are POSIX (``"processed_log/IMU"``)."""

    def files(self) -> frozenset[str]:
        """The names of the files directly in the folder."""
        ...

    def has_file(self, relative: str) -> bool:
        """Whether the folder holds the file ``relative``."""
        ...

    def has_folder(self, relative: str) -> bool:
        """Whether the folder holds the subfolder ``relative``."""
        ...


@dataclass(frozen=True)
class LocalFolder:
    """A folder on disk (:class:`Folder`)."""

    path: Path

    def __str__(self) -> str:
        return str(self.path)

    def files(self) -> frozenset[str]:
        try:
            with os.scandir(self.path) as entries:
                return frozenset(e.name for e in entries if e.is_file())  # a link to a file is a file, as is_file says
        except OSError:  # gone, or not readable: no files to claim it by
            return frozenset()

    def has_file(self, relative: str) -> bool:
        return (self.path / relative).is_file()

    def has_folder(self, relative: str) -> bool:
        return (self.path / relative).is_dir()


class Listing:
    """Files named by relative POSIX paths (the objects listed under a URL) as a tree of folders; ``""`` is
    the top. A folder exists when some file lies below it (object storage has no empty folders)."""

    def __init__(self, names: Iterable[str]) -> None:
        self._files: dict[str, set[str]] = {"": set()}
        self._subfolders: dict[str, set[str]] = {"": set()}
        for name in names:
            folder, _, file = name.rpartition("/")
            self._files.setdefault(folder, set()).add(file)
            while folder:
                above, _, last = folder.rpartition("/")
                inside = self._subfolders.setdefault(above, set())
                if last in inside:  # known, and so are the folders above it
                    break
                inside.add(last)
                self._subfolders.setdefault(folder, set())
                folder = above

    def subfolders(self, folder: str) -> frozenset[str]:
        """The names of the folders directly in ``folder``."""
        return frozenset(self._subfolders.get(folder, ()))

    def folder(self, at: str) -> Folder:
        """The folder ``at`` (``""``: the top) as a claim sees it."""
        return _Listed(self, at)

    def files_in(self, folder: str) -> frozenset[str]:
        """The names of the files directly in ``folder``."""
        return frozenset(self._files.get(folder, ()))

    def is_folder(self, folder: str) -> bool:
        return folder in self._subfolders


@dataclass(frozen=True)
class _Listed:
    listing: Listing
    at: str

    def __str__(self) -> str:
        return self.at or "."

    def _path(self, relative: str) -> str:
        return f"{self.at}/{relative}" if self.at else relative

    def files(self) -> frozenset[str]:
        return self.listing.files_in(self.at)

    def has_file(self, relative: str) -> bool:
        parent, _, name = self._path(relative).rpartition("/")
        return name in self.listing.files_in(parent)

    def has_folder(self, relative: str) -> bool:
        return self.listing.is_folder(self._path(relative))


__all__ = ["Folder", "Listing", "LocalFolder"]
