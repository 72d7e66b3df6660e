"""Field offsets of serialized ROS messages, for many messages at once, from their definitions.

A batch of messages is :class:`~mountcal.io.ros2.cdr.Rows` (one byte buffer, the start and size of
each message). :func:`locate` walks a message type's fields in declaration order, one field for all
messages at a time: a field's offset is one integer while every message so far has the same layout
(strings of one length, sequences of one count: the usual case, read as strided views), else one
offset per message. Fields before the wanted ones are skipped, not decoded.

Two serialisations:

- **CDR** (ROS 2; ``cdr=True``): the rows start after the 4-byte encapsulation header (see
  :func:`mountcal.io.ros2.cdr.cdr_rows`); a primitive of size k is aligned to a multiple of k counted
  from there (only when one is read: an empty sequence aligns nothing); a string is a uint32 length
  including its NUL, then the bytes.
- **ROS 1** (``cdr=False``): little-endian, no alignment, no encapsulation; a string is a uint32
  length (no NUL), then the bytes; ``time`` and ``duration`` are two 4-byte integers.

In both, a sequence is a uint32 count followed by its elements, and a fixed array is its elements.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mountcal.io.ros.types import ARRAY, BASE, NAME, Types
from mountcal.io.ros2.cdr import CdrError, Offset, Rows, align, as_offset
from mountcal.io.ros2.cdr import string_counts as cdr_string_counts

Path = tuple[str, ...]

PRIMITIVES = {
    "bool": "u1",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "<i2",
    "uint16": "<u2",
    "int32": "<i4",
    "uint32": "<u4",
    "int64": "<i8",
    "uint64": "<u8",
    "float32": "<f4",
    "float64": "<f8",
}


def _size(primitive: str) -> int:
    if primitive not in PRIMITIVES:
        raise CdrError(f"a field of type {primitive}, which mountcal does not read")
    return np.dtype(PRIMITIVES[primitive]).itemsize


def _number(desc: Any) -> str | None:
    """The primitive of a numeric field, or of the first element of a fixed array of numbers; else None."""
    kind, detail = desc
    if kind == ARRAY and detail[1] > 0:
        kind, detail = detail[0]
    return detail[0] if kind == BASE and detail[0] in PRIMITIVES else None


class _Walk:
    """One pass over a batch of messages of one type, collecting the offsets of the wanted fields."""

    def __init__(self, rows: Rows, types: Types, cdr: bool, wanted: Iterable[Path]) -> None:
        self.rows, self.types, self.cdr = rows, types, cdr
        self.wanted = set(wanted)
        self.prefixes = {p[:i] for p in self.wanted for i in range(1, len(p))}
        self.found: dict[Path, tuple[Offset, str]] = {}

    def align(self, at: Offset, size: int) -> Offset:
        return align(at, size) if self.cdr and size > 1 else at

    def struct(self, type_name: str, at: Offset, prefix: Path) -> Offset | None:
        """Walk the fields of ``type_name`` from ``at``; the offset after it, or None once all are found."""
        if type_name not in self.types:
            raise CdrError(f"a message using {type_name}, which its definition does not define")
        for name, desc in self.types[type_name][1]:
            path = (*prefix, name)
            if path in self.wanted:
                if desc == (BASE, ("string", 0)):
                    at = self.align(at, 4)
                    self.found[path] = (at, "string")
                else:
                    primitive = _number(desc)
                    if primitive is None:
                        raise CdrError(f"field {'.'.join(path)} is neither a number nor a string")
                    at = self.align(at, _size(primitive))
                    self.found[path] = (at, primitive)
                if len(self.found) == len(self.wanted):
                    return None
            if path in self.prefixes and desc[0] == NAME:
                after = self.struct(desc[1], at, path)
                if after is None:
                    return None
                at = after
            else:
                at = self.skip(desc, at, path)
        return at

    def skip(self, desc: Any, at: Offset, path: Path) -> Offset:
        """The offset just after a field described by ``desc`` that starts at (or after) ``at``."""
        kind, detail = desc
        what = ".".join(path)
        if kind == BASE:
            if detail[0] == "string":
                return self.string(at, what)
            size = _size(detail[0])
            return self.align(at, size) + size
        if kind == NAME:
            end = self.struct(detail, at, path)
            assert end is not None  # nothing wanted inside a skipped struct
            return end
        sub, length = detail
        if kind == ARRAY:
            return self.repeat(sub, at, length, path)
        at = self.align(at, 4)
        count = self.rows.take(at, "<u4", 1, f"the length of {what}")[:, 0].astype(np.int64)
        at = at + 4
        if sub[0] == BASE and sub[1][0] != "string":
            size = _size(sub[1][0])
            if not self.cdr or size == 1:
                return as_offset(at + count * size)
            return as_offset(np.where(count > 0, align(at, size), at) + count * size)
        counts = np.unique(count)
        if counts.size > 1:
            raise CdrError(
                f"sequence {what} holds {int(counts[0])} to {int(counts[-1])} elements in different messages; "
                "mountcal reads fields after a sequence of messages or strings only when its length is the same "
                "in every message"
            )
        return self.repeat(sub, at, int(counts[0]) if counts.size else 0, path)

    def repeat(self, sub: Any, at: Offset, count: int, path: Path) -> Offset:
        if sub[0] == BASE and sub[1][0] != "string":
            size = _size(sub[1][0])
            return self.align(at, size) + count * size if count else at
        for _ in range(count):
            at = self.skip(sub, at, path)
        return at

    def string(self, at: Offset, what: str) -> Offset:
        at = self.align(at, 4)
        length = self.rows.take(at, "<u4", 1, f"string {what}")[:, 0].astype(np.int64)
        return as_offset(at + 4 + length)


def locate(
    rows: Rows, types: Types, type_name: str, wanted: Iterable[Path], *, cdr: bool
) -> dict[Path, tuple[Offset, str]]:
    """Offset and primitive type of each wanted numeric or string field (a path through nested messages; a
    fixed array of numbers stands for its first element; a string's offset is that of its length).

    Raises
    ------
    CdrError
        A wanted field is missing from the definition or is not a number, or a message is too short
        for a length prefix it needs.
    """
    walk = _Walk(rows, types, cdr, wanted)
    walk.struct(type_name, 0, ())
    missing = walk.wanted - set(walk.found)
    if missing:
        raise CdrError(f"no numeric field {', '.join(sorted('.'.join(p) for p in missing))} in {type_name}")
    return walk.found


def read(rows: Rows, found: dict[Path, tuple[Offset, str]], path: Path) -> NDArray[Any]:
    """The values of one located field, shape (n,), checked to lie inside every message."""
    at, primitive = found[path]
    return rows.take(at, PRIMITIVES[primitive], 1, ".".join(path))[:, 0]


def read_columns(rows: Rows, found: dict[Path, tuple[Offset, str]], paths: list[Path]) -> NDArray[Any]:
    """Several located fields as columns, shape (n, len(paths)); fields of one type that lie back to
    back (a Vector3's x, y, z) are read in one pass."""
    at0, primitive = found[paths[0]]
    size = _size(primitive)
    back_to_back = all(
        found[p][1] == primitive and np.all(np.asarray(found[p][0]) - np.asarray(at0) == i * size)
        for i, p in enumerate(paths)
    )
    if back_to_back:
        return rows.take(at0, PRIMITIVES[primitive], len(paths), ".".join(paths[0][:-1]))
    return np.column_stack([read(rows, found, p) for p in paths])


def string_counts(rows: Rows, found: dict[Path, tuple[Offset, str]], path: Path) -> dict[str, int]:
    """The values of one located string field, each with how many messages hold it (vectorised:
    :func:`mountcal.io.ros2.cdr.string_counts`)."""
    at, kind = found[path]
    if kind != "string":
        raise CdrError(f"field {'.'.join(path)} is not a string")
    length = rows.take(at, "<u4", 1, ".".join(path))[:, 0].astype(np.int64)
    first = at + 4 if isinstance(at, int) else as_offset(at + 4)
    return cdr_string_counts(rows, first, as_offset(at + 4 + length))


def read_strings(rows: Rows, found: dict[Path, tuple[Offset, str]], path: Path) -> list[bytes]:
    """The values of one located string field, one ``bytes`` per message (its NUL, in CDR, removed).

    Text is taken message by message: for the low-rate topics that carry it (NMEA sentences).
    """
    at, kind = found[path]
    if kind != "string":
        raise CdrError(f"field {'.'.join(path)} is not a string")
    length = rows.take(at, "<u4", 1, ".".join(path))[:, 0].astype(np.int64)
    start = rows.start + at + 4
    rows.need(np.asarray(at) + 4 + length, ".".join(path))
    buf = rows.buf
    return [bytes(buf[s : s + n]).rstrip(b"\0") for s, n in zip(start.tolist(), length.tolist(), strict=True)]


__all__ = ["PRIMITIVES", "locate", "read", "read_columns", "read_strings", "string_counts"]
