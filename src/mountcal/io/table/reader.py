"""Sample tables in the registry (:mod:`mountcal.io.registry`): CSV and Parquet with mountcal's own columns
(``t_s, ax, ay, az``), a column map, or a known export (:mod:`mountcal.io.table.layout`)."""

from __future__ import annotations

from collections.abc import Collection, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.io.reader import LogReader

if TYPE_CHECKING:
    from mountcal.io.frame import Rotated
    from mountcal.io.reader import LogOptions
    from mountcal.io.samples import LogSummary, Samples
    from mountcal.io.table.layout import Layout


class TableReader(LogReader):
    name = "table"
    suffixes = (".csv", ".parquet", ".pq")
    description = "CSV or Parquet sample table (t_s, ax, ay, az; a column map; phone and imucal exports)"

    def read(self, path: Path, options: LogOptions) -> Samples:
        from mountcal.io.table.mapped import check_magnitude, read_mapped

        layout, read_as = table_layout(path, options)
        if layout.native:
            from mountcal.io.table.read import read_table

            samples = read_table(path)
        else:
            samples = read_mapped(path, layout, read_as)
        rotated = table_rotated(path, read_as, _data(layout))
        return _said(_framed(check_magnitude(samples, layout, str(path)), rotated), layout)

    def iter_chunks(self, path: Path, options: LogOptions, max_samples: int) -> Iterator[Samples]:
        from mountcal.io.table.mapped import iter_mapped

        layout, read_as = table_layout(path, options)
        if layout.native:
            from mountcal.io.table.read import iter_table

            chunks = iter_table(path, max_samples)
        else:
            chunks = iter_mapped(path, layout, read_as, max_samples)
        return _checked(chunks, layout, read_as, path)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        from mountcal.io.samples import summary

        return summary(self.read(path, options), path.suffix.lstrip(".").lower(), "table")


def _checked(chunks: Iterator[Samples], layout: Layout, read_as: dict[str, str], path: Path) -> Iterator[Samples]:
    """The chunks, the first (the first with samples) checked as :func:`check_magnitude` checks a whole table;
    its verdict (gravity-free) carried to the rest; each with the frame the whole file states."""
    from dataclasses import replace

    from mountcal.io.table.mapped import check_magnitude

    verdict: str | None = None
    rotated, looked = None, False  # the frame, looked up once the reader has checked the file (its first chunk)
    for chunk in chunks:
        if verdict is None and len(chunk):
            chunk = check_magnitude(chunk, layout, str(path))
            verdict = chunk.gravity_free
        elif verdict:
            chunk = replace(chunk, gravity_free=verdict)
        if not looked:
            rotated, looked = table_rotated(path, read_as, _data(layout)), True
        yield _said(_framed(chunk, rotated), layout)


def table_rotated(path: Path, read_as: dict[str, str], data: Collection[str] = ()) -> Rotated | None:
    """What a table states of its samples' frame (:mod:`mountcal.io.frame`): a Parquet file's metadata (naming
    the calibration applied), else its column ``frame`` over the whole file — a CSV's only way to say it —
    unless ``data``, the columns its layout reads, hold it (a column map naming ``frame``: data, not a mark).

    Raises
    ------
    InputError
        A column ``frame`` without one value in every row, or with a word other than ``sensor``,
        ``vehicle``, ``levelled`` (:func:`mountcal.io.frame.column_text`).
    """
    from mountcal.io.frame import FRAME_COLUMN, parquet_rotated, table_column_rotated
    from mountcal.io.table.mapped import PARQUET, header

    stated = parquet_rotated(path) if path.suffix.lower() in PARQUET else None
    if stated is not None or FRAME_COLUMN in data:
        return stated
    return table_column_rotated(path, header(path)[0], read_as.get("sep", ","))


def _data(layout: Layout) -> list[str]:
    """The columns the layout reads as data."""
    return [c.name for c in layout.columns.values()]


def _framed(samples: Samples, rotated: Rotated | None) -> Samples:
    from dataclasses import replace

    return samples if rotated is None else replace(samples, rotated=rotated)


def _said(samples: Samples, layout: Layout) -> Samples:
    """The samples carrying the conventions their layout settled (the time unit)."""
    from dataclasses import replace

    return replace(samples, conventions=(*samples.conventions, *layout.conventions)) if layout.conventions else samples


def table_layout(path: Path, options: LogOptions) -> tuple[Layout, dict[str, str]]:
    """The layout of a sample table (see :mod:`mountcal.io.table.layout`) and how to read its CSV.

    Raises
    ------
    InputError
        A table whose columns are neither mountcal's, mapped, nor a known export; a map given twice.
    """
    from dataclasses import replace

    from mountcal.core.errors import InputError
    from mountcal.core.option_names import option
    from mountcal.io.table.layout import mapping_columns, refuse_unknown, resolve
    from mountcal.io.table.mapped import header
    from mountcal.io.table.time_unit import settle_time

    names, read_as = header(path)
    columns = options.columns
    if options.mapping is not None:
        if columns is not None:
            raise InputError(
                str(path),
                "one column map",
                f"{option('columns')} and {option('mapping')} {options.mapping}",
                "Give the map once.",
            )
        columns = mapping_columns(options.mapping)
    layout = resolve(names, path, columns=columns, acc_unit=options.unit)
    if layout is None:
        raise refuse_unknown(names, path)
    layout, time_unit = settle_time(layout, path, read_as)  # stated and checked, or inferred; said
    layout = replace(layout, conventions=(*layout.conventions, time_unit))
    return (replace(layout, read_as=read_as) if read_as else layout), read_as


__all__ = ["TableReader", "table_layout", "table_rotated"]
