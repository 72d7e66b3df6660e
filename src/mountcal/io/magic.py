"""What a file's first bytes say it is, against what its name says (a file named for another format).

Readers are chosen by a file's name (:func:`mountcal.io.registry.reader_for`); a file whose content
is another known format — an MF4 saved as ``.blf``, a Parquet file named ``.csv``, a gzip archive
named ``.mcap`` — would otherwise reach the wrong reader and be refused as corrupt, or misread.
Only formats with a fixed signature are recognised; a text format has none, so any of these
signatures in a text-named file is a mismatch. Only mountcal's own suffixes are judged: a reader
plugin's format may hold a Parquet table or a ZIP archive by design.
"""

from __future__ import annotations

import stat
from pathlib import Path

from mountcal.core.errors import InputError
from mountcal.core.signatures import LONGEST, SIGNATURES, signature_of

# compressed content: the tool that writes the file inside to stdout (mountcal reads logs uncompressed)
DECOMPRESS = {".gz": "gzip -dc", ".zip": "unzip -p", ".xz": "xz -dc", ".bz2": "bzip2 -dc", ".zst": "zstd -dc"}
# the suffixes whose content starts with a signature above (the others name text formats)
SIGNED_SUFFIXES = {".blf": ".blf", ".mf4": ".mf4", ".mdf": ".mf4", ".mcap": ".mcap", ".bag": ".bag"}
SIGNED_SUFFIXES |= {".parquet": ".parquet", ".pq": ".parquet", ".db3": ".db3"}
TEXT_SUFFIXES = (".csv", ".asc", ".log", ".trc")  # the built-in text formats: no signature at all


def content_format(path: Path) -> tuple[str, str, bytes] | None:
    """(what, suffix, the bytes) of the signature ``path`` starts with; None for none, or a path that is
    not a regular file (a FIFO is never read here: it would block)."""
    try:
        if not stat.S_ISREG(path.stat().st_mode):
            return None
        with path.open("rb") as f:
            head = f.read(LONGEST)
    except OSError:
        return None  # the reader reports what keeps it from the file
    return signature_of(head)


def check_named_for_content(path: Path) -> None:
    """Refuse a file whose content is a known format other than the one its suffix names. Only the
    suffixes of mountcal's own formats are judged: a plugin's format may well be a Parquet or a ZIP
    inside (its reader knows)."""
    named = path.suffix.lower()
    if named not in SIGNED_SUFFIXES and named not in TEXT_SUFFIXES:
        return
    found = content_format(path)
    if found is None:
        line = _text_table(path) if named in SIGNED_SUFFIXES else None
        if line is not None:  # a CSV saved under a binary format's name: its signature is missing, say what is there
            raise InputError(
                str(path),
                f"the format its name says ({named})",
                f"a text table (CSV), no {named} signature: its first line reads {line!r}",
                f"Rename it with the suffix of its content ({path.with_suffix('.csv').name}) — mountcal reads a "
                "file as its name says — or export it again in the format you meant.",
            )
        return
    what, suffix, signature = found
    if SIGNED_SUFFIXES.get(named) == suffix:
        return
    raise InputError(
        str(path),
        f"the format its name says ({named or 'no suffix'})",
        f"{what}: it starts with {signature!r}",
        _decompress(path, suffix, path.with_name(f"{path.stem}_plain{path.suffix}"))
        if suffix in DECOMPRESS
        else f"Rename it with the suffix of its content ({path.with_suffix(suffix).name}) — mountcal reads a file "
        "as its name says — or export it again in the format you meant.",
    )


TEXT_LOOK = 4096  # bytes read to tell a text table from a binary file without a signature


def _text_table(path: Path) -> str | None:
    """The first line of a file that reads as a delimited text table (UTF-8, no NUL, a header of four columns or
    more and a row of as many), else None: a binary file that merely lacks its signature, or text, is not one."""
    try:
        with path.open("rb") as f:
            head = f.read(TEXT_LOOK)
    except OSError:
        return None
    if not head or b"\x00" in head:
        return None
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError as err:
        if err.start < len(head) - 3:  # not merely a character cut at the end of the look
            return None
        text = head[: err.start].decode("utf-8")
    lines = text.splitlines()
    first = lines[0].strip() if lines else ""
    if len(lines) < 2 or not first.isprintable():
        return None
    # a table mountcal reads has four columns at least (t_s, ax, ay, az; beta_deg, ax, ay, az), and rows like it
    delimiter = max((",", ";", "\t"), key=first.count)
    if first.count(delimiter) < 3 or lines[1].count(delimiter) != first.count(delimiter):
        return None
    return first[:80]


# CANedge's own packed logs: an MF4 compressed, encrypted, or both, that CSS Electronics' tools unpack
CANEDGE_PACKED = {".mfc": "compressed", ".mfe": "encrypted", ".mfm": "compressed and encrypted"}


def decompress_hint(path: Path) -> str:
    """How to get at the log inside a file whose suffix names an archive, or a CANedge log compressed or
    encrypted ("" for other suffixes)."""
    suffix = path.suffix.lower()
    if suffix in CANEDGE_PACKED:
        return (
            f"It is a CANedge log, {CANEDGE_PACKED[suffix]} ({path.suffix}): turn it into an MF4 with CSS "
            "Electronics' MF4 converters (mdf2finalized; an encrypted log needs the device's password file) and "
            "give the .MF4."
        )
    return _decompress(path, suffix, path.with_suffix("")) if suffix in DECOMPRESS else ""


def _decompress(path: Path, suffix: str, inner: Path) -> str:
    return (
        f"It is compressed: decompress it ({DECOMPRESS[suffix]} {path.name} > {inner.name}) and give the file "
        "inside; mountcal reads logs uncompressed."
    )


__all__ = ["CANEDGE_PACKED", "DECOMPRESS", "SIGNATURES", "check_named_for_content", "content_format", "decompress_hint"]
