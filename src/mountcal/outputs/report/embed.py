"""Figures to HTML: a matplotlib figure as inline SVG (text as paths, ids made unique) or base64 PNG."""

from __future__ import annotations

import base64
import io
import re
from typing import Literal

import matplotlib as mpl
from matplotlib.figure import Figure

from mountcal.core.terminal import html_text as escape

ImageFormat = Literal["svg", "png"]

_ID = re.compile(r'\bid="([^"]+)"')
_PATH_DATA = re.compile(r'\sd="[^"]*"')
_DIGITS = re.compile(r"(\.\d\d)\d+")  # coordinates in pixels: a hundredth is finer than any screen


def figure_html(fig: Figure, caption: str, image_format: ImageFormat, number: int) -> str:
    alt = caption.split(":")[0].split(";")[0]
    if image_format == "png":
        payload = base64.b64encode(_savefig(fig, "png")).decode("ascii")
        img = f'<img alt="{escape(alt)}" src="data:image/png;base64,{payload}">'
    else:
        img = embed_svg(_savefig(fig, "svg").decode("utf-8"), f"fig{number}-", alt)
    return f"<figure>\n{img}\n<figcaption>{escape(caption)}</figcaption>\n</figure>"


def _savefig(fig: Figure, fmt: str) -> bytes:
    buf = io.BytesIO()
    metadata = {"Date": None} if fmt == "svg" else {"Software": None}
    with mpl.rc_context({"svg.fonttype": "path", "svg.hashsalt": "mountcal"}):
        fig.savefig(buf, format=fmt, dpi=110, metadata=metadata)
    return buf.getvalue()


def embed_svg(svg: str, prefix: str, label: str) -> str:
    """An SVG document made fit to inline in HTML: no XML prolog, ids unique, responsive size.

    Parameters
    ----------
    svg : str
        A standalone SVG document (matplotlib's output).
    prefix : str
        Prepended to every id (and to every reference to one), so that several figures in one
        page do not collide.
    label : str
        Accessible name of the image.
    """
    start = svg.find("<svg")
    if start < 0:
        raise ValueError("not an SVG document")
    body = _PATH_DATA.sub(lambda m: _DIGITS.sub(r"\1", m.group(0)), svg[start:])
    ids = set(_ID.findall(body))
    body = _ID.sub(lambda m: f'id="{prefix}{m.group(1)}"', body)
    body = re.sub(
        r'(href="#|url\(#)([^")]+)',
        lambda m: m.group(1) + (prefix + m.group(2) if m.group(2) in ids else m.group(2)),
        body,
    )
    head_end = body.index(">")
    head = body[:head_end]
    head = re.sub(r'\s(width|height)="[^"]*"', "", head, count=2)
    return head + f' role="img" aria-label="{escape(label)}"' + body[head_end:]
