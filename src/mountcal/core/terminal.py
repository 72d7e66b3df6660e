"""Text from files, made safe for a terminal and for a UTF-8 document.

Topic names, signal names, column names and paths come from files a user did not write: an escape
sequence in one could move the cursor, retitle the window or hide text, and a bidi override could
show a name reversed. :func:`safe` writes every such character as a visible escape. A file name
that is not valid UTF-8 arrives with its undecodable bytes as lone surrogates, which no UTF-8
output can hold: :func:`decodable` (and :func:`safe`) write each as the byte ``\\xNN`` it stood for.
"""

from __future__ import annotations

import html
import re

# C0 and C1 controls, DEL, and the Unicode format characters that reorder or hide text
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200b-\u200f\u2028-\u202e\u2060-\u2069\ufeff]")


_SURROGATE = re.compile("[\ud800-\udfff]")


def decodable(text: object) -> str:
    """``str(text)`` with each lone surrogate (an undecodable byte of a file name) as ``\\xNN``."""
    return _SURROGATE.sub(_byte, str(text))


def _byte(m: re.Match[str]) -> str:
    code = ord(m.group())
    return f"\\x{code - 0xDC00:02x}" if 0xDC80 <= code <= 0xDCFF else f"\\u{code:04x}"


def html_text(text: object) -> str:
    """``text`` escaped for HTML, encodable as UTF-8 (:func:`decodable`)."""
    return html.escape(decodable(text))


def safe(text: object, keep: str = "") -> str:
    """``str(text)`` with control and bidi characters shown as ``\\xNN`` / ``\\uNNNN`` (``keep``: spared),
    and undecodable bytes of file names as ``\\xNN`` (:func:`decodable`)."""

    def escape(m: re.Match[str]) -> str:
        c = m.group()
        if c in keep:
            return c
        return f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}"

    return _UNSAFE.sub(escape, decodable(text))


__all__ = ["decodable", "html_text", "safe"]
