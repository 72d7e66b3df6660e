"""Third-party extensions found through Python entry points (``importlib.metadata``).

A package extends mountcal by declaring an entry point in a group (``mountcal.readers`` for log
formats, ``mountcal.loop.model_choice`` for effects); the module named is imported only when the group is
first used, so installing a plugin costs nothing to ``mountcal --help``. A plugin that fails to
import is an :class:`~mountcal.core.errors.InputError` naming the plugin, its package and the cause.

Loading is isolated: whatever the module does at import — raise, call ``sys.exit``, raise
``KeyboardInterrupt``, print — cannot end the command or write into its results. An exit or an
exception becomes that InputError; text printed on stdout goes to stderr, reported with the
plugin's name (stdout carries results: JSON, CSV).
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from mountcal.core.errors import InputError

_log = logging.getLogger("mountcal")


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
            with output_to_stderr(self.where):
                return self.entry_point.load()
        except (Exception, SystemExit, KeyboardInterrupt) as err:  # the plugin's, not the user's: named, no traceback
            raise self.failed("an importable", err) from err

    @property
    def where(self) -> str:
        """The plugin in messages: name, entry point and package."""
        origin = f" of the package {self.package}" if self.package else ""
        return f"plugin {self.name!r} ({self.value}){origin}"

    def failed(self, expected: str, err: BaseException) -> InputError:
        """The InputError for ``err`` raised by this plugin (``expected``: what it should have been)."""
        return InputError(
            self.where,
            f"{expected} {self.group} entry point",
            f"{type(err).__name__}: {err}",
            f"Fix or uninstall the package declaring it (pip uninstall {self.package or '...'}).",
        )


@contextlib.contextmanager
def output_to_stderr(where: str) -> Iterator[None]:
    """Keep stdout for results while a plugin runs: Python-level prints are caught and logged on stderr
    under ``where``; bytes written to file descriptor 1 directly go to stderr."""
    caught = io.StringIO()
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:  # no descriptor 1
        saved = -1
    if saved >= 0:
        sys.stderr.flush()
        os.dup2(2, 1)
    try:
        with contextlib.redirect_stdout(caught):
            yield
    finally:
        if saved >= 0:
            os.dup2(saved, 1)
            os.close(saved)
        if caught.getvalue():
            _log.warning("%s printed on stdout (moved to stderr): %s", where, caught.getvalue().rstrip()[:2000])


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


__all__ = ["Plugin", "entry_points_of", "output_to_stderr"]
