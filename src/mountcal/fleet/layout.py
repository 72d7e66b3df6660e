"""How a fleet's files map to vehicles and logs: the layouts, stated or inferred from the names.

- ``folders``: every log file is one log; its vehicle is its parent folder.
- ``canedge``: CSS Electronics' CANedge uploads ``LOG/<device serial>/<session>/<split>.MF4``: the
  device is the vehicle, a session (one power cycle, 8 hex digits) is one log, and its splits
  (``<split counter>[-<start time, hex Unix seconds>].MF4``, 10 minutes each by default) are joined
  in time order. As CSS's own ``canedge-browser`` lists them: device and session folders sorted by
  name, a split counter seen twice keeps its first file (an upload repeated under another time
  stamp). Compressed or encrypted splits (``.MFC``, ``.MFE``, ``.MFM``) are counted, not read
  (decompress them with CSS's ``mdf2finalized`` first).
- ``manifest``: a CSV naming each log's vehicle (:func:`mountcal.fleet.inputs.read_manifest`).

:func:`infer_layout` chooses ``canedge`` for files that all sit in that layout, ``folders`` for files
none of which do, and refuses a mixture (the user says which with ``--layout``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Literal

from mountcal.core.errors import InputError
from mountcal.fleet.storage import RemoteObject

Layout = Literal["auto", "canedge", "folders", "manifest"]
LAYOUTS = ("auto", "canedge", "folders", "manifest")
SESSION = re.compile(r"^[0-9A-Fa-f]{8}$")
SPLIT = re.compile(r"^(?P<split>[0-9A-Fa-f]{8})(?:-(?P<time>[0-9A-Fa-f]{8}))?\.(?P<ext>mf4|mfc|mfe|mfm)$", re.I)
UNREADABLE_SPLITS = ("mfc", "mfe", "mfm")  # CANedge's compressed and encrypted formats


@dataclass(frozen=True)
class Found:
    """A file found for the fleet: how the user sees it, and where a reader finds it.

    ``path`` is the absolute local path or the object's URL (a prefix's, for a log that is a folder of
    objects); ``stamp`` identifies an object's version (None for a local file, whose bytes are hashed).
    """

    shown: str
    path: str
    stamp: str | None = None
    objects: tuple[RemoteObject, ...] = ()  # a log that is a prefix in storage: its objects (paths below it)

    @property
    def parts(self) -> tuple[str, ...]:
        return PurePath(self.path.split("://", 1)[-1]).parts


@dataclass(frozen=True)
class Session:
    """One CANedge session: device, session folder, its splits in split-counter order."""

    device: str
    session: str
    folder: str  # the session folder as the user sees it
    splits: tuple[Found, ...]


@dataclass
class Grouped:
    """Files grouped by a layout, and what was set aside, counted by reason."""

    sessions: list[Session] = field(default_factory=list)
    singles: list[Found] = field(default_factory=list)  # one log each (folders layout)
    set_aside: dict[str, int] = field(default_factory=dict)

    def count(self, reason: str, n: int = 1) -> None:
        self.set_aside[reason] = self.set_aside.get(reason, 0) + n


def natural_key(name: str | PurePath) -> tuple[tuple[int, int | str], ...]:
    """Sort key that orders ``log_9`` before ``log_10``."""
    return tuple((0, int(t)) if t.isdigit() else (1, t) for t in re.split(r"(\d+)", str(name)) if t)


def unreadable_split(name: str) -> bool:
    """Whether a file is a CANedge log mountcal cannot read (compressed or encrypted), by its suffix
    whatever its name (a split renamed stays one): the layout counts it instead of leaving it unseen."""
    return PurePath(name).suffix.lower().lstrip(".") in UNREADABLE_SPLITS


def canedge_split(found: Found) -> re.Match[str] | None:
    """The split-name match of a file in the CANedge layout (session folder of 8 hex digits, a device above)."""
    parts = found.parts
    if len(parts) < 3 or not SESSION.match(parts[-2]):
        return None
    return SPLIT.match(parts[-1])


def infer_layout(files: Sequence[Found], where: str) -> Literal["canedge", "folders"]:
    """``canedge`` when every file is a CANedge split, ``folders`` when none is.

    Raises
    ------
    InputError
        Some are and some are not: which files are logs of which vehicle would be a guess.
    """
    matched = sum(canedge_split(f) is not None for f in files)
    if matched == 0:
        return "folders"
    if matched == len(files):
        return "canedge"
    example = next(f.shown for f in files if canedge_split(f) is None)
    raise InputError(
        where,
        "one layout: every log a CANedge split (LOG/<device>/<session>/<split>.MF4) or none",
        f"{matched} files in the CANedge layout and {len(files) - matched} not (e.g. {example})",
        "Say which with --layout canedge (the others are set aside and counted) or --layout folders "
        "(each file one log of the vehicle named by its folder).",
    )


def group(files: Sequence[Found], layout: Literal["canedge", "folders"]) -> Grouped:
    """The files as sessions (``canedge``) or single logs (``folders``), in name order."""
    out = Grouped()
    if layout == "folders":
        out.singles = list(files)
        return out
    by_session: dict[tuple[str, ...], dict[int, Found]] = {}
    for f in sorted(files, key=lambda f: f.path):
        match = canedge_split(f)
        if match is None:
            out.count("files outside the CANedge layout (LOG/<device>/<session>/<split>.MF4)")
            continue
        if match["ext"].lower() in UNREADABLE_SPLITS:
            out.count("compressed or encrypted CANedge splits (.MFC/.MFE/.MFM; run mdf2finalized first)")
            continue
        splits = by_session.setdefault(f.parts[:-1], {})
        counter = int(match["split"], 16)
        if counter in splits:  # canedge-browser keeps the first file of a split counter
            out.count("CANedge splits uploaded twice (same split counter; the first is kept)")
            continue
        splits[counter] = f
    for key, splits in by_session.items():
        first = splits[min(splits)]
        shown_folder = first.shown.rsplit("/", 1)[0] if "/" in first.shown else "."
        ordered = tuple(splits[k] for k in sorted(splits))
        out.sessions.append(Session(device=key[-2], session=key[-1], folder=shown_folder, splits=ordered))
    return out


__all__ = [
    "LAYOUTS",
    "Found",
    "Grouped",
    "Layout",
    "Session",
    "canedge_split",
    "group",
    "infer_layout",
    "natural_key",
    "unreadable_split",
]
