"""What a reader accepts as input: a regular file, and bounded amounts of what it inflates or holds.

Every reader calls :func:`check_regular_file` before opening its input: a FIFO would block the
read forever, ``/dev/zero`` or ``/dev/urandom`` never end, and a directory is not a log. Each one is
refused with an :class:`~mountcal.core.errors.InputError` instead.

Readers also bound their memory and time by what they will actually inflate, walk and hold,
whatever a file declares: each charges :mod:`mountcal.core.budget` per block or batch (the largest
block, the decompression ratio, rows, records, columns), and a limit hit is an
:class:`~mountcal.core.errors.InputError` naming the file, the limit and the variable that raises it.
See ``docs/reliability.md`` for the memory bound these give.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Sized
from pathlib import Path
from typing import TypeVar

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.core.paths import input_file

_Sized = TypeVar("_Sized", bound=Sized)


def check_regular_file(path: str | os.PathLike[str], role: str) -> Path:
    """``path`` as a Path once it is known to be an existing regular file (symlinks followed).

    ``role`` says what the file is for (``"MCAP log"``, ``"DBC"``): the message's expectation. The
    check is :func:`mountcal.core.paths.input_file`'s without its size limit (logs are large; their
    readers bound what they hold instead).

    Raises
    ------
    InputError
        The path does not exist, or is a directory, FIFO, socket or device.
    """
    return input_file(path, f"a {role}", limit=sys.maxsize)


def max_block_bytes() -> int:
    """The largest block (MCAP chunk, BLF container, ...) a reader inflates, in bytes."""
    return budget.setting("block")


def max_rows() -> int:
    """The most samples, frames or rows a reader materialises (a total of the run: :mod:`mountcal.core.budget`)."""
    return budget.setting("rows")


def block_too_large(where: str, what: str, found: str) -> InputError:
    """The error for a block declaring or inflating to more than :func:`max_block_bytes`.

    ``what`` names the block (``"an MCAP chunk at byte 8"``), ``found`` what it holds.
    """
    return budget.over(
        "block",
        where,
        f"{what} of at most {max_block_bytes() >> 20} MiB once inflated",
        found,
        "A block this large is damage or a decompression bomb.",
    )


def too_many_rows(where: str, what: str, count: int) -> InputError:
    """The error for an input holding more than :func:`max_rows` samples, frames or rows."""
    return budget.over("rows", where, f"at most {max_rows()} {what}", f"{count} or more", "Split the input.")


def hold(parts: Iterable[_Sized], where: str, what: str) -> list[_Sized]:
    """``list(parts)``, charging their rows to the run's budget as they arrive."""
    out = []
    for part in parts:
        budget.charge("rows", len(part), where, what)
        out.append(part)
    return out


def csv_columns(head: bytes | Path, where: str, *, charge: bool = True) -> None:
    """Charge the columns of a CSV table (its first line; ``head``: the bytes, or the file) to the
    budget, reading no more of the line than the limit allows: a header of a million columns is
    refused before a parser allocates one object per column. ``charge=False`` checks them alone
    (a look at a header that the table's reader charges again)."""
    limit = budget.setting("columns")
    if isinstance(head, Path):
        with head.open("rb") as f:
            line = b""
            while b"\n" not in line and line.count(b",") <= limit:
                piece = f.read(1 << 16)
                if not piece:
                    break
                line += piece
    else:
        line = head[: head.find(b"\n")] if b"\n" in head[: 1 << 24] else head[: 1 << 24]
    line = line.split(b"\n", 1)[0]
    budget.charge("columns", line.count(b",") + 1, where, "table columns", total=charge)


MAX_COMMENT_LINES = 1000  # '#' lines looked past above a CSV's header


def comment_lines(path: Path) -> int:
    """How many lines starting with ``#`` (a logger's preamble) stand above a CSV's header, at most
    :data:`MAX_COMMENT_LINES`: what every reader of a table skips (:func:`mountcal.io.table.mapped.dialect`)."""
    count = 0
    with path.open("rb") as f:
        while count < MAX_COMMENT_LINES and f.readline().lstrip(b"\xef\xbb\xbf \t").startswith(b"#"):
            count += 1
    return count


def check_parquet_rows(path: Path) -> int | None:
    """The rows a Parquet file declares (None: an unreadable footer), refusing more than
    :func:`max_rows` from its footer alone (a few kilobytes of run-length-encoded zeros can declare
    billions of rows); its columns are charged to the budget."""
    import pyarrow.parquet as pq

    try:
        meta = pq.ParquetFile(path).metadata
    except Exception:  # an unreadable footer: the reader's own parse reports it
        return None
    budget.charge("columns", meta.num_columns, str(path), "table columns")
    if meta.num_rows > max_rows():
        raise too_many_rows(str(path), "table rows", meta.num_rows)
    return int(meta.num_rows)
