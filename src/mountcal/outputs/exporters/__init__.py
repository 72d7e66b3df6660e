"""Hand a calibration to the systems that use it, each in its vendor's own conventions: the registry of exporters.

``mountcal export result.json --to FORMAT`` (:mod:`mountcal.cli.export`). A format is one
:class:`~mountcal.outputs.exporters.common.Exporter` — its ``--to`` name, the suffixes ``-o`` may end
in, one line saying what it writes, and the function writing it from a
:class:`~mountcal.core.result.Calibration` — declared in the ``EXPORTERS`` tuple of a module:

- **built-in:** every module of this package is read for ``EXPORTERS`` (in the order of their names), so a
  new format is one new file here; nothing else lists the formats. ``--to``, the suffixes ``-o`` accepts,
  ``mountcal export --help`` and the table of docs/exporters.md are made from :func:`exporters`;
- **other packages:** one entry point per format in the group ``mountcal.exporters``, named as the format,
  naming its ``Exporter``::

      [project.entry-points."mountcal.exporters"]
      csv-angles = "my_package.angles:EXPORTER"

  Its name is a ``--to`` choice with no import (:func:`names`); the module is imported when the format is
  chosen or the whole list is asked for. It cannot replace a built-in name. A plugin that fails to load,
  or whose writer raises or prints, is refused by name (:mod:`mountcal.core.plugins`).

Every built-in format is built from one :class:`Mounting` (the rotation, its σ, what was assumed), which
refuses a result whose yaw is not determined or that is not confident unless told otherwise. Definitions
and sources: docs/exporters.md. This module and the modules of this package import no numerical library
at their top: listing the formats (``--help``) stays light.
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
from functools import cache
from typing import TYPE_CHECKING

from mountcal.core.errors import InputError, MountcalError
from mountcal.core.option_names import option
from mountcal.outputs.exporters.autoware import read_parent_pose
from mountcal.outputs.exporters.child import with_child
from mountcal.outputs.exporters.common import (
    BODY_FRAME,
    Exporter,
    ExportOptions,
    Frames,
    Mounting,
    ParentPose,
    YawPolicy,
    mounting,
)

if TYPE_CHECKING:
    from mountcal.core.plugins import Plugin
    from mountcal.core.result import Calibration

GROUP = "mountcal.exporters"
_log = logging.getLogger("mountcal")


@cache
def builtin() -> dict[str, Exporter]:
    """The built-in formats by name: the ``EXPORTERS`` of every module of this package, by module name."""
    found: dict[str, Exporter] = {}
    for module in pkgutil.iter_modules(__path__):
        declared = getattr(importlib.import_module(f"{__name__}.{module.name}"), "EXPORTERS", ())
        for exporter in declared:
            if not isinstance(exporter, Exporter) or exporter.name in found:
                raise TypeError(f"{__name__}.{module.name}.EXPORTERS: {exporter!r} is not a new Exporter")
            found[exporter.name] = exporter
    return found


def names() -> tuple[str, ...]:
    """Every ``--to`` name: the built-in ones, then those other packages register (none of them imported)."""
    from mountcal.core.plugins import entry_points_of  # importlib.metadata: only when a plugin may be meant

    own = builtin()
    return (*own, *(p.name for p in entry_points_of(GROUP) if p.name not in own))


@cache
def _plugin(name: str) -> Exporter:
    from mountcal.core.plugins import entry_points_of

    for plugin in entry_points_of(GROUP):
        if plugin.name == name:
            return _as_exporter(plugin)
    raise InputError("the export format", f"one of {', '.join(names())}", repr(name), "Choose a listed format.")


def _as_exporter(plugin: Plugin) -> Exporter:
    """The plugin's exporter, its writer isolated: its exceptions and prints are refused or moved, by name."""
    from mountcal.core.plugins import output_to_stderr

    obj = plugin.load()
    if not isinstance(obj, Exporter) or obj.name != plugin.name:
        raise InputError(
            plugin.where,
            f"a mountcal.outputs.exporters.common.Exporter named {plugin.name!r}",
            f"{type(obj).__name__} {obj!r}"[:200],
            "Point the entry point at the Exporter, named as the entry point.",
        )
    write = obj.write

    def isolated(cal: Calibration, options: ExportOptions) -> str | bytes:
        try:
            with output_to_stderr(plugin.where):
                out = write(cal, options)
        except MountcalError:
            raise
        except (Exception, SystemExit) as err:
            raise plugin.failed(f"an exporter that can write {plugin.name}, as an", err) from err
        if not isinstance(out, str | bytes):
            raise plugin.failed("an exporter returning text or bytes, as an", TypeError(type(out).__name__))
        return out

    return Exporter(obj.name, obj.suffixes, obj.description, isolated, obj.frames)


def get(name: str) -> Exporter:
    """The format called ``name``.

    Raises
    ------
    InputError
        No format has that name, or the plugin declaring it cannot be loaded.
    """
    own = builtin()
    return own[name] if name in own else _plugin(name)


def exporters() -> dict[str, Exporter]:
    """Every format by name, those of other packages loaded (one that fails to load is left out, with a warning)."""
    out = dict(builtin())
    for name in names():
        if name not in out:
            try:
                out[name] = _plugin(name)
            except InputError as err:
                _log.warning("an export-format plugin is left out: %s", err)
    return out


def export(
    cal: Calibration,
    fmt: str,
    *,
    yaw: YawPolicy = "refuse",
    accept_unconfident: bool = False,
    frames: Frames | None = None,
) -> str | bytes:
    """The calibration in ``fmt`` (text, or bytes for a binary format such as ``ublox-ubx``).

    ``frames`` (parent, child, translation, the parent's pose) applies to the formats that name
    frames (those with :attr:`Exporter.frames`); giving it to another format is refused, not ignored.
    The child defaults to the frame the calibration's data were in (:func:`frames_for`).
    """
    exporter = get(fmt)
    framed = [e.name for e in builtin().values() if e.frames is not None]
    if frames is not None and exporter.frames is None:
        raise InputError(
            f"export --to {fmt}",
            f"no frame names, translation or parent pose (they apply to {', '.join(framed)})",
            f"parent {frames.parent!r}, child {frames.child!r}, translation {frames.translation_m}",
            "Leave them out for this format.",
        )
    if frames is not None and frames.parent == BODY_FRAME and frames.parent_pose is not None:
        raise InputError(
            f"the parent frame {BODY_FRAME}",
            f"no pose of its own (the pose of a parent is given in {BODY_FRAME})",
            f"a pose from {frames.parent_pose.source}",
            f"Name the parent that pose belongs to ({option('parent')}), or leave the pose out.",
        )
    return exporter.write(cal, ExportOptions(yaw, accept_unconfident, frames_for(cal, fmt, frames)))


def frames_for(cal: Calibration, fmt: str, frames: Frames | None = None) -> Frames | None:
    """The frames :func:`export` writes for ``fmt`` (None for a format that names none): ``frames`` or the
    format's own, the child named (given, else the frame the calibration's data were in, else ``imu_link``),
    with what the output says of that name (:func:`mountcal.outputs.exporters.child.with_child`)."""
    own = get(fmt).frames
    if own is None:
        return frames  # export() refuses frames given to a format that names none
    return with_child(cal, frames if frames is not None else own)


def markdown_table() -> str:
    """The table of formats in docs/exporters.md (a test keeps the page equal to it)."""
    lines = ["| `--to` | writes | `-o` may end in |", "|---|---|---|"]
    for e in builtin().values():
        suffixes = ", ".join(f"`{s}`" for s in e.suffixes) or "anything"
        lines.append(f"| `{e.name}` | {e.description} | {suffixes} |")
    return "\n".join(lines)


__all__ = [
    "GROUP",
    "ExportOptions",
    "Exporter",
    "Frames",
    "Mounting",
    "ParentPose",
    "builtin",
    "export",
    "exporters",
    "frames_for",
    "get",
    "markdown_table",
    "mounting",
    "names",
    "read_parent_pose",
]
