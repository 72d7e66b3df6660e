"""The terms ``--model`` can name: the one list behind the parser, the CLI help, errors and README.

Each term is an effect of the static model (docs/conventions.md §6, :mod:`mountcal.estimate.full`) with the
stop-table column it needs, if any. ``surface`` (a random road tilt per stop) is not here: it
changes the noise model, and only the automatic selection, which fits its size, adds it.
"""

from __future__ import annotations

from dataclasses import dataclass

from mountcal.stoptable import SITE, STD, TEMPERATURE


@dataclass(frozen=True)
class Term:
    name: str
    meaning: str
    needs: tuple[str, ...] = ()  # stop-table columns it needs


TERMS = (
    Term("rotation", "the mounting rotation (always)"),
    Term("slope", "the slope of the ground (always)"),
    Term("bias", "a constant accelerometer bias, 3 values"),
    Term("temperature", "a bias drift per °C, 3 values", (TEMPERATURE,)),
    Term("gravity", "local gravity, fitted"),
    Term("site_slope", "one slope per site", (SITE,)),
    Term("scale", "scale and cross-axis errors, 6 values"),
)
BASE = tuple(t.name for t in TERMS[:2])
OPTIONAL = tuple(t.name for t in TERMS[2:])
BY_NAME = {t.name: t for t in TERMS}
NOISE_COLUMNS = STD  # not a term: the stop noise comes from these when present


def help_text() -> str:
    """The ``--model`` help of every command that takes it."""
    return f"auto (default: the stops choose), or {','.join(BASE)} followed by any of {', '.join(OPTIONAL)}"


def markdown_list() -> str:
    """The README's list of terms (a test keeps README.md equal to it)."""
    lines = []
    for t in TERMS:
        need = f" (needs the `{'`, `'.join(t.needs)}` column)" if t.needs else ""
        lines.append(f"  - `{t.name}`: {t.meaning}{need}")
    return "\n".join(lines)
