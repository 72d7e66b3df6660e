"""Third-party extensions found through Python entry points (``importlib.metadata``).

A package extends mountcal by declaring an entry point in a group (``mountcal.readers`` for log
formats, ``mountcal.effects`` for effects); the module named is imported only when the group is
first used, so installing a plugin costs nothing to ``mountcal --help``. A plugin that fails to
import is an :class:`~mountcal.errors.InputError` naming the plugin, its package and the cause.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from mountcal.errors import InputError


@dataclass(frozen=True)
class Plugin:
    """One entry point of a group: where it comes from, and how to load it."""

    group: str
    name: str
    value: str  # "module:attribute"
    package: str  # the distribution declaring it ("" when unknown)
    entry_point: EntryPoint

    def load(self) -> Any:
        """The object the entry point names.

        Raises
        ------
        InputError
            The module does not import or lacks the attribute: the message names the plugin.
        """
        try:
            return self.entry_point.load()
        except Exception as err:  # a plugin's own bug or missing dependency: named, not a traceback
            origin = f" of the package {self.package}" if self.package else ""
            raise InputError(
                f"plugin {self.name!r} ({self.value}){origin}",
                f"an importable {self.group} entry point",
                f"{type(err).__name__}: {err}",
                f"Fix or uninstall the package declaring it (pip uninstall {self.package or '...'}).",
            ) from err


def entry_points_of(group: str) -> list[Plugin]:
    """The entry points declared in ``group`` by installed packages, by name (not yet imported).

    Two distributions on the path with the same name (a package installed twice) declare the same
    entry point: it is listed once.
    """
    found: dict[tuple[str, str], Plugin] = {}
    for ep in entry_points(group=group):
        dist = getattr(ep, "dist", None)
        package = dist.metadata["Name"] if dist is not None else ""
        found.setdefault((ep.name, ep.value), Plugin(group, ep.name, ep.value, package or "", ep))
    return sorted(found.values(), key=lambda p: p.name)


__all__ = ["Plugin", "entry_points_of"]
