"""The report's "closing the loop" section: model steps before/after, unexplained structure,
the final model's effects and its residual tests."""

from __future__ import annotations

from collections.abc import Sequence

from mountcal.core.findings import STRUCTURE_P, Finding
from mountcal.core.result import Calibration, ModelStep
from mountcal.core.terminal import html_text as escape
from mountcal.outputs.report.document import ANGLES, angle_estimates, format_effect, format_pm, moved_deg, step_label


def steps_section(cal: Calibration) -> str:
    out = ["<h2>Closing the loop: before and after</h2>"]
    if not cal.model_steps:
        out.append(
            '<p class="info">This result carries no model steps: the residual analysis that adds effects one '
            f"at a time (before/after) is not part of the {escape(cal.method)} method.</p>"
        )
    else:
        out.append(_steps_table(cal.model_steps))
    if not cal.unexplained:
        if cal.diagnostics:
            out.append(
                '<p class="ok">Unexplained structure: none — the best model leaves no significant structure.</p>'
            )
        else:
            out.append('<p class="info">No analysis of unexplained residual structure is recorded in this result.</p>')
    else:
        out.append(
            '<p class="bad">Structure the best model leaves unexplained (the σ are qualified accordingly):</p>'
            + _findings_table(cal.unexplained, flag=False)
        )
    out += [_effects_section(cal), _diagnostics_section(cal.diagnostics)]
    return "\n".join(o for o in out if o)


def _steps_table(steps: Sequence[ModelStep]) -> str:
    head = (
        "<tr><th>step</th><th>model terms</th><th>residual RMS (m/s²)</th><th>χ² (dof)</th>"
        + "".join(f"<th>{a} ± 1σ</th>" for a in ANGLES)
        + "</tr>"
    )
    rows = [head]
    why = []
    for i, step in enumerate(steps):
        label = step_label(i, step)
        est, moved = angle_estimates(step), moved_deg(step)
        cells = []
        for a in ANGLES:
            text = escape(format_pm(est[a].value, est[a].sigma))
            if a in moved:
                text += f'<br><span class="small">moved {_moved(moved[a], est[a].sigma)}</span>'
            cells.append(f'<td class="num">{text}</td>')
        rows.append(
            f"<tr><td>{escape(label)}</td><td><code>{escape(', '.join(step.terms))}</code></td>"
            f'<td class="num">{step.residual_rms_mps2:.4g}</td><td class="num">{step.chi2:.4g} ({step.dof})</td>'
            f"{''.join(cells)}</tr>"
        )
        details = [escape(step.reason)] if step.reason else []
        if step.excluded_stops:
            details.append(f"stops left out: {', '.join(map(str, step.excluded_stops))}")
        if step.loo_rms_mps2 is not None:
            details.append(f"leave-one-out RMS {step.loo_rms_mps2:.4g} m/s²")
        details += [f"{escape(e.name)} = {escape(format_effect(e))}" for e in step.effects]
        why.append(f"<li><b>{escape(label)}</b>: {'; '.join(details)}</li>")
    table = '<div class="wide"><table>' + "".join(rows) + "</table></div>"
    return table + "<h3>What each step added, and why</h3><ul>" + "".join(why) + "</ul>"


def _moved(moved: float, sigma: float | None) -> str:
    """A change in degrees, to the precision of the σ it is compared with."""
    text = format_pm(moved, sigma, "°").split(" ± ")[0]
    return ("+" if moved >= 0 and not text.startswith("-") else "") + text


def _effects_section(cal: Calibration) -> str:
    if not cal.effects:
        return ""
    rows = "".join(
        f'<tr><th>{escape(e.name)}</th><td class="num">{escape(format_effect(e))}</td></tr>' for e in cal.effects
    )
    return (
        "<h3>Effects in the final model</h3>\n<table><tr><th>effect</th><th>value ± 1σ "
        "(sensor x, y, z where a vector)</th></tr>" + rows + "</table>"
    )


def _diagnostics_section(tests: Sequence[Finding]) -> str:
    if not tests:
        return ""
    return (
        "<h3>Residual tests of the final model</h3>\n"
        + _findings_table(tests, flag=True)
        + f'<p class="small">A test flags structure at p &lt; {STRUCTURE_P:g}.</p>'
    )


def _findings_table(findings: Sequence[Finding], *, flag: bool) -> str:
    rows = ["<tr><th>test</th><th>looks for</th><th>size</th><th>p</th>" + ("<th></th>" if flag else "") + "</tr>"]
    for t in findings:
        p = "—" if t.p_value is None else f"{t.p_value:.2g}"
        if t.p_value is None and t.z_limit is not None and t.statistic is not None:
            p = f"z = {t.statistic:.3g} (limit {t.z_limit:g})"
        verdict = '<span class="bad">structure</span>' if t.significant else '<span class="ok">ok</span>'
        cell = f"<td>{verdict if t.p_value is not None else escape(t.reason or '')}</td>" if flag else ""
        rows.append(
            f"<tr><td><code>{escape(t.test)}</code></td><td>{escape(t.what)}</td><td>{escape(t.size)}</td>"
            f'<td class="num">{escape(p)}</td>{cell}</tr>'
        )
    return "<table>" + "".join(rows) + "</table>"
