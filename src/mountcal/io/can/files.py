"""A CAN log file of any format read into :class:`~mountcal.io.can.frames.CanFrames`, whole or in chunks:
BLF and MF4 by their own parsers (:mod:`mountcal.io.can.blf`, :mod:`mountcal.io.can.mf4`), the text
formats (ASC, candump ``.log``, TRC, CSV) through python-can's readers, batched into arrays."""

from __future__ import annotations

import io
import locale
from collections.abc import Callable, Collection, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mountcal.core import budget, ranges
from mountcal.core.errors import InputError
from mountcal.io.can.frames import CLASSIC_WIDTH, DATA_WIDTH, CanFrames, Filter
from mountcal.io.inputs import check_regular_file, hold
from mountcal.io.reader import CHUNK_SAMPLES
from mountcal.io.whole import open_prefix, text_end

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

FORMATS = {".blf": "blf", ".asc": "asc", ".log": "log", ".trc": "trc", ".csv": "csv", ".mf4": "mf4", ".mdf": "mf4"}


# ---------------------------------------------------------------------------------------------
# Public readers


def log_format(path: str | Path) -> str:
    """The log format of ``path`` from its suffix: one of ``blf asc log trc csv mf4``.

    Raises
    ------
    InputError
        When the suffix is not a CAN log format.
    """
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise InputError(
            str(path),
            "a CAN log (" + ", ".join(sorted(FORMATS)) + ")",
            f"the suffix {Path(path).suffix!r}",
            "Rename the file to its format's suffix or convert it with python-can's `can.logconvert`.",
        )
    return fmt


def read_frames(path: str | Path, *, ids: Collection[int] | None = None, channel: int | None = None) -> CanFrames:
    """Read all data frames of a CAN log into one table.

    Parameters
    ----------
    path : str or Path
        A BLF, ASC, candump ``.log``, TRC, CSV or MF4 file.
    ids : collection of int, optional
        Keep only these arbitration ids (filtering happens before payloads are copied).
    channel : int, optional
        Keep only this channel (python-can numbering, see the module docstring).

    Returns
    -------
    CanFrames
        The frames in file order.
    """
    chunks = iter_frames(path, ids=ids, channel=channel, max_frames=1 << 20)
    return CanFrames.concat(hold(chunks, str(path), "CAN frames"))


def iter_frames(
    path: str | Path,
    *,
    max_frames: int = CHUNK_SAMPLES,
    ids: Collection[int] | None = None,
    channel: int | None = None,
) -> Iterator[CanFrames]:
    """Stream the data frames of a CAN log in chunks of at most ``max_frames`` frames.

    Memory stays bounded by the chunk size: BLF is read a batch of containers at a time, MF4 a
    record range at a time, the text formats a batch of lines at a time.

    Parameters
    ----------
    path : str or Path
        A BLF, ASC, candump ``.log``, TRC, CSV or MF4 file.
    max_frames : int
        Largest chunk, in frames (after filtering).
    ids, channel
        As for :func:`read_frames`.

    Yields
    ------
    CanFrames
        Consecutive, non-empty chunks in file order.
    """
    path = Path(path)
    fmt = log_format(path)
    check_regular_file(path, "CAN log")
    keep = Filter(ids, channel)
    # the binary formats' parsers import this module's CanFrames: imported here, when needed
    if fmt == "blf":
        from mountcal.io.can.blf import iter_blf

        chunks = iter_blf(path, keep)
    elif fmt == "mf4":
        from mountcal.io.can.mf4 import iter_mf4

        chunks = iter_mf4(path, keep, max_frames)
    else:
        chunks = _iter_text(path, fmt, keep, max_frames)
    yield from _rechunk(chunks, max_frames)


def _rechunk(chunks: Iterable[CanFrames], max_frames: int) -> Iterator[CanFrames]:
    """Regroup a stream of tables into tables of at most ``max_frames`` rows (none empty).

    Small tables (a filter keeps few frames of a batch) are joined until they hold a quarter of
    ``max_frames``; larger ones go out as they are, split as views: joining them would only copy.
    """
    if max_frames < 1:
        raise ValueError(f"max_frames must be >= 1; got {max_frames}")
    pending: list[CanFrames] = []
    count = 0
    for chunk in chunks:
        if not len(chunk):
            continue
        pending.append(chunk)
        count += len(chunk)
        if count < max(max_frames // 4, 1):
            continue
        joined = CanFrames.concat(pending)
        for start in range(0, len(joined), max_frames):
            yield joined.take(slice(start, start + max_frames))
        pending, count = [], 0
    if count:
        yield CanFrames.concat(pending)


# ---------------------------------------------------------------------------------------------
# Text formats, through python-can's readers


def _text_reader(path: Path, fmt: str, whole: int) -> Any:
    """python-can's reader of the format, on the file's first ``whole`` bytes (its whole lines)."""
    import can

    readers: dict[str, Callable[..., Any]] = {
        "asc": can.ASCReader,
        "log": can.CanutilsLogReader,
        "trc": can.TRCReader,
        "csv": can.CSVReader,
    }
    if whole == path.stat().st_size:
        return readers[fmt](str(path))
    # a cut file read in part: its last, incomplete line left out (python-can would parse what is there)
    return readers[fmt](io.TextIOWrapper(open_prefix(path, whole), encoding=locale.getpreferredencoding(False)))


def _iter_text(path: Path, fmt: str, keep: Filter, max_frames: int) -> Iterator[CanFrames]:
    from can.util import channel2int

    rows: list[tuple[float, int, int, bool, int, bytes]] = []
    done = 0  # data frames before this batch
    line_error = (ValueError, IndexError, KeyError, TypeError)
    whole = text_end(path, asc=fmt == "asc")  # a last line without its line break: a cut file
    try:
        reader = _text_reader(path, fmt, whole)
        with reader:
            for msg in reader:
                if msg.is_error_frame or msg.is_remote_frame:
                    continue
                ch = channel2int(msg.channel)
                rows.append(
                    (msg.timestamp, -1 if ch is None else ch, msg.arbitration_id, msg.is_extended_id,
                     len(msg.data), bytes(msg.data))
                )  # fmt: skip
                if len(rows) >= max_frames:
                    yield _rows_table(rows, keep, path, done)
                    done += len(rows)
                    rows = []
    except line_error as err:
        raise InputError(
            str(path),
            f"a {fmt.upper()} log python-can can parse",
            f"a malformed line ({type(err).__name__}: {err})",
            "Repair or re-export the log.",
        ) from err
    yield _rows_table(rows, keep, path, done)


def _rows_table(rows: list[tuple[float, int, int, bool, int, bytes]], keep: Filter, path: Path, done: int) -> CanFrames:
    """A batch of parsed lines as a table, its time stamps and ids checked against their ranges
    (a text log can say ``nan`` or ``-0x70``), and charged to the budget as records."""
    if not rows:
        return CanFrames.empty()
    budget.charge("records", len(rows), str(path), "lines of a text CAN log")
    t_s, channel, ident, ext, length, payload = zip(*rows, strict=True)
    what = "of the data frames (rows: data frames in file order)"
    ranges.check_values("time_s", t_s, str(path), f"time stamps {what}", first=done)
    ranges.check_values("can_id", ident, str(path), f"arbitration ids {what}", first=done)
    raw_id = np.asarray(ident, np.uint32)
    chan = np.asarray(channel, np.int64)
    mask = keep.mask(raw_id, chan)
    index = np.arange(len(rows)) if mask is None else np.flatnonzero(mask)
    width = max((len(payload[k]) for k in index), default=0)
    data = np.zeros((index.shape[0], CLASSIC_WIDTH if width <= CLASSIC_WIDTH else DATA_WIDTH), np.uint8)
    for row, k in enumerate(index):
        raw = payload[k][:DATA_WIDTH]
        data[row, : len(raw)] = np.frombuffer(raw, np.uint8)
    return CanFrames(
        np.asarray(t_s, np.float64)[index],
        chan[index],
        raw_id[index],
        np.asarray(ext, np.bool_)[index],
        np.minimum(np.asarray(length, np.int64)[index], DATA_WIDTH).astype(np.uint8),
        data,
    )


__all__ = ["FORMATS", "iter_frames", "log_format", "read_frames"]
