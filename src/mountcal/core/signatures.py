"""The fixed first bytes of the binary formats mountcal meets, and what each says a file is.

One table for every check of a file against what it should be: a log named for another format
(:mod:`mountcal.io.magic`), and a log given where a JSON or TOML document is expected
(:func:`mountcal.core.budget.document`).
"""

from __future__ import annotations

# signature → (what the content is, the suffix that names it)
SIGNATURES: tuple[tuple[bytes, str, str], ...] = (
    (b"LOGG", "a BLF log", ".blf"),
    (b"MDF     ", "an MF4 log", ".mf4"),
    (b"UnFinMF ", "an MF4 log (unfinalised)", ".mf4"),
    (b"\x89MCAP", "an MCAP log", ".mcap"),
    (b"#ROSBAG", "a ROS 1 bag", ".bag"),
    (b"PAR1", "a Parquet table", ".parquet"),
    (b"SQLite format 3\x00", "an SQLite database (a ROS 2 bag's .db3)", ".db3"),
    (b"\x1f\x8b", "a gzip archive", ".gz"),
    (b"PK\x03\x04", "a ZIP archive", ".zip"),
    (b"\xfd7zXZ\x00", "an XZ archive", ".xz"),
    (b"BZh", "a bzip2 archive", ".bz2"),
    (b"\x28\xb5\x2f\xfd", "a Zstandard archive", ".zst"),
)
LONGEST = max(len(s) for s, _, _ in SIGNATURES)


def signature_of(head: bytes) -> tuple[str, str, bytes] | None:
    """(what, suffix, the signature) of the signature ``head`` starts with; None for none."""
    for signature, what, suffix in SIGNATURES:
        if head.startswith(signature):
            return what, suffix, signature
    return None


__all__ = ["LONGEST", "SIGNATURES", "signature_of"]
