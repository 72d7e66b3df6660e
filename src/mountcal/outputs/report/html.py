"""A self-contained HTML report of a calibration: one file, no scripts, no external assets.

Figures are embedded as inline SVG (text drawn as paths, so no fonts are needed) or as base64
PNG. Sections, most wanted first: the angles ± 1σ; what could not be determined and why, in
words; notes; fit quality and gravity; the before/after model steps, effects and unexplained
structure when the result carries them; figures; the model and how it was chosen; observability
with the Cramér–Rao bounds; provenance and conventions.
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from html import escape
from pathlib import PurePath
from typing import Any, Literal

import matplotlib as mpl
from matplotlib.figure import Figure

from mountcal.conventions import G_N
from mountcal.errors import InputError
from mountcal.outputs.report import figures
from mountcal.outputs.report.document import (
    ANGLES,
    ModelStep,
    angle_estimates,
    format_effect,
    format_pm,
    model_steps,
    unexplained,
)
from mountcal.result import STRUCTURE_P, Calibration
from mountcal.stoptable import StopTable

ImageFormat = Literal["svg", "png"]


_CSS = """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;color:#1d2329;
 max-width:980px;margin:24px auto;padding:0 20px;background:#fff}
h1{font-size:24px;margin:0 0 4px}h2{font-size:19px;margin:28px 0 8px;border-bottom:1px solid #d7dde3;
 padding-bottom:3px}h3{font-size:16px;margin:16px 0 6px}
.sub{color:#56606b;margin:0 0 14px}table{border-collapse:collapse;margin:6px 0 10px;font-size:14px}
th,td{border:1px solid #d7dde3;padding:4px 9px;text-align:left;vertical-align:top}
th{background:#f2f5f8}td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.nd{color:#8a4b00;font-weight:600}.ok{color:#1b6e2a;font-weight:600}.bad{color:#a31515;font-weight:600}
.box{border-left:4px solid #c98a00;background:#fff8e6;padding:6px 12px;margin:8px 0}
.info{border-left:4px solid #7a8896;background:#f4f6f8;padding:6px 12px;margin:8px 0}
figure{margin:14px 0 20px}figure svg,figure img{width:100%;max-width:900px;height:auto;display:block}
figcaption{color:#56606b;font-size:13px;margin-top:4px}code{font-size:13px}
ul{margin:4px 0 8px;padding-left:22px}.wide{overflow-x:auto}.small{font-size:13px;color:#56606b}
"""


def render(
    calibration: Calibration | Mapping[str, Any],
    table: StopTable | None = None,
    *,
    title: str | None = None,
    image_format: ImageFormat = "svg",
) -> str:
    """The HTML report of a calibration, as one self-contained document.

    Parameters
    ----------
    calibration : Calibration or mapping
        The result, or its JSON document (which may carry later entries such as ``model_steps``
        and ``unexplained``; a :class:`Calibration` contributes what its ``to_dict`` holds).
    table : StopTable, optional
        The stop table the result was fitted to, in the same order. It adds the 3-D figure of the
        stops on the fitted plane and circle, headings, per-stop σ and the temperature/time
        trends; without it the residual figures are drawn from the result alone.
    title : str, optional
    image_format : {"svg", "png"}
        Inline SVG (default) or base64-encoded PNG.

    Returns
    -------
    str
        The HTML document.

    Raises
    ------
    InputError
        When the document is not a calibration result, or the table's stop count differs from it.
    """
    if isinstance(calibration, Calibration):
        cal, doc = calibration, calibration.to_dict()
    else:
        doc = dict(calibration)
        cal = Calibration.from_dict(doc)
    if table is not None and len(table) != cal.residual_s.shape[0]:
        raise InputError(
            table.source,
            f"the stop table of this result ({cal.residual_s.shape[0]} stops)",
            f"{len(table)} stops",
            "Pass the stop table the calibration was computed from (`mountcal stops … -o stops.csv`).",
        )
    if image_format not in ("svg", "png"):
        raise InputError("--figures", "svg or png", repr(image_format), "Choose one of them.")
    heading = title or f"Mounting calibration — {short_source(str(cal.provenance.get('input') or 'calibration'))}"
    parts = [
        _header(heading, cal, doc),
        _angles_section(cal),
        _undetermined_section(cal, doc),
        _notes_section(cal, table),
        _fit_section(cal),
        _gravity_section(cal),
        _steps_section(doc),
        _figures_section(cal, doc, table, image_format),
        _model_section(cal),
        _observability_section(cal),
        _provenance_section(cal, doc),
    ]
    body = "\n".join(p for p in parts if p)
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f"<title>{escape(heading)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n"
    )


def short_source(source: str) -> str:
    """A readable name for the input: the file name with its folder; for split logs, the folder and count."""
    paths = [PurePath(p.strip()) for p in source.split(" + ")]
    if len(paths) == 1:
        return "/".join(paths[0].parts[-2:])
    try:
        common = PurePath(os.path.commonpath([str(p) for p in paths]))
    except ValueError:  # absolute and relative paths mixed
        common = paths[0].parent
    return f"{'/'.join(common.parts[-2:]) or '.'} ({len(paths)} files)"


# --- sections -------------------------------------------------------------------------------------


def _header(heading: str, cal: Calibration, doc: Mapping[str, Any]) -> str:
    method = "full maximum-likelihood estimator" if cal.method == "full" else "the paper's method (Zhang et al. 2011)"
    created = cal.provenance.get("created_utc") or "unknown time"
    return (
        f'<h1>{escape(heading)}</h1>\n<p class="sub">{escape(method)}, model '
        f"<code>{escape(', '.join(cal.model))}</code> · computed {escape(str(created))} · "
        f"{escape(str(cal.provenance.get('software', 'mountcal')))} · report generated "
        f"{datetime.now(UTC).isoformat(timespec='seconds')} · all uncertainties 1σ</p>" + _confidence(cal, doc)
    )


def _confidence(cal: Calibration, doc: Mapping[str, Any]) -> str:
    p = cal.fit.get("p_value")
    if doc.get("confident") is False:
        return (
            '<p class="box"><b>Not a confident result.</b> The residuals show structure that the model does not '
            "explain (see <i>Closing the loop</i> below): the angles may be off by more than their σ.</p>"
        )
    if isinstance(p, int | float) and p < STRUCTURE_P:
        return (
            f'<p class="box"><b>The model does not explain these stops</b> (χ² p = {p:.2g}). '
            f"{_sigma_caveat(cal.fit)}</p>"
        )
    return ""


def _angles_section(cal: Calibration) -> str:
    est = angle_estimates(cal)
    about = dict(zip("xyz", cal.rotation_sigma_deg, strict=True))
    rows = []
    meaning = {
        "roll": "rotation about vehicle x (forward)",
        "pitch": "rotation about vehicle y (left)",
        "yaw": "rotation about vehicle z (up)",
        "slope": "slope α of the parking plane",
    }
    reasons = any(not e.determined for e in est.values())  # the "why" column only when something is missing
    for name in ANGLES:
        e = est[name]
        value = escape(format_pm(e.value, e.sigma))
        cls = "num" if e.determined else "nd"
        note = f"<td>{escape(e.reason) if not e.determined and e.reason else ''}</td>" if reasons else ""
        rows.append(f'<tr><th>{name}</th><td class="{cls}">{value}</td><td>{meaning[name]}</td>{note}</tr>')
    if cal.bias_mps2 is not None:
        for k, axis in enumerate("xyz"):
            s = None if cal.bias_sigma_mps2 is None else float(cal.bias_sigma_mps2[k])
            b = float(cal.bias_mps2[k])
            mg = format_pm(b / G_N * 1e3, None if s is None else s / G_N * 1e3, " mg")
            rows.append(
                f'<tr><th>bias {axis}</th><td class="num">{escape(format_pm(b, s, " m/s²"))}</td>'
                f"<td>accelerometer bias, sensor {axis} ({escape(mg)})</td>{'<td></td>' if reasons else ''}</tr>"
            )
    why = "<th>not determined because</th>" if reasons else ""
    table = f"<table><tr><th>quantity</th><th>estimate ± 1σ</th><th>meaning</th>{why}</tr>" + "".join(rows) + "</table>"
    axes = ", ".join(f"{axis}: {'not determined' if s is None else f'{s:.3g}°'}" for axis, s in about.items())
    extra = (
        f'<p class="small">Rotation uncertainty about the vehicle axes (1σ) — {escape(axes)}. Angles follow '
        "mountcal's conventions (docs/conventions.md): <code>R_vs = Rz(yaw)·Ry(pitch)·Rx(roll)</code> maps "
        "sensor to vehicle coordinates (ISO 8855: x forward, y left, z up).</p>"
        if any(s is not None for s in cal.rotation_sigma_deg)
        else ""
    )
    return f"<h2>Mounting angles</h2>\n{table}\n{extra}"


def _undetermined_section(cal: Calibration, doc: Mapping[str, Any]) -> str:
    items: list[str] = []
    if cal.yaw_deg is None:
        items.append(f"<b>Yaw</b> is not determined: {escape(cal.yaw_reason or 'no reason given')}.")
    if cal.slope_deg is None:
        items.append("<b>Slope</b> is not determined (see the notes below).")
    # Effects the stops cannot separate (as opposed to effects that were tested and not needed).
    for effect, why in _declined(cal.model_selection).items():
        if effect not in cal.model and any(w in why for w in ("confounded", "not separable", "not enough stops")):
            items.append(f"<b>{escape(effect)}</b> cannot be estimated from these stops: {escape(why)}.")
    if cal.method == "paper":
        items.append("<b>Accelerometer bias</b> is not estimated: the paper's method assumes none.")
    if not items:
        return '<h2>What the data could not determine</h2>\n<p class="ok">Everything in the model is determined.</p>'
    return "<h2>What the data could not determine</h2>\n<ul>" + "".join(f"<li>{i}</li>" for i in items) + "</ul>"


def _model_section(cal: Calibration) -> str:
    sel = cal.model_selection
    mode = sel.get("mode", "fixed")
    lines = [f"<p>Chosen model: <code>{escape(', '.join(cal.model))}</code> ("]
    if cal.method == "paper":
        lines[0] += "the paper's method fits rotation and slope only)</p>"
    elif mode == "fixed":
        lines[0] += "fixed by the user)</p>"
    else:
        lines[0] += "chosen automatically)</p>"
    if "test" in sel:
        test = f"<p>Selection: {escape(str(sel['test']))}"
        if isinstance(sel.get("p_value"), int | float):
            test += (
                f"; statistic {float(sel.get('statistic', math.nan)):.3g}, p = {float(sel['p_value']):.3g} "
                f"(a term is added when p &lt; {float(sel.get('alpha', 0.01)):g})"
            )
        lines.append(test + ".</p>")
    path = sel.get("steps")
    if isinstance(path, Sequence) and not isinstance(path, str) and path:
        lines.append(f"<p>Effects added, in order: {escape(' → '.join(map(str, path)))}.</p>")
    declined = {k: v for k, v in _declined(sel).items() if k not in cal.model}
    if declined:
        lines.append(
            "<p>Effects considered and not added:</p><ul>"
            + "".join(f"<li><b>{escape(k)}</b>: {escape(v)}</li>" for k, v in declined.items())
            + "</ul>"
        )
    candidates = sel.get("candidates")
    if isinstance(candidates, Sequence) and candidates:
        rows = ["<tr><th>candidate model</th><th>χ²</th><th>dof</th><th>residual RMS (m/s²)</th><th>AIC</th></tr>"]
        for c in candidates:
            if not isinstance(c, Mapping):
                continue
            chosen = " (chosen)" if list(c.get("terms", [])) == list(cal.model) else ""
            rows.append(
                f"<tr><td><code>{escape(', '.join(map(str, c.get('terms', []))))}</code>{chosen}</td>"
                f'<td class="num">{_num(c.get("chi2"), ".4g")}</td><td class="num">{_num(c.get("dof"), "d")}</td>'
                f'<td class="num">{_num(c.get("residual_rms_mps2"), ".4g")}</td>'
                f'<td class="num">{_num(c.get("aic"), ".5g")}</td></tr>'
            )
        lines.append("<table>" + "".join(rows) + "</table>")
    return "<h2>Model and model selection</h2>\n" + "\n".join(lines)


def _declined(selection: Mapping[str, Any]) -> dict[str, str]:
    """Effect → the last reason it was not added (a search may decline an effect at every step)."""
    out: dict[str, str] = {}
    raw = selection.get("declined")
    if isinstance(raw, Sequence) and not isinstance(raw, str):
        for item in raw:
            if isinstance(item, Mapping) and "effect" in item:
                out[str(item["effect"])] = str(item.get("why", ""))
    return out


def _fit_section(cal: Calibration) -> str:
    fit = cal.fit
    rms = cal.residual_rms_mps2
    rows = [("residual RMS", f"{rms:.4g} m/s² ({rms / G_N * 1e3:.3g} mg)")]
    chi2, dof, p = fit.get("chi2"), fit.get("dof"), fit.get("p_value")
    if isinstance(chi2, int | float):
        rows.append(("χ²", f"{chi2:.4g} on {dof} degrees of freedom" if dof is not None else f"{chi2:.4g}"))
    if isinstance(p, int | float):
        rows.append(("p (χ² test of the model)", f"{p:.3g}"))
    if fit.get("noise"):
        rows.append(("noise model", str(fit["noise"])))
    if isinstance(fit.get("noise_scale_mps2"), int | float):
        rows.append(("estimated noise σ of a stop mean", f"{fit['noise_scale_mps2']:.4g} m/s²"))
    for key, label in (("iterations", "iterations"), ("pairs", "opposite-heading pairs"), ("headings", "headings")):
        if fit.get(key) is not None:
            rows.append((label, str(fit[key])))
    if fit.get("uncertainty"):
        rows.append(("uncertainty", str(fit["uncertainty"])))
    table = "<table>" + "".join(f"<tr><th>{escape(k)}</th><td>{escape(v)}</td></tr>" for k, v in rows) + "</table>"
    birge = fit.get("birge_ratio")
    if isinstance(birge, int | float) and birge > 1:
        rows.append(("σ widened by", f"×{birge:.3g} (Birge ratio √(χ²/dof): the scatter the model leaves)"))
    if isinstance(p, int | float):
        verdict = (
            f'<p class="bad">The model does not explain these stops (p = {p:.2g} &lt; {STRUCTURE_P:g}): an effect is '
            f"missing from it. {_sigma_caveat(fit)}</p>"
            if p < STRUCTURE_P
            else f'<p class="ok">The residuals are consistent with the stop noise (p = {p:.2g}).</p>'
        )
    else:
        verdict = (
            '<p class="info">The stop noise was estimated from these residuals, so χ² cannot test the fit; '
            "the σ are scaled to the residual spread.</p>"
        )
    return "<h2>Fit quality</h2>\n" + table + verdict


def _sigma_caveat(fit: Mapping[str, Any]) -> str:
    birge = fit.get("birge_ratio")
    if isinstance(birge, int | float) and birge > 1:
        return f"The σ are widened ×{birge:.3g} to cover the scatter, yet may still understate the error."
    return "The σ assume the model is right and are too small."


def _gravity_section(cal: Calibration) -> str:
    assumed = "assumed" in cal.gravity_source
    box = "box" if assumed else "info"
    return f'<h2>Gravity</h2>\n<p class="{box}">g = {cal.gravity_mps2:.5f} m/s² — {escape(cal.gravity_source)}.</p>'


def _observability_section(cal: Calibration) -> str:
    obs = cal.observability
    if not obs:
        return (
            '<h2>Observability</h2>\n<p class="info">Not computed for this method; its σ come from '
            f"{escape(str(cal.fit.get('uncertainty', 'first-order propagation')))}.</p>"
        )
    rank, n = obs.get("fisher_rank"), obs.get("n_parameters")
    cond = obs.get("condition_number")
    params = ", ".join(map(str, obs.get("parameters", [])))
    lines = [
        f"<p>Fisher information rank {escape(str(rank))} of {escape(str(n))} parameters "
        f"(<code>{escape(params)}</code>); condition number "
        f"{'infinite (some direction unobservable)' if cond is None else f'{float(cond):.3g}'}"
        " (of the scaled information matrix).</p>"
    ]
    crb = obs.get("crb_1sigma")
    if isinstance(crb, Mapping) and crb:
        est = angle_estimates(cal)
        head = "".join(f"<th>{a} (deg)</th>" for a in ANGLES)
        rows = [f"<tr><th>1σ</th>{head}</tr>"]
        fit_cells = "".join(f'<td class="num">{_num(est[a].sigma, ".3g")}</td>' for a in ANGLES)
        rows.append(f"<tr><td>this fit (<code>{escape(', '.join(cal.model))}</code>)</td>{fit_cells}</tr>")
        for model, bounds in crb.items():
            if isinstance(bounds, Mapping):
                cells = "".join(f'<td class="num">{_num(bounds.get(f"{a}_deg"), ".3g")}</td>' for a in ANGLES)
            else:
                cells = f'<td colspan="{len(ANGLES)}">singular: not determined by these stops</td>'
            rows.append(f"<tr><td>Cramér–Rao bound, <code>{escape(str(model))}</code></td>{cells}</tr>")
        lines.append("<table>" + "".join(rows) + "</table>")
    if obs.get("crb_note"):
        lines.append(f'<p class="small">{escape(str(obs["crb_note"]))}.</p>')
    return "<h2>Observability</h2>\n" + "\n".join(lines)


def _steps_section(doc: Mapping[str, Any]) -> str:
    steps = model_steps(doc)
    found = unexplained(doc)
    out = ["<h2>Closing the loop: before and after</h2>"]
    if steps is None:
        out.append(
            '<p class="info">This result carries no model steps: the residual analysis that adds effects one '
            "at a time (before/after) was not run for it.</p>"
        )
    elif not steps:
        out.append('<p class="info">The model search recorded no steps.</p>')
    else:
        out.append(_steps_table(steps))
    if found is None:
        out.append('<p class="info">No analysis of unexplained residual structure is recorded in this result.</p>')
    elif not found:
        out.append('<p class="ok">Unexplained structure: none — the best model leaves no significant structure.</p>')
    else:
        first = ["what", "size", "p_value", "test"]
        present = {k for item in found for k in item}
        keys = [k for k in first if k in present] + sorted(present - set(first) - {"log10_p"})
        rows = "".join(
            "<tr>" + "".join(f"<td>{escape(_plain(item.get(k, ''), '.3g'))}</td>" for k in keys) + "</tr>"
            for item in found
        )
        out.append(
            '<p class="bad">Structure the best model leaves unexplained (the σ are qualified accordingly):</p>'
            "<table><tr>" + "".join(f"<th>{escape(k)}</th>" for k in keys) + "</tr>" + rows + "</table>"
        )
    out += [_effects_section(doc), _diagnostics_section(doc)]
    return "\n".join(o for o in out if o)


def _steps_table(steps: Sequence[ModelStep]) -> str:
    head = (
        "<tr><th>step</th><th>model terms</th><th>residual RMS (m/s²)</th><th>χ² (dof)</th>"
        + "".join(f"<th>{a} ± 1σ</th>" for a in ANGLES)
        + "</tr>"
    )
    rows = [head]
    why = []
    for step in steps:
        cells = []
        for a in ANGLES:
            e = step.angles[a]
            text = escape(format_pm(e.value, e.sigma))
            if a in step.moved_deg:
                text += f'<br><span class="small">moved {_moved(step.moved_deg[a], e.sigma)}</span>'
            cells.append(f'<td class="num">{text}</td>')
        chi = "—" if step.chi2 is None else f"{step.chi2:.4g}" + ("" if step.dof is None else f" ({step.dof})")
        if step.p_value is not None:
            chi += f"<br>p = {step.p_value:.2g}"
        rows.append(
            f"<tr><td>{escape(step.label)}</td><td><code>{escape(', '.join(step.terms))}</code></td>"
            f'<td class="num">{_num(step.residual_rms_mps2, ".4g")}</td><td class="num">{chi}</td>'
            f"{''.join(cells)}</tr>"
        )
        details = [escape(step.reason)] if step.reason else []
        if step.excluded_stops:
            details.append(f"stops left out: {', '.join(map(str, step.excluded_stops))}")
        details += [f"{escape(k)} = {escape(format_effect(k, v))}" for k, v in step.effects.items()]
        details += [f"{escape(str(k))}: {escape(_plain(v))}" for k, v in step.extra.items() if v is not None]
        if details:
            why.append(f"<li><b>{escape(step.label)}</b>: {'; '.join(details)}</li>")
    table = '<div class="wide"><table>' + "".join(rows) + "</table></div>"
    return table + ("<h3>What each step added, and why</h3><ul>" + "".join(why) + "</ul>" if why else "")


def _moved(moved: float, sigma: float | None) -> str:
    """A change in degrees, to the precision of the σ it is compared with."""
    text = format_pm(moved, sigma, "°").split(" ± ")[0]
    return ("+" if moved >= 0 and not text.startswith("-") else "") + text


def _effects_section(doc: Mapping[str, Any]) -> str:
    effects = doc.get("effects")
    if not isinstance(effects, Mapping) or not effects:
        return ""
    rows = "".join(
        f'<tr><th>{escape(str(k))}</th><td class="num">{escape(format_effect(str(k), v))}</td></tr>'
        for k, v in effects.items()
    )
    return (
        "<h3>Effects in the final model</h3>\n<table><tr><th>effect</th><th>value ± 1σ "
        "(sensor x, y, z where a vector)</th></tr>" + rows + "</table>"
    )


def _diagnostics_section(doc: Mapping[str, Any]) -> str:
    tests = doc.get("diagnostics")
    if not isinstance(tests, Sequence) or isinstance(tests, str) or not tests:
        return ""
    rows = ["<tr><th>test</th><th>looks for</th><th>size</th><th>p</th><th></th></tr>"]
    for t in tests:
        if not isinstance(t, Mapping):
            continue
        p = _number_or_none(t.get("p_value"))
        flag = (
            '<span class="bad">structure</span>' if p is not None and p < STRUCTURE_P else '<span class="ok">ok</span>'
        )
        rows.append(
            f"<tr><td><code>{escape(str(t.get('test', '')))}</code></td><td>{escape(str(t.get('what', '')))}</td>"
            f'<td>{escape(_plain(t.get("size", "")))}</td><td class="num">{_num(p, ".2g")}</td>'
            f"<td>{flag if p is not None else ''}</td></tr>"
        )
    return (
        "<h3>Residual tests of the final model</h3>\n<table>"
        + "".join(rows)
        + f'</table><p class="small">A test flags structure at p &lt; {STRUCTURE_P:g}.</p>'
    )


def _number_or_none(x: Any) -> float | None:
    return float(x) if isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) else None


def _figures_section(
    cal: Calibration, doc: Mapping[str, Any], table: StopTable | None, image_format: ImageFormat
) -> str:
    out = ["<h2>Figures</h2>"]
    shown: list[tuple[Figure, str]] = []
    if table is not None:
        shown.append(
            (
                figures.stops_3d(cal, table),
                "Stop means (sensor frame) with the fitted plane and circle; lines join each stop's fitted "
                "position to its measured mean, the residual magnified as the legend says. The arrow is the "
                "vehicle's z axis.",
            )
        )
    else:
        out.append(
            '<p class="info">The 3-D figure of the stops on the fitted plane and circle needs the stop means: '
            "pass the stop table (<code>--stops STOPS</code>). The residual figures below come from the result "
            "alone.</p>"
        )
    shown.append(
        (
            figures.residual_vs_heading(cal, table),
            "Per-stop residual (measured − fitted) on the sensor axes, mm/s² (mg on the right).",
        )
    )
    if table is not None and (table.temperature_c is not None or table.t_s is not None):
        shown.append(
            (
                figures.residual_trends(cal, table),
                "Per-stop residual against "
                + " and ".join(
                    name for name, v in (("temperature", table.temperature_c), ("time", table.t_s)) if v is not None
                )
                + ": a trend points at a drifting bias or a changing surface.",
            )
        )
    if cal.observability.get("crb_1sigma") or cal.method == "paper":
        shown.append(
            (
                figures.uncertainty_vs_crb(cal),
                "The 1σ of each angle from this fit beside the Cramér–Rao bound of each model for this very stop set.",
            )
        )
    steps = model_steps(doc)
    entries: dict[str, Mapping[str, Any]] = {}
    for step, item in zip(steps or [], doc.get("model_steps") or [], strict=False):
        if isinstance(item, Mapping):
            entries[_unique(step.label, entries)] = item
    if entries:
        shown.append(
            (figures.angles(entries), "Angles ± 1σ after each model step: how much each moved as effects were added.")
        )
    out += [_figure(fig, caption, image_format, k) for k, (fig, caption) in enumerate(shown, start=1)]
    return "\n".join(out)


def _notes_section(cal: Calibration, table: StopTable | None) -> str:
    notes = list(cal.notes)
    if table is not None:
        notes += list(table.notes)
    if not notes:
        return ""
    return '<h2>Notes</h2>\n<ul class="box">' + "".join(f"<li>{escape(n)}</li>" for n in notes) + "</ul>"


def _provenance_section(cal: Calibration, doc: Mapping[str, Any]) -> str:
    prov = cal.provenance
    rows = "".join(f"<tr><th>{escape(str(k))}</th><td>{escape(_plain(v))}</td></tr>" for k, v in prov.items())
    conv = doc.get("conventions")
    conv_rows = (
        "".join(f"<tr><th>{escape(str(k))}</th><td>{escape(_plain(v))}</td></tr>" for k, v in conv.items())
        if isinstance(conv, Mapping)
        else ""
    )
    q = ", ".join(f"{x:.9f}" for x in cal.rot_vs.as_quat())
    return (
        "<h2>Provenance and conventions</h2>\n<table>"
        + rows
        + f"<tr><th>rotation quaternion (x, y, z, w)</th><td><code>{q}</code>"
        + ("" if cal.yaw_determined else f"<br>{escape(cal.frame)}")
        + "</td></tr>"
        + conv_rows
        + f"<tr><th>format</th><td>{escape(str(doc.get('format')))} version {escape(str(doc.get('format_version')))}"
        "</td></tr></table>"
    )


# --- figures to HTML ------------------------------------------------------------------------------

_ID = re.compile(r'\bid="([^"]+)"')


def _figure(fig: Figure, caption: str, image_format: ImageFormat, number: int) -> str:
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
    body = svg[start:]
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


def _num(x: Any, fmt: str) -> str:
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        return "—"
    return format(int(x), fmt) if fmt == "d" else format(float(x), fmt)


def _plain(v: Any, fmt: str = ".6g") -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, float):
        return format(v, fmt)
    text = json.dumps(v, default=str, ensure_ascii=False)
    return text if len(text) <= 300 else text[:297] + "…"


def _unique(label: str, taken: Iterable[str]) -> str:
    names = set(taken)
    out, k = label, 2
    while out in names:
        out, k = f"{label} ({k})", k + 1
    return out
