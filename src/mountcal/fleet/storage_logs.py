"""The logs among the objects listed under a URL, found as a walk of a local folder finds them.

- A **prefix that is one log** — a Sensor Logger recording, a ROS 2 bag, a comma2k19 segment: judged by the
  readers' own rule from its objects' names (:func:`mountcal.io.registry.is_log_folder`, the rule that
  judges a local folder) — is one log, named by the prefix's URL, keyed by its objects' paths and stamps
  (:func:`~mountcal.fleet.storage.folder_stamp`) and fetched whole into one local folder by the worker. Its
  objects are not logs of their own; a log folder inside it is part of it (the outermost one counts).
- Every **other object** a reader takes (by its name: a suffix) is one log.
- The rest is **set aside and counted** by reason: objects no reader takes, and objects of a log folder whose
  names no local file can have (an empty, ``.`` or ``..`` part).

The logs come in a local walk's order: in each folder its log folders, then its files, then its other folders,
each in natural order.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import PurePosixPath

from mountcal.fleet.layout import Found, natural_key
from mountcal.fleet.storage import RemoteObject, folder_stamp, is_file_path
from mountcal.io.folder import Listing
from mountcal.io.reader import LogOptions
from mountcal.io.registry import is_log_folder

_Order = tuple[tuple[int, tuple[tuple[int, int | str], ...]], ...]  # a log's place in a walk's order
NOT_LOGS = "objects in storage that are no log nor part of one (no reader takes them)"
NO_FILE_PATH = "objects of a log folder in storage whose names no local file can have (an empty, . or .. part)"


def storage_logs(
    objects: Sequence[RemoteObject], options: LogOptions, takes: Callable[[PurePosixPath], bool]
) -> tuple[list[Found], dict[str, int]]:
    """The logs among ``objects`` (listed under one URL), and what was set aside, counted by reason.

    ``takes`` says whether an object outside a log folder is a log (its path inside the bucket).
    """
    listing = Listing(o.relative for o in objects if o.relative and is_file_path(o.relative))
    folders = _log_folders(listing, options)
    members: dict[str, list[RemoteObject]] = {folder: [] for folder in folders}
    found: list[tuple[_Order, Found]] = []
    set_aside: Counter[str] = Counter()
    for obj in objects:
        folder = _log_folder_of(obj.relative, folders) if obj.relative else None
        if folder is not None:
            if is_file_path(obj.relative):  # its path below the log folder
                members[folder].append(
                    replace(obj, relative=obj.relative[len(folder) + 1 :] if folder else obj.relative)
                )
            else:
                set_aside[NO_FILE_PATH] += 1
        elif takes(PurePosixPath(obj.url.split("://", 1)[1])):
            found.append((_walk_order(obj.relative, folder=False), Found(obj.url, obj.url, obj.stamp)))
        else:
            set_aside[NOT_LOGS] += 1
    for folder, inside in members.items():
        if not inside:  # all its objects set aside
            continue
        first = inside[0]  # the prefix's URL from an object's own (the protocol and bucket as listed)
        url = first.url[: len(first.url) - len(first.relative)].rstrip("/")
        found.append((_walk_order(folder, folder=True), Found(url, url, folder_stamp(inside), tuple(inside))))
    return [f for _, f in sorted(found, key=lambda pair: pair[0])], dict(set_aside)


def _log_folders(listing: Listing, options: LogOptions) -> set[str]:
    """The folders of the listing that are one log, the outermost only (its folders are its parts)."""
    logs, todo = set(), [""]
    while todo:
        folder = todo.pop()
        if is_log_folder(listing.folder(folder), options):
            logs.add(folder)
            continue
        todo.extend(f"{folder}/{name}" if folder else name for name in listing.subfolders(folder))
    return logs


def _log_folder_of(relative: str, folders: set[str]) -> str | None:
    """The log folder holding the object at ``relative``, if any (by its key's prefixes: a key with an empty or
    ``..`` part below a log folder is found in it too)."""
    if "" in folders:
        return ""
    parts = relative.split("/")
    for k in range(1, len(parts)):
        prefix = "/".join(parts[:k])
        if prefix in folders:
            return prefix
    return None


def _walk_order(relative: str, folder: bool) -> _Order:
    """Where a local walk (:func:`mountcal.fleet.inputs._walk_logs`) meets a log: in each folder its log
    folders (0), then its files (1), then what is inside its other folders (2)."""
    parts = relative.split("/") if relative else []
    above = tuple((2, natural_key(p)) for p in parts[:-1])
    return (*above, (0 if folder else 1, natural_key(parts[-1]))) if parts else above


__all__ = ["NOT_LOGS", "NO_FILE_PATH", "storage_logs"]
