"""What a reader accepts as input: a regular file, and bounded amounts of what it inflates or holds.

Every reader calls :func:`check_regular_file` before opening its input: a FIFO would block the
read forever, ``/dev/zero`` or ``/dev/urandom`` never end, and a directory is not a log. Each one is
refused with an :class:`~mountcal.errors.InputError` instead.

Readers also bound their memory by what they will actually hold, whatever a file declares:

- ``MOUNTCAL_MAX_BLOCK_MB`` (default 256): the largest block a reader inflates or loads at once
  (an MCAP chunk, a BLF log container, a Parquet row group), checked on the declared size and
  again while inflating (the inflate stops at the declared size), so a decompression bomb is
  refused after at most this much memory.
- ``MOUNTCAL_MAX_ROWS`` (default 100 million): the most samples, frames or table rows a reader
  materialises from one input, counted before they are held.

A limit hit is an :class:`~mountcal.errors.InputError` naming the file, the limit and the variable
that raises it. See ``docs/reliability.md`` for the memory bound these give.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Sized
from pathlib import Path
from typing import TypeVar

from mountcal.errors import InputError
from mountcal.paths import input_file

MAX_BLOCK_ENV = "MOUNTCAL_MAX_BLOCK_MB"
MAX_ROWS_ENV = "MOUNTCAL_MAX_ROWS"
_DEFAULT_BLOCK_MB = 256
_DEFAULT_ROWS = 100_000_000
_Sized = TypeVar("_Sized", bound=Sized)


def check_regular_file(path: str | os.PathLike[str], role: str) -> Path:
    """``path`` as a Path once it is known to be an existing regular file (symlinks followed).

    ``role`` says what the file is for (``"MCAP log"``, ``"DBC"``): the message's expectation. The
    check is :func:`mountcal.paths.input_file`'s without its size limit (logs are large; their
    readers bound what they hold instead).

    Raises
    ------
    InputError
        The path does not exist, or is a directory, FIFO, socket or device.
    """
    return input_file(path, f"a {role}", limit=sys.maxsize)


def _env_int(name: str, default: int) -> int:
    raw = os.environ.get(name, "").strip()
    if not raw:
        return default
    try:
        value = int(raw)
    except ValueError:
        value = 0
    if value < 1:
        raise InputError(name, "a positive whole number", repr(raw), f"Set {name} to a number ≥ 1 or unset it.")
    return value


def max_block_bytes() -> int:
    """The largest block (MCAP chunk, BLF container, ...) a reader inflates, in bytes."""
    return _env_int(MAX_BLOCK_ENV, _DEFAULT_BLOCK_MB) << 20


def max_rows() -> int:
    """The most samples, frames or rows a reader materialises from one input."""
    return _env_int(MAX_ROWS_ENV, _DEFAULT_ROWS)


def block_too_large(where: str, what: str, found: str) -> InputError:
    """The error for a block declaring or inflating to more than :func:`max_block_bytes`.

    ``what`` names the block (``"an MCAP chunk at byte 8"``), ``found`` what it holds.
    """
    limit_mb = max_block_bytes() >> 20
    return InputError(
        where,
        f"{what} of at most {limit_mb} MiB once inflated (the {MAX_BLOCK_ENV} limit)",
        found,
        f"A block this large is damage or a decompression bomb; if the file is genuine, raise the "
        f"limit, e.g. {MAX_BLOCK_ENV}={4 * limit_mb}.",
    )


def too_many_rows(where: str, what: str, count: int) -> InputError:
    """The error for an input holding more than :func:`max_rows` samples, frames or rows."""
    limit = max_rows()
    return InputError(
        where,
        f"at most {limit} {what} (the {MAX_ROWS_ENV} limit)",
        f"{count} or more",
        f"Split the input, or raise the limit, e.g. {MAX_ROWS_ENV}={2 * limit}, with the memory to hold them.",
    )


def hold(parts: Iterable[_Sized], where: str, what: str) -> list[_Sized]:
    """``list(parts)``, counting their rows as they arrive and refusing past :func:`max_rows`."""
    out, count, limit = [], 0, max_rows()
    for part in parts:
        count += len(part)
        if count > limit:
            raise too_many_rows(where, what, count)
        out.append(part)
    return out


def check_parquet_rows(path: Path) -> None:
    """Refuse a Parquet file declaring more than :func:`max_rows` rows, from its footer alone
    (a few kilobytes of run-length-encoded zeros can declare billions of rows)."""
    import pyarrow.parquet as pq

    try:
        rows = pq.ParquetFile(path).metadata.num_rows
    except Exception:  # an unreadable footer: the reader's own parse reports it
        return
    if rows > max_rows():
        raise too_many_rows(str(path), "table rows", rows)
