"""CAN logs in the registry (:mod:`mountcal.io.registry`): every python-can / asammdf format, with a DBC."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.reader import LogReader

if TYPE_CHECKING:
    from mountcal.io.reader import LogOptions
    from mountcal.io.samples import LogSummary, Samples

CAN_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".mf4", ".mdf")  # always CAN; a .csv is CAN with a DBC


class CanReader(LogReader):
    name = "can"
    suffixes = (*CAN_SUFFIXES, ".csv")
    description = "CAN (BLF, ASC, candump log, TRC, MF4; CSV with --dbc) decoded with a DBC"

    def claims(self, path: Path, options: LogOptions) -> bool:
        suffix = path.suffix.lower()
        return suffix in CAN_SUFFIXES or (suffix == ".csv" and options.dbc is not None)

    def read(self, path: Path, options: LogOptions) -> Samples:
        from mountcal.io.can.read import read_can

        return read_can(path, _dbc(path, options), mapping=options.mapping, channel=options.channel)

    def iter_chunks(self, path: Path, options: LogOptions, max_samples: int) -> Iterator[Samples]:
        from mountcal.io.can.read import iter_can

        dbc = _dbc(path, options)
        return iter_can(path, dbc, mapping=options.mapping, channel=options.channel, max_samples=max_samples)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        from mountcal.io.can.read import inspect_can

        return inspect_can(path, options.dbc)  # without a DBC: ids per channel


def _dbc(path: Path, options: LogOptions) -> str | tuple[str, ...]:
    if options.dbc is None:
        raise InputError(
            str(path),
            "a DBC to decode this CAN log",
            f"no {option('dbc')}",
            f"Pass the DBC file as {option('dbc')} (and the signal mapping as {option('mapping')} when the signals "
            "are not named plainly).",
        )
    return options.dbc


__all__ = ["CAN_SUFFIXES", "CanReader"]
