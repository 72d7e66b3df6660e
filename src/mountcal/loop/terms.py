"""The terms ``--model`` can name: the one list behind the parser, the CLI help, errors and docs/commands.md.

The base terms (rotation, slope) and every registered effect (:mod:`mountcal.estimate.effects`,
built-in or from another package's ``mountcal.effects`` entry point), each with the stop-table
column it needs, if any. ``surface`` (a random road tilt per stop) is not here: it changes the
noise model, and only the automatic selection, which fits its size, adds it.

:func:`help_text` imports no effect (the CLI builds its parser with it); the rest reads the effects.
"""

from __future__ import annotations

from dataclasses import dataclass

from mountcal.estimate import effects as registry


@dataclass(frozen=True)
class Term:
    name: str
    meaning: str
    needs: tuple[str, ...] = ()  # stop-table columns it needs


BASE = registry.BASE
_BASE_MEANINGS = ("the mounting rotation (always)", "the slope of the ground (always)")
BASE_TERMS = tuple(Term(name, meaning) for name, meaning in zip(BASE, _BASE_MEANINGS, strict=True))


def terms() -> tuple[Term, ...]:
    """Every term, the base ones first."""
    effects = registry.registered().values()
    return BASE_TERMS + tuple(Term(e.name, e.meaning, e.needs) for e in effects)


def by_name() -> dict[str, Term]:
    return {t.name: t for t in terms()}


def optional() -> tuple[str, ...]:
    return registry.names()


def help_text() -> str:
    """The ``--model`` help of every command that takes it: the built-in effects (finding those other
    packages register takes longer than a ``--help`` should; :func:`optional` lists them all)."""
    effects = (*registry.BUILTIN, "or an effect another package registers")
    return f"auto (default: the stops choose), or {','.join(BASE)} followed by any of {', '.join(effects)}"


def markdown_list() -> str:
    """The list of terms in docs/commands.md (a test keeps the page equal to it)."""
    lines = []
    for t in terms():
        need = f" (needs the `{'`, `'.join(t.needs)}` column)" if t.needs else ""
        lines.append(f"  - `{t.name}`: {t.meaning}{need}")
    return "\n".join(lines)
