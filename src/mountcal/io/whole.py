"""Whether an input file is whole: every reader checks that it reached the end of a complete file.

A copy cut short (an interrupted transfer, a full disk, a logger switched off mid-write) must not
be read as if it were the whole recording. Each format knows where it should end from what its
reader reads anyway (sizes, headers, footers; no extra pass over the data):

- MF4: every block the file links to lies inside it; an unfinalised MF4 (CANedge writes no length
  for its last data block) ends on a whole record (:mod:`mountcal.io.can.mf4`);
- BLF: the file size its header records, and whole objects (:mod:`mountcal.io.can.blf`);
- MCAP: the footer and closing magic (:mod:`mountcal.io.mcap.records`);
- text logs (ASC, candump ``.log``, TRC, CAN CSV) and CSV tables: a line break after the last line,
  and ``End TriggerBlock`` after an ASC's ``Begin Triggerblock`` (:func:`text_end`);
- Parquet: its footer, which holds the schema and where each row group lies (:func:`parquet_end`).

A reader that finds its file cut calls :func:`found_cut`. By default that refuses the file
(:class:`TruncatedInput`: the byte where it ends and what the format expected there). Inside
:func:`reading` with ``allow_truncated`` (``--allow-truncated``, ``LogOptions.allow_truncated``)
the cut is recorded instead and the reader goes on with the whole part; the caller carries the
record (:attr:`Cut.sentence`) into the samples, the result's provenance and the summary, so a
result from part of a file always says so.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any, BinaryIO, TypeVar

from mountcal.core.errors import InputError
from mountcal.core.option_names import option

_T = TypeVar("_T")
_READ_IN_PART = ": read in part"


@dataclass(frozen=True)
class Cut:
    """Where an incomplete file ends, and what its format expected there."""

    path: str
    ends_at: int  # the file's size in bytes: the byte where it ends (-1: not known to be cut, see found_unverified)
    expected: str  # what the format says should be there ("the rest of its DT block (to byte 2000)")
    whole: int = -1  # bytes of it that hold whole records, where the reader knows (a text's whole lines)

    @property
    def sentence(self) -> str:
        """The cut in one sentence, as results and summaries record it."""
        if self.ends_at < 0:  # an end that cannot be verified (found_unverified)
            return f"{self.path}: {self.expected}"
        return f"{self.path} ends at byte {self.ends_at}, before {self.expected}{_READ_IN_PART}"


class TruncatedInput(InputError):
    """A file that ends before its format says it does (a cut copy, an unfinished recording)."""

    def __init__(self, cut: Cut, todo: str = "") -> None:
        super().__init__(
            cut.path,
            f"a complete file: {cut.expected}",
            f"a file that ends at byte {cut.ends_at}",
            todo or _todo(),
        )
        self.cut = cut


def _todo() -> str:
    allow = option("allow_truncated", True)
    return f"Copy the file again if it was transferred; {allow} reads the whole part of it (the result then says so)."


@dataclass
class _Policy:
    allow: bool
    cuts: list[Cut] = field(default_factory=list)


_policy: ContextVar[_Policy | None] = ContextVar("mountcal_whole_files", default=None)


@contextmanager
def reading(allow_truncated: bool = False, cuts: list[Cut] | None = None) -> Iterator[list[Cut]]:
    """Within this block readers refuse a cut file, or (``allow_truncated``) read its whole part;
    yields the list of the cuts found (one per file): ``cuts``, when given, to go on with."""
    policy = _Policy(allow_truncated, [] if cuts is None else cuts)
    token = _policy.set(policy)
    try:
        yield policy.cuts
    finally:
        _policy.reset(token)


def read_under(chunks: Iterator[_T], allow_truncated: bool, cuts: list[Cut]) -> Iterator[_T]:
    """``chunks`` (a reader's generator) consumed under the policy of :func:`reading`, each step
    inside it, one policy for all steps; the cuts found are added to ``cuts`` as they are found."""
    policy = _Policy(allow_truncated, cuts)
    try:
        while True:
            token = _policy.set(policy)
            try:
                item = next(chunks)
            except StopIteration:
                return
            finally:
                _policy.reset(token)
            yield item
    finally:
        close = getattr(chunks, "close", None)
        if close is not None:
            close()


def found_cut(path: str | os.PathLike[str], ends_at: int, expected: str, *, whole: int = -1, hint: str = "") -> Cut:
    """A reader found ``path`` ending at byte ``ends_at`` before ``expected``.

    Returns the cut when the current policy allows reading the whole part (the reader goes on);
    a second cut of the same file is the first one.

    Raises
    ------
    TruncatedInput
        By default, and outside :func:`reading`.
    """
    cut = Cut(str(path), int(ends_at), expected, whole)
    policy = _policy.get()
    if policy is None or not policy.allow:
        raise TruncatedInput(cut, f"{_todo()} {hint}".rstrip())
    for known in policy.cuts:
        if known.path == cut.path:
            return known
    policy.cuts.append(cut)
    return cut


def was_cut(path: str | os.PathLike[str]) -> bool:
    """Whether a cut of ``path`` was found (and allowed) in the current reading: what a reader
    finds incomplete at the end is then the cut, not damage."""
    policy = _policy.get()
    return policy is not None and any(c.path == str(path) and c.ends_at >= 0 for c in policy.cuts)


def found_unverified(path: str | os.PathLike[str], why: str) -> None:
    """A reader cannot tell whether ``path`` is whole (``why``): recorded with the cuts, never refused.

    An unfinalised MF4 states no length for its last data block: a copy cut exactly between two
    records reads like the whole file. The samples, results and listings carry this sentence so
    that the result says what could not be checked.
    """
    policy = _policy.get()
    if policy is not None and all(c.path != str(path) for c in policy.cuts):
        policy.cuts.append(Cut(str(path), -1, why))


def is_cut(sentence: str) -> bool:
    """Whether a sentence of ``Samples.incomplete`` / ``provenance.incomplete_inputs`` is a cut (the
    file was read in part), not an end that could not be verified."""
    return sentence.endswith(_READ_IN_PART)


def unreadable_part(cut: Cut, why: str) -> TruncatedInput:
    """The refusal of a cut file whose whole part cannot be read either (``why``: what is lost)."""
    return TruncatedInput(cut, f"Copy the file again if it was transferred: what is left cannot be read ({why}).")


# --------------------------------------------------------------------------- line-oriented text

_TAIL = 4096  # bytes read from each end of a text file: its last line break and an ASC's closing line


def text_end(path: str | os.PathLike[str], *, asc: bool = False) -> int:
    """The number of bytes of a text file that hold whole lines (its size when it is whole).

    A file whose last byte is not a line break ends inside a line: cut (:func:`found_cut`). An ASC
    log that opens a trigger block (``Begin Triggerblock``) must close it (``End TriggerBlock``,
    python-can's and Vector's writers do): one that does not was cut between lines.
    """
    size = os.stat(path).st_size
    if size == 0:
        return 0
    with open(path, "rb") as f:
        head = f.read(_TAIL)
        f.seek(max(0, size - _TAIL))
        tail = f.read(_TAIL)
        if tail.endswith((b"\n", b"\r")):
            if asc and b"begin triggerblock" in head.lower() and b"end triggerblock" not in tail.lower():
                found_cut(path, size, "the line 'End TriggerBlock' that closes the ASC log's trigger block")
            return size
        start = _last_line_start(f, size)
    found_cut(path, size, f"the line break that ends its last line (from byte {start})")
    return start


def text_bytes_end(raw: bytes, where: str) -> Cut | None:
    """:func:`text_end` of a text held in memory (a stop table read whole): None when it ends with
    a line break; else the cut (where allowed), whose last line starts at :attr:`Cut.whole`."""
    if not raw or raw.endswith((b"\n", b"\r")):
        return None
    start = raw.rfind(b"\n") + 1
    return found_cut(where, len(raw), f"the line break that ends its last line (from byte {start})", whole=start)


def _last_line_start(f: BinaryIO, size: int) -> int:
    """The byte after the last line break of a file (0 without one), read backwards a block at a time."""
    end = size
    while end > 0:
        start = max(0, end - (1 << 16))
        f.seek(start)
        at = f.read(end - start).rfind(b"\n")
        if at >= 0:
            return start + at + 1
        end = start
    return 0


def text_source(path: str | os.PathLike[str]) -> str | os.PathLike[str] | io.BufferedReader:
    """What a parser of a line-oriented text reads: the file when it is whole, its whole lines when it
    was cut and that is allowed (:func:`text_end` refuses it otherwise)."""
    whole = text_end(path)
    return path if whole == os.stat(path).st_size else open_prefix(path, whole)


def open_prefix(path: str | os.PathLike[str], limit: int) -> io.BufferedReader:
    """The first ``limit`` bytes of a file as a binary stream: the whole lines of a cut text file,
    for a parser that would otherwise read the incomplete last one."""
    return io.BufferedReader(_Prefix(open(path, "rb"), limit))  # the caller closes it


class _Prefix(io.RawIOBase):
    """The first ``limit`` bytes of a binary file (closing it closes the file)."""

    def __init__(self, raw: io.BufferedReader, limit: int) -> None:
        self.raw, self.left = raw, limit

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        view = memoryview(buffer)[: self.left]
        n = self.raw.readinto(view) or 0
        self.left -= n
        return n

    def close(self) -> None:
        self.raw.close()
        super().close()


# --------------------------------------------------------------------------- Parquet

_PARQUET_MAGIC = b"PAR1"


def parquet_end(path: str | os.PathLike[str] | None = None, raw: bytes | None = None, where: str = "") -> None:
    """Refuse a Parquet file without its footer (metadata, its length, ``PAR1``): cut short.

    The footer says where every row group lies, so the part before it cannot be read either.
    """
    if raw is None:
        assert path is not None
        size = os.stat(path).st_size
        with open(path, "rb") as f:
            f.seek(max(0, size - 8))
            tail = f.read(8)
    else:
        size, tail = len(raw), raw[-8:]
    name = where or str(path)
    if len(tail) == 8 and tail[4:] == _PARQUET_MAGIC and 8 + int.from_bytes(tail[:4], "little") <= size - 4:
        return
    if size >= 4 and _starts_parquet(path, raw):
        cut = Cut(name, size, "the Parquet footer (the file's metadata and the closing PAR1)")
        found_cut(name, size, cut.expected)
        raise unreadable_part(cut, "a Parquet file lists its row groups only in the footer")


def _starts_parquet(path: str | os.PathLike[str] | None, raw: bytes | None) -> bool:
    if raw is not None:
        return raw[:4] == _PARQUET_MAGIC
    assert path is not None
    with open(path, "rb") as f:
        return f.read(4) == _PARQUET_MAGIC


__all__ = [
    "Cut",
    "TruncatedInput",
    "found_cut",
    "found_unverified",
    "is_cut",
    "open_prefix",
    "parquet_end",
    "read_under",
    "reading",
    "text_bytes_end",
    "text_end",
    "text_source",
    "unreadable_part",
    "was_cut",
]
