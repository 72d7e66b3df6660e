"""The columns that carry a stop table's input conventions, written and read back by one rule each.

A stop table outlives the log it came from: a convention that qualified the log's readings (the frame mountcal had
rotated them into, a phone app's assumed acceleration sign, an odometry frame not known to face east, several IMU
frames on one topic) must come back with the table, or the table would calibrate as if it were not there. Each
column here has its writer (the conventions → the column's text, or None) and its reader (the column's values →
the conventions it states); :class:`mountcal.stops.table.StopTable` calls both through this list.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import pandas as pd

from mountcal.core.result import Convention
from mountcal.io.frame import FRAME_COLUMN, FRAME_CONVENTION, column_frame
from mountcal.io.heading_frame import HEADING_FRAME, odometry_frame_column, odometry_frame_from_column
from mountcal.io.sensor_frame import SENSOR_FRAME, column_several, several_column
from mountcal.io.sensor_logger import SIGN, column_sign, sign_column

Writer = Callable[[Sequence[Convention]], "str | None"]
Reader = Callable[[list[object], str], list[Convention]]


def _frame_text(conventions: Sequence[Convention]) -> str | None:
    """Rotated samples' stops: a triad or a second rotation is refused on reading them."""
    return next((c.value for c in conventions if c.name == FRAME_CONVENTION), None)


COLUMNS: tuple[tuple[str, Writer, Reader], ...] = (
    (FRAME_COLUMN, _frame_text, lambda values, where: column_frame(values, where, FRAME_COLUMN)),
    (SIGN, sign_column, lambda values, where: [column_sign(values, where)]),
    (HEADING_FRAME, odometry_frame_column, lambda values, where: [odometry_frame_from_column(values, where)]),
    (SENSOR_FRAME, several_column, lambda values, where: [column_several(values, where)]),
)
NAMES = tuple(name for name, _, _ in COLUMNS)


def convention_columns(conventions: Sequence[Convention]) -> dict[str, str]:
    """The columns a table written with ``conventions`` carries (one value, repeated in every row)."""
    return {name: text for name, write, _ in COLUMNS if (text := write(conventions)) is not None}


def conventions_from_columns(df: pd.DataFrame, where: str) -> list[Convention]:
    """The conventions a table's columns state."""
    return [c for name, _, read in COLUMNS if name in df.columns for c in read(df[name].tolist(), where)]


__all__ = ["NAMES", "convention_columns", "conventions_from_columns"]
