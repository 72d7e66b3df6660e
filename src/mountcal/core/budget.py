"""One memory and time budget per process: what the readers inflate, walk and hold, counted against totals.

A hostile file's cost is not in one block but in the sum: two million empty BLF containers, a
small MCAP whose chunks each inflate to the block limit, a table of a million columns. So every
reader charges what it does to one set of totals, and the first charge past a limit is an
:class:`~mountcal.core.errors.InputError` naming the file, the limit and the environment variable that
raises it. The limits (:data:`LIMITS`, stated in docs/reliability.md with the memory bound they give):

- ``block``: the largest block inflated or loaded at once (an MCAP chunk, a BLF container, an MF4
  data block), checked on the declared size before anything is allocated.
- ``inflate_ratio``: decompressed bytes in total at most this many times the compressed bytes read,
  plus one block: a decompression bomb is a ratio, a big genuine log is not (real logs: 5–7×).
- ``rows``: samples, frames and table rows held in memory, in total.
- ``records``: records, containers and text lines stepped through one at a time, in total (time).
- ``columns``: table columns read, in total.
- ``streams``: distinct CAN ids (per channel) tallied, in total: a bus has hundreds, not millions.
- ``stops``: rows of stop tables and stops planned, in total (every stop costs a fit's Jacobian).
- ``input``: the size of one small input file (protocol sheet, mapping, DBC, stop table, manifest).
- ``document``: JSON and TOML documents parsed (results, specs, mappings, triads), in total.
- ``depth``: the nesting of one JSON or TOML document (checked by a linear scan before parsing).

The totals belong to a *scope*: one command of the CLI, one log of a fleet, or one outermost
call of a reader from Python (:func:`scope`, :func:`scoped`, :func:`scoped_iter`); scopes nest
into the outermost one and are per thread. Charges are made per block or per batch, never per
message, so counting costs nothing measurable on the hot paths.
"""

from __future__ import annotations

import functools
import math
import os
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, ParamSpec, TypeVar

from mountcal.core.errors import InputError

MIB = 1 << 20
_SCAN_BYTES = 1 << 20  # nesting_depth scans 1 MiB at a time: the arrays of a piece take 40 times its size
_P = ParamSpec("_P")
_T = TypeVar("_T")


@dataclass(frozen=True)
class Limit:
    """One limit of the budget: its key, the variable that sets it, its default and what it counts."""

    key: str
    variable: str
    default: int
    unit: str  # "MiB" (the value is given in MiB, used in bytes), "×" or "" (a count)
    counts: str
    per: str  # "process" (a total of the scope) or what it bounds alone ("block", "file", "document")
    most: int = 1 << 40  # the largest value the variable may be set to


LIMITS: tuple[Limit, ...] = (
    Limit("block", "MOUNTCAL_MAX_BLOCK_MB", 256, "MiB", "a block inflated or loaded at once", "block", 1 << 16),
    Limit(
        "inflate_ratio",
        "MOUNTCAL_MAX_INFLATE_RATIO",
        100,
        "×",
        "decompressed bytes per compressed byte read",
        "process",
        1 << 20,
    ),
    Limit("rows", "MOUNTCAL_MAX_ROWS", 100_000_000, "", "samples, frames and table rows held", "process"),
    Limit(
        "records", "MOUNTCAL_MAX_RECORDS", 200_000_000, "", "records, containers and lines stepped through", "process"
    ),
    Limit("columns", "MOUNTCAL_MAX_COLUMNS", 10_000, "", "table columns read", "process"),
    Limit("streams", "MOUNTCAL_MAX_STREAMS", 65_536, "", "distinct CAN ids (per channel) tallied", "process"),
    Limit("stops", "MOUNTCAL_MAX_STOPS", 100_000, "", "stops read from stop tables", "process"),
    Limit("input", "MOUNTCAL_MAX_INPUT_MB", 256, "MiB", "a small input file", "file", 1 << 20),
    Limit("document", "MOUNTCAL_MAX_DOCUMENT_MB", 32, "MiB", "JSON and TOML parsed", "process", 1 << 16),
    Limit("depth", "MOUNTCAL_MAX_DEPTH", 64, "", "nesting levels of a JSON or TOML document", "document", 10_000),
)
_BY_KEY = {limit.key: limit for limit in LIMITS}


def setting(key: str) -> int:
    """The value of a limit (bytes for the ``MiB`` ones), from its variable or its default.

    Raises
    ------
    InputError
        The variable is set to something other than a whole number from 1 to the limit's most.
    """
    limit = _BY_KEY[key]
    raw = os.environ.get(limit.variable, "").strip()
    if not raw:
        return limit.default * MIB if limit.unit == "MiB" else limit.default
    try:
        value = float(raw) if limit.unit == "MiB" else int(raw)
    except ValueError:
        value = 0
    scaled = int(value * MIB) if limit.unit == "MiB" and math.isfinite(value) else value
    if not (math.isfinite(value) and 0 < value <= limit.most and scaled >= 1):
        kind = "a number of MiB above 0" if limit.unit == "MiB" else "a whole number from 1"
        raise InputError(
            limit.variable,
            f"{kind} up to {limit.most}",
            repr(raw),
            f"Set {limit.variable} to such a number, or unset it for the default {limit.default}.",
        )
    return int(scaled)


def _shown(limit: Limit, value: int) -> str:
    return f"{value / MIB:g} MiB" if limit.unit == "MiB" else f"{value}"


def over(key: str, where: str, what: str, found: str, todo: str = "") -> InputError:
    """The refusal of a charge past limit ``key``: names the limit, its variable and how to raise it."""
    limit = _BY_KEY[key]
    value = setting(key)
    raised = f"{4 * value / MIB:g}" if limit.unit == "MiB" else str(4 * value)
    return InputError(
        where,
        f"{what} (the {limit.variable} limit{', counted over the whole run' if limit.per == 'process' else ''})",
        found,
        (todo + " " if todo else "")
        + f"If the input is genuine, raise the limit, e.g. {limit.variable}={raised}, with the memory and time "
        "it needs.",
    )


@dataclass
class Totals:
    """What a scope has charged so far."""

    compressed: int = 0
    inflated: int = 0
    counts: dict[str, int] = field(default_factory=dict)


_local = threading.local()


def _totals() -> Totals | None:
    return getattr(_local, "totals", None)


@contextmanager
def scope() -> Iterator[Totals]:
    """Count the charges of the block against one set of totals (joining an enclosing scope)."""
    outer = _totals()
    if outer is not None:
        yield outer
        return
    _local.totals = Totals()
    try:
        yield _local.totals
    finally:
        _local.totals = None


def scoped(func: Callable[_P, _T]) -> Callable[_P, _T]:
    """``func`` run inside a :func:`scope` (its own, or its caller's)."""

    @functools.wraps(func)
    def run(*args: _P.args, **kwargs: _P.kwargs) -> _T:
        with scope():
            return func(*args, **kwargs)

    return run


def scoped_iter(func: Callable[_P, Iterator[_T]]) -> Callable[_P, Iterator[_T]]:
    """A generator function run inside a :func:`scope` for as long as it is being consumed."""

    @functools.wraps(func)
    def run(*args: _P.args, **kwargs: _P.kwargs) -> Iterator[_T]:
        with scope():
            yield from func(*args, **kwargs)

    return run


def charge(key: str, amount: int, where: str, what: str, *, total: bool = True) -> None:
    """Add ``amount`` to the scope's total of ``key`` (``rows``, ``records``, ``columns``, ``stops``,
    ``document``) and refuse when the total passes the limit. ``what`` names what is counted
    ("CAN frames"). Outside any scope, or with ``total=False``, ``amount`` alone is checked."""
    totals = _totals() if total else None
    count = amount
    if totals is not None:
        count = totals.counts.get(key, 0) + amount
        totals.counts[key] = count
    limit = setting(key)
    if count > limit:
        unit = _BY_KEY[key]
        shown = f"{count / MIB:.1f} MiB" if unit.unit == "MiB" else f"{count}"
        raise over(key, where, f"at most {_shown(unit, limit)} {what}", f"{shown}{' so far' if totals else ''}")


def check_block(size: int, where: str, what: str, found: str | None = None) -> None:
    """Refuse a block (``what``: "an MCAP chunk at byte 8") declaring more than the block limit."""
    if size > setting("block"):
        raise over(
            "block",
            where,
            f"{what} of at most {setting('block') // MIB} MiB once inflated",
            found or f"one stating {size} bytes",
            "A block this large is damage or a decompression bomb.",
        )


def inflate(compressed: int, inflated: int, where: str, what: str) -> None:
    """Charge a block about to be inflated: ``compressed`` bytes read, ``inflated`` declared.

    The block alone must be within the block limit; all blocks together may inflate to at most
    ``inflate_ratio`` times the compressed bytes read, plus one block.
    """
    check_block(inflated, where, what)
    totals = _totals() or Totals()
    totals.compressed += compressed
    totals.inflated += inflated
    ratio = setting("inflate_ratio")
    if totals.inflated > ratio * totals.compressed + setting("block"):
        raise over(
            "inflate_ratio",
            where,
            f"compressed data inflating to at most {ratio} times its size (plus one block) in all",
            f"{totals.inflated} bytes declared by {what}, from {totals.compressed} compressed bytes",
            "A ratio this high is a decompression bomb or filler, not a recording.",
        )


def check_depth(depth: int, where: str, what: str) -> None:
    limit = setting("depth")
    if depth > limit:
        raise over("depth", where, f"{what} nested at most {limit} levels deep", f"{depth} levels")


def nesting_depth(raw: bytes, *, strings: bool = True) -> int:
    """The deepest nesting of ``[``/``{`` in ``raw``, in one linear pass of whole-array steps.

    With ``strings`` (JSON), brackets inside double-quoted strings do not count: a quote ends a
    string unless an odd run of backslashes precedes it. Without (TOML, whose strings come in four
    kinds), every bracket counts: an over-estimate, never an under-estimate. Up to the first byte a
    parser would reject, the count is exact; a parser stops there, so it never nests deeper.
    """
    import numpy as np

    deepest = level = 0
    in_string = False
    run = 0  # backslashes ending the previous piece
    for start in range(0, len(raw), _SCAN_BYTES):
        piece = np.frombuffer(raw, np.uint8, count=min(_SCAN_BYTES, len(raw) - start), offset=start)
        opens = (piece == ord("[")) | (piece == ord("{"))
        closes = (piece == ord("]")) | (piece == ord("}"))
        if strings:
            slash = piece == ord("\\")
            index = np.arange(piece.size)
            last_other = np.maximum.accumulate(np.where(slash, -1, index))  # last non-backslash ≤ i
            # backslashes right before i: those ending at i - 1
            before = np.empty(piece.size, np.int64)
            before[0] = run
            ends = index[:-1] - last_other[:-1]  # run length ending at i - 1 within the piece
            before[1:] = np.where(last_other[:-1] < 0, index[:-1] + 1 + run, ends)
            quote = (piece == ord('"')) & (before % 2 == 0)
            inside = (np.cumsum(quote) + in_string) % 2 == 1  # after this byte: inside a string
            outside = ~inside & ~quote  # brackets are never quotes; a bracket outside has even parity
            opens &= outside
            closes &= outside
            in_string = bool(inside[-1])
            run = int(piece.size - 1 - last_other[-1]) + (run if last_other[-1] < 0 else 0)
        depth = level + np.cumsum(opens.astype(np.int64) - closes)
        if depth.size:
            deepest, level = max(deepest, int(depth.max())), int(depth[-1])
    return deepest


def document(raw: bytes, where: str, what: str, *, toml: bool = False, charged: bool = False) -> Any:
    """Parse a JSON (or TOML) document within the budget: size charged (unless ``charged``), depth
    checked before the parser recurses, no ``NaN``/``Infinity`` (JSON) or ``nan``/``inf`` (TOML)
    literals.

    Raises
    ------
    InputError
        Naming ``where``, what it should be and the first problem found.
    """
    if not charged:
        charge("document", len(raw), where, f"bytes of JSON and TOML ({what})")
    _text_or_refuse(raw, where, what)  # a log's binary bytes are neither brackets to count nor text to decode
    check_depth(nesting_depth(raw, strings=not toml), where, what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputError(
            where,
            f"{what} in UTF-8",
            f"byte 0x{raw[err.start]:02x} at byte {err.start}, which is not UTF-8",
            "Save it as UTF-8 (a comment in another encoding is the usual cause).",
        ) from err
    try:
        if toml:
            import tomllib

            return tomllib.loads(text, parse_float=_finite_float)
        import json

        return json.loads(text, parse_constant=_no_constant)
    except RecursionError as err:  # a backstop: the depth check keeps parsers far from the limit
        raise InputError(where, what, "nesting too deep to parse", "Pass a file written by its tool.") from err
    except ValueError as err:  # JSONDecodeError and TOMLDecodeError are ValueErrors
        kind = "TOML" if toml else "JSON"
        _empty_or_cut(raw, text, err, where, what, kind)
        raise InputError(
            where, f"valid {kind} ({what})", f"invalid {kind} ({err})", "Fix or re-export the file."
        ) from err


_CALIBRATE_IT = " (a log goes to mountcal calibrate, whose -o writes the calibration JSON)."
_BINARY_LOOK = 4096  # bytes looked at for a NUL: text (JSON, TOML, in UTF-8) never holds one


def _text_or_refuse(raw: bytes, where: str, what: str) -> None:
    """Refuse a binary file given for a document — a log, a table, an archive (named by its signature), or
    any file with a NUL byte — naming what it is: its bytes would otherwise be counted as brackets (a
    "document nested 2678 levels deep") or be refused as text in another encoding."""
    from mountcal.core.signatures import signature_of

    found = signature_of(raw[:64])
    if found is not None:
        content, suffix, signature = found
        raise InputError(
            where,
            what,
            f"{content} (it starts with {signature!r}), not a text document",
            f"Give {what} here; a {suffix} file is an input of its own"
            + (_CALIBRATE_IT if "calibration" in what else "."),
        )
    nul = raw.find(b"\x00", 0, _BINARY_LOOK)
    if nul >= 0 and not raw.startswith((b"\xff\xfe", b"\xfe\xff")):  # UTF-16 text: said by the UTF-8 check
        raise InputError(
            where,
            what,
            f"binary data (a NUL byte at byte {nul}), not a text document",
            f"Give {what} here, a text file (JSON or TOML, as its tool writes it).",
        )


def _empty_or_cut(raw: bytes, text: str, err: ValueError, where: str, what: str, kind: str) -> None:
    """Refuse an empty document, or a JSON one whose parser ran out of text (an interrupted copy or write), as
    such: the parser's own message ("Expecting value: line 1 column 1") says neither."""
    if not text.strip():
        raise InputError(
            where, f"{what} ({kind})", f"an empty file ({len(raw)} bytes)", "Check the path, or write the file again."
        ) from err
    import json

    if isinstance(err, json.JSONDecodeError) and _ran_out(text, err):
        raise InputError(
            where,
            f"{what} ({kind}), whole: its document closed",
            f"a file that ends at byte {len(raw)} inside the document ({err.msg}): cut short",
            "Copy the file again if it was transferred, or write it again with the command that made it.",
        ) from err


def _ran_out(text: str, err: ValueError) -> bool:
    """Whether the JSON parser failed for want of more text: it stopped at the text's end, or at a string that
    runs to the end (no closing quote after it)."""
    import json

    assert isinstance(err, json.JSONDecodeError)
    if err.pos >= len(text.rstrip()):
        return True
    if err.msg.startswith("Unterminated string"):  # the string runs to the end of the text
        return '"' not in text[err.pos + 1 :].replace('\\"', "")
    return False


def _no_constant(name: str) -> float:
    raise ValueError(f"the non-standard literal {name}")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"the non-finite number {text}")
    return value


def markdown() -> str:
    """The table of docs/reliability.md: each limit, its variable, default and what it counts."""
    lines = ["| limit | variable | default | counts | over |", "|---|---|---|---|---|"]
    for limit in LIMITS:
        default = f"{limit.default} MiB" if limit.unit == "MiB" else f"{limit.default:,}".replace(",", " ")
        if limit.unit == "×":
            default = f"{limit.default}× (+ one block)"
        per = "the whole run" if limit.per == "process" else f"one {limit.per}"
        lines.append(f"| {limit.key} | `{limit.variable}` | {default} | {limit.counts} | {per} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # the table of docs/reliability.md
    print(markdown(), end="")

__all__ = [
    "LIMITS",
    "Limit",
    "charge",
    "check_block",
    "check_depth",
    "document",
    "inflate",
    "markdown",
    "nesting_depth",
    "over",
    "scope",
    "scoped",
    "scoped_iter",
    "setting",
]
