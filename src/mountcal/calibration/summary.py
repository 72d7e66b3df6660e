"""A calibration as text for a person: the answer in one line, then what supports it, then the notes.

The answer line (:func:`answer`) holds the four angles, each with its 1σ (an angle the data cannot
determine is ``undetermined``, never a number without its σ), and ``confident`` or ``NOT CONFIDENT:``
with the main reason. The supporting lines and the notes follow (:func:`summary_parts`); nothing is
said twice (the reasons for doubt are in the notes, not repeated after them).
"""

from __future__ import annotations

from mountcal.core.angles import ANGLE_NAMES
from mountcal.core.result import Calibration
from mountcal.estimate import effects

ANGLES = ANGLE_NAMES


def angle(name: str, value: float | None, sigma: float | None) -> str:
    """``roll 5.001 ± 0.599°``, or ``roll undetermined`` when the value or its σ is missing."""
    if value is None or sigma is None:
        return f"{name} undetermined"
    return f"{name} {value:.3f} ± {sigma:.3f}°"


def main_reason(cal: Calibration) -> str:
    """Why a result is not confident, in a few words: the first structure left unexplained or check failed."""
    for u in cal.unexplained:
        return f"{u.what} ({u.size})"
    for c in cal.checks:
        if c.passed is False:
            return f"plausibility check {c.name} failed"
    doubts = [n for n in cal.notes if "not confident" in n]
    return doubts[0].split(";")[0] if doubts else "see the notes"


def answer(cal: Calibration) -> str:
    """The answer in one line: each angle ± 1σ (or undetermined), and whether it is confident."""
    a = cal.angles
    angles = "  ".join(angle(name, a.value(name), a.sigma(name)) for name in ANGLES)
    return f"{angles}  {'confident' if cal.confident else 'NOT CONFIDENT: ' + main_reason(cal)}"


def summary_parts(cal: Calibration) -> tuple[str, list[str], list[str]]:
    """The answer line, the lines that support it (method, model, σ split, fit, gravity, inputs, checks), and
    the notes."""
    sel = cal.model_selection
    how = "fixed, not chosen" if sel.mode == "fixed" else "auto: " + " → ".join(sel.steps)
    how = how if cal.method == "full" else cal.method  # "paper", or "driving" when there were no stops
    lines = [f"{cal.method} method, model: {', '.join(cal.model)} ({how}); uncertainties are 1σ"]
    lines += [f"stop set aside: {step.reason}" for step in cal.model_steps if step.added == "outlier"]
    if cal.systematic is not None:
        from mountcal.loop.systematic import summary_line

        lines.append(summary_line(cal.systematic))
    lines += effects.summary_lines(cal)  # each fitted effect's own line, as it says
    fit = cal.fit
    chi = f", χ² = {fit.chi2:.1f} on {fit.dof} dof" if fit.chi2 is not None else ""
    if fit.p_value is not None:
        chi += f" (p = {fit.p_value:.2g})"
    lines.append(f"residual RMS {cal.residual_rms_mps2:.4g} m/s²{chi}")
    lines.append(f"gravity {cal.gravity_mps2:.5f} m/s² ({cal.gravity_source})")
    if cal.yaw_reason:
        lines.append(f"yaw undetermined: {cal.yaw_reason}")
    if cal.slope_deg is None:
        lines.append("slope undetermined (see the notes)")
    known = {"stated": "stated by", "inferred": "inferred from", "default": "assumed:"}
    lines += [
        f"input {c.name}: {c.value} ({known[c.how]} {c.by})"
        for c in cal.provenance.conventions
        if c.name != "gravity"  # the gravity line above says it
    ]
    if cal.checks:
        by = {True: "passed", False: "FAILED", None: "not tested"}
        groups = {v: [c.name for c in cal.checks if c.passed is k] for k, v in by.items()}
        lines.append("checks " + "; ".join(f"{k}: {', '.join(v)}" for k, v in groups.items() if v))
    if cal.provenance.input_kind:
        lines.append(f"input: {cal.provenance.input_kind}")
    lines += [f"input file: {line}" for line in cal.provenance.incomplete_inputs]
    notes = list(dict.fromkeys(cal.notes))  # each once
    if not cal.confident:
        notes.append("not confident: rotating with it warns, requiring a confident result refuses it")
    return answer(cal), lines, notes


def summary(cal: Calibration) -> str:
    """A readable summary: the answer line, what supports it, the notes (:func:`summary_parts`)."""
    first, lines, notes = summary_parts(cal)
    return "\n".join([first, *(f"  {line}" for line in lines), *(f"  note: {n}" for n in notes)])


__all__ = ["answer", "summary", "summary_parts"]
