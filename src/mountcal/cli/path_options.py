"""Every path a command reads or writes, declared where its parser is built, and the one check made from them.

A path option is added with :func:`add_path` instead of ``add_argument``: it says whether the
path is an input or an output, what it may be (a file, or also a folder), whether ``-`` means
stdin/stdout, which files an output writes (live's ``-o PREFIX`` writes four) and the suffixes it
takes. :func:`check_paths` runs in :func:`mountcal.cli.main` before any command, from those
declarations alone:

- every input is a regular file (or a folder, where the option takes folders); the small ones (a
  DBC, a mapping, a protocol sheet, a result JSON, ...) are at most the small-input limit
  (:func:`mountcal.core.paths.input_file`);
- no output equals, aliases or replaces an input of the same command, another output, a
  directory, a device, a FIFO or a socket (:func:`mountcal.core.paths.check_outputs`);
- no output is named for another format than it writes (``rotate -o out.blf``; its declared
  ``formats``, :func:`mountcal.core.output_suffix.check_output_suffix`).

So an option added later is checked without a line in its command; ``tests/test_paths.py`` fails
for a path option added with plain ``add_argument``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NoReturn

STDIO = "-"
Formats = tuple[str, ...] | Callable[[argparse.Namespace], tuple[str, ...]]
_ATTRIBUTE = "mountcal_path"


@dataclass(frozen=True)
class PathOption:
    """What a path option names.

    Attributes
    ----------
    role : "input" or "output"
    what : str
        The file in messages ("the DBC").
    folders : bool
        An input may be a folder (a comma2k19 segment, a fleet's folder of logs).
    small : bool
        An input held whole in memory: at most :func:`mountcal.core.paths.small_input_limit` bytes.
    globs : bool
        An input may be a glob pattern (expanded by the command).
    stdio : bool
        ``-`` is stdin (input) or stdout (output).
    formats : tuple of str, or a function of the parsed arguments giving them
        For an output, the suffixes of the formats it writes (lower case, with the dot; the default
        first): a name ending in another data format's suffix is refused
        (:func:`mountcal.core.output_suffix.check_output_suffix`). Empty: the command decides (live's
        prefix, fleet's ``.parquet``).
    formats_by : str, optional
        The option whose value chooses the format (``export``'s ``--to``), named in the refusal.
    writes : callable, optional
        For an output: ``(value, args) -> [(path, note)]``, the files it writes (``note`` says
        which, for messages); default: the value itself.
    """

    role: Literal["input", "output"]
    what: str
    folders: bool = False
    small: bool = False
    globs: bool = False
    stdio: bool = False
    formats: Formats = ()
    writes: Callable[[Any, argparse.Namespace], list[tuple[str, str]]] | None = None
    formats_by: str | None = None

    def suffixes(self, args: argparse.Namespace) -> tuple[str, ...]:
        """The suffixes of what it writes, for these arguments."""
        return self.formats(args) if callable(self.formats) else self.formats


def add_path(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    *flags: str,
    role: Literal["input", "output"],
    what: str,
    folders: bool = False,
    small: bool = False,
    globs: bool = False,
    stdio: bool = False,
    formats: Formats = (),
    writes: Callable[[Any, argparse.Namespace], list[tuple[str, str]]] | None = None,
    formats_by: str | None = None,
    **argument: Any,
) -> argparse.Action:
    """``parser.add_argument(*flags, **argument)``, declared as a path the command reads or writes."""
    action = parser.add_argument(*flags, **argument)
    setattr(action, _ATTRIBUTE, PathOption(role, what, folders, small, globs, stdio, formats, writes, formats_by))
    return action


def declared(action: argparse.Action) -> PathOption | None:
    """The declaration of an option (None: not a path)."""
    found = getattr(action, _ATTRIBUTE, None)
    return found if isinstance(found, PathOption) else None


class CommandParser(argparse.ArgumentParser):
    """A command's parser: a missing ``-o`` that may be ``-`` says so (results go to stdout only when asked)."""

    def error(self, message: str) -> NoReturn:
        output = next((a for a in self._actions if "--output" in a.option_strings), None)
        spec = None if output is None else declared(output)
        if message.startswith("the following arguments are required") and "-o/--output" in message:
            if spec is not None and spec.stdio:
                message += " (-o FILE writes a file, -o - writes to stdout)"
        super().error(message)


def command_parser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The sub-parser of ``command``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            found: argparse.ArgumentParser = action.choices[command]
            return found
    raise KeyError(command)


def label(action: argparse.Action) -> str:
    """How messages name an option: its first flag (``-o``, ``--dbc``), or ``input`` for the positional."""
    return action.option_strings[0] if action.option_strings else "input"


def _values(args: argparse.Namespace, action: argparse.Action) -> list[str]:
    value = getattr(args, action.dest, None)
    if value is None:
        return []
    return [str(v) for v in value] if isinstance(value, list | tuple) else [str(value)]


def paths_of(
    parser: argparse.ArgumentParser, args: argparse.Namespace
) -> Iterator[tuple[argparse.Action, PathOption, str, str]]:
    """Every (option, declaration, name in messages, path) the parsed ``args`` name, outputs expanded
    to the files they write; ``-`` (stdin/stdout) left out."""
    for action in parser._actions:
        spec = declared(action)
        if spec is None:
            continue
        flag = label(action)
        if spec.role == "output" and spec.writes is not None:
            for path, note in spec.writes(getattr(args, action.dest, None), args):
                yield action, spec, f"{flag} {note}".strip(), path
            continue
        for value in _values(args, action):
            if not (spec.stdio and value == STDIO):
                yield action, spec, flag, value


def check_paths(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse, before the command runs, an input that is not a (small enough) regular file or folder,
    and an output onto an input, onto another output or onto anything but a regular file.

    Raises
    ------
    InputError
        Naming the option, the path, what was found and what to do.
    """
    from mountcal.core.output_suffix import check_output_suffix
    from mountcal.core.paths import check_outputs, input_file

    inputs: dict[str, list[str]] = {}
    written: list[tuple[str, str]] = []
    named: list[tuple[str, str, tuple[str, ...]]] = []  # outputs whose suffix says their format
    for _, spec, name, path in paths_of(parser, args):
        if spec.role == "output":
            written.append((name, path))
            if spec.formats:
                by = spec.formats_by
                chosen = "" if by is None else f" with {by} {getattr(args, by.lstrip('-').replace('-', '_'))}"
                named.append((f"{args.command} {name.split(' ')[0]}{chosen}", path, spec.suffixes(args)))
            continue
        if spec.globs and not Path(path).exists():
            continue  # a pattern, or nothing: the command expands it and says what it found
        what = spec.what if name == "input" else f"{spec.what} given to {name}"
        input_file(path, what, limit=None if spec.small else 2**63, folders=spec.folders)
        inputs.setdefault(name, []).append(path)
    names = [name for name, _ in written]
    outputs = {
        name if names.count(name) == 1 else f"{name} #{names[:i].count(name) + 1}": path
        for i, (name, path) in enumerate(written)
    }
    check_outputs(outputs, inputs)  # first: an output onto an input is refused for what it is
    for option, path, suffixes in named:
        if suffixes:
            check_output_suffix(option, path, suffixes)


__all__ = ["CommandParser", "PathOption", "add_path", "check_paths", "command_parser", "declared", "label", "paths_of"]
