"""Text from files, made safe for a terminal.

Topic names, signal names, column names and paths come from files a user did not write: an escape
sequence in one could move the cursor, retitle the window or hide text, and a bidi override could
show a name reversed. :func:`safe` writes every such character as a visible escape.
"""

from __future__ import annotations

import re

# C0 and C1 controls, DEL, and the Unicode format characters that reorder or hide text
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200b-\u200f\u2028-\u202e\u2060-\u2069\ufeff]")


def safe(text: object, keep: str = "") -> str:
    """``str(text)`` with control and bidi characters shown as ``\\xNN`` / ``\\uNNNN`` (``keep``: spared)."""

    def escape(m: re.Match[str]) -> str:
        c = m.group()
        if c in keep:
            return c
        return f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}"

    return _UNSAFE.sub(escape, str(text))


__all__ = ["safe"]
