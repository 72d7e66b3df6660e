"""A self-contained HTML report of a calibration: one file, no scripts, no external assets.

Figures are embedded as inline SVG (text drawn as paths, so no fonts are needed) or as base64
PNG. Sections, most wanted first: the angles ± 1σ; what could not be determined and why, in
words; notes; fit quality and gravity; the before/after model steps, effects and unexplained
structure when the result carries them; figures; the model and how it was chosen; observability
with the Cramér–Rao bounds; provenance and conventions.
"""

from __future__ import annotations

import json
import math
import os
from datetime import UTC, datetime
from pathlib import PurePath
from typing import Any

from matplotlib.figure import Figure

import mountcal.outputs.report.figures as figures
from mountcal.core.conventions import CONVENTIONS, G_N
from mountcal.core.errors import InputError
from mountcal.core.findings import STRUCTURE_P
from mountcal.core.option_names import option
from mountcal.core.result import FORMAT, FORMAT_VERSION, Calibration, FitQuality, ModelStep
from mountcal.core.terminal import html_text as escape
from mountcal.core.typed_json import to_plain
from mountcal.estimate import effects
from mountcal.outputs.report.document import ANGLES, angle_estimates, format_pm, step_label
from mountcal.outputs.report.embed import ImageFormat, figure_html
from mountcal.outputs.report.loop import steps_section
from mountcal.outputs.report.timeline import Timeline
from mountcal.stops.table import StopTable

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
    calibration: Calibration,
    table: StopTable | None = None,
    *,
    title: str | None = None,
    image_format: ImageFormat = "svg",
    timeline: Timeline | None = None,
) -> str:
    """The HTML report of a calibration, as one self-contained document.

    Parameters
    ----------
    calibration : Calibration
        The result (a result file: :meth:`Calibration.load`; its JSON document: :meth:`Calibration.from_dict`).
    table : StopTable, optional
        The stop table the result was fitted to, in the same order. It adds the 3-D figure of the
        stops on the fitted plane and circle, headings, per-stop σ and the temperature/time
        trends; without it the residual figures are drawn from the result alone.
    title : str, optional
    image_format : {"svg", "png"}
        Inline SVG (default) or base64-encoded PNG.
    timeline : Timeline, optional
        The log over time (:func:`mountcal.outputs.report.timeline_of` of ``calibrate_log``'s
        result): drawn first among the figures, with the stops and driving intervals marked.
        Without it the report says in one line that it was made without the log's samples.

    Returns
    -------
    str
        The HTML document.

    Raises
    ------
    InputError
        When the table's stop count differs from the result's.
    """
    if not isinstance(calibration, Calibration):
        raise TypeError(
            f"render() takes a Calibration, not {type(calibration).__name__} (Calibration.load for a result file, "
            "Calibration.from_dict for its JSON document)"
        )
    cal = calibration
    if table is not None and len(table) != cal.residual_s.shape[0]:
        raise InputError(
            table.source,
            f"the stop table of this result ({cal.residual_s.shape[0]} stops)",
            f"{len(table)} stops",
            "Pass the stop table the calibration was computed from (`mountcal stops … -o stops.csv`).",
        )
    if image_format not in ("svg", "png"):
        raise InputError(option("figures"), "svg or png", repr(image_format), "Choose one of them.")
    heading = title or f"Mounting calibration — {short_source(cal.provenance.input or 'calibration')}"
    parts = [
        _header(heading, cal),
        _angles_section(cal),
        _undetermined_section(cal),
        _notes_section(cal, table),
        _fit_section(cal),
        _gravity_section(cal),
        steps_section(cal),
        _figures_section(cal, table, image_format, timeline),
        _model_section(cal),
        _observability_section(cal),
        _provenance_section(cal),
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


def _header(heading: str, cal: Calibration) -> str:
    method = "full maximum-likelihood estimator" if cal.method == "full" else "the paper's method (Zhang et al. 2011)"
    created = cal.provenance.created_utc
    return (
        f'<h1>{escape(heading)}</h1>\n<p class="sub">{escape(method)}, model '
        f"<code>{escape(', '.join(cal.model))}</code> · computed {escape(str(created))} · "
        f"{escape(cal.provenance.software)} · report generated "
        f"{datetime.now(UTC).isoformat(timespec='seconds')} · all uncertainties 1σ</p>" + _confidence(cal)
    )


def _confidence(cal: Calibration) -> str:
    p = cal.fit.p_value
    if not cal.confident:
        return (
            '<p class="box"><b>Not a confident result.</b> The residuals show structure that the model does not '
            "explain (see <i>Closing the loop</i> below): the angles may be off by more than their σ.</p>"
        )
    if p is not None and p < STRUCTURE_P:
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
    offset = effects.offset_of(cal)
    if offset is not None:
        for k, axis in enumerate("xyz"):
            s = offset.sigma[k]
            b = offset.value[k]
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
    return f"<h2>Mounting angles</h2>\n{table}\n{extra}{_parts(cal)}"


def _parts(cal: Calibration) -> str:
    """The two parts of every σ: the stops' noise and the sensor's limits the stops cannot see."""
    part = cal.systematic
    if part is None:
        return ""
    from mountcal.loop.systematic import summary_line

    dominated = (
        " <b>The error is dominated by sensor errors these stops cannot see</b>: a triad calibration or stops on "
        "slopes of two inclinations would remove that part."
        if part.dominant
        else ""
    )
    default = " No sensor limits were given: a default class was assumed." if part.default_spec else ""
    return (
        f'<p class="small">Each σ above is the total √(statistical² + systematic²) — {escape(summary_line(part))}.'
        f"{default}{dominated}</p>"
    )


def _undetermined_section(cal: Calibration) -> str:
    items: list[str] = []
    if cal.yaw_deg is None:
        items.append(f"<b>Yaw</b> is not determined: {escape(cal.yaw_reason or 'no reason given')}.")
    if cal.slope_deg is None:
        items.append("<b>Slope</b> is not determined (see the notes below).")
    # Effects the stops cannot separate (as opposed to effects that were tested and not needed).
    for effect, why in _declined(cal).items():
        if effect not in cal.model and any(w in why for w in ("confounded", "not separable", "not enough stops")):
            items.append(f"<b>{escape(effect)}</b> cannot be estimated from these stops: {escape(why)}.")
    if cal.method == "paper":
        items.append("<b>Accelerometer bias</b> is not estimated: the paper's method assumes none.")
    if not items:
        return '<h2>What the data could not determine</h2>\n<p class="ok">Everything in the model is determined.</p>'
    return "<h2>What the data could not determine</h2>\n<ul>" + "".join(f"<li>{i}</li>" for i in items) + "</ul>"


def _model_section(cal: Calibration) -> str:
    sel = cal.model_selection
    lines = [f"<p>Chosen model: <code>{escape(', '.join(cal.model))}</code> ("]
    if cal.method == "paper":
        lines[0] += "the paper's method fits rotation and slope only)</p>"
    elif sel.mode == "fixed":
        lines[0] += "fixed by the user)</p>"
    else:
        lines[0] += f"chosen automatically{'' if sel.alpha is None else f', significance {sel.alpha:g}'})</p>"
    if sel.steps:
        lines.append(f"<p>Effects added, in order: {escape(' → '.join(sel.steps))}.</p>")
    declined = {k: v for k, v in _declined(cal).items() if k not in cal.model}
    if declined:
        lines.append(
            "<p>Effects considered and not added:</p><ul>"
            + "".join(f"<li><b>{escape(k)}</b>: {escape(v)}</li>" for k, v in declined.items())
            + "</ul>"
        )
    return "<h2>Model and model selection</h2>\n" + "\n".join(lines)


def _declined(cal: Calibration) -> dict[str, str]:
    """Effect → the last reason it was not added (a search may decline an effect at every step)."""
    return {d.effect: d.why for d in cal.model_selection.declined}


def _fit_section(cal: Calibration) -> str:
    fit = cal.fit
    rms = cal.residual_rms_mps2
    rows = [("residual RMS", f"{rms:.4g} m/s² ({rms / G_N * 1e3:.3g} mg)")]
    if fit.chi2 is not None:
        rows.append(
            ("χ²", f"{fit.chi2:.4g} on {fit.dof} degrees of freedom" if fit.dof is not None else f"{fit.chi2:.4g}")
        )
    if fit.p_value is not None:
        rows.append(("p (χ² test of the model)", f"{fit.p_value:.3g}"))
    texts = (
        ("noise model", fit.noise),
        (
            "estimated noise σ of a stop mean",
            None if fit.noise_scale_mps2 is None else f"{fit.noise_scale_mps2:.4g} m/s²",
        ),
        ("iterations", None if fit.iterations is None else str(fit.iterations)),
        ("opposite-heading pairs", None if fit.pairs is None else str(fit.pairs)),
        ("headings", fit.headings),
        ("uncertainty", fit.uncertainty),
        ("calibrated from", fit.calibrated_from),
    )
    rows += [(label, text) for label, text in texts if text is not None]
    if fit.birge_ratio > 1:
        rows.append(("σ widened by", f"×{fit.birge_ratio:.3g} (Birge ratio √(χ²/dof): the scatter the model leaves)"))
    table = "<table>" + "".join(f"<tr><th>{escape(k)}</th><td>{escape(v)}</td></tr>" for k, v in rows) + "</table>"
    p = fit.p_value
    if p is not None:
        verdict = (
            f'<p class="bad">The model does not explain these stops (p = {p:.2g} &lt; {STRUCTURE_P:g}): an effect is '
            f"missing from it. {_sigma_caveat(fit)}</p>"
            if p < STRUCTURE_P
            else f'<p class="ok">The residuals are consistent with the stop noise (p = {p:.2g}).</p>'
        )
    elif fit.chi2 is None:
        verdict = ""
    else:
        verdict = (
            '<p class="info">The stop noise was estimated from these residuals, so χ² cannot test the fit; '
            "the σ are scaled to the residual spread.</p>"
        )
    return "<h2>Fit quality</h2>\n" + table + verdict


def _sigma_caveat(fit: FitQuality) -> str:
    if fit.birge_ratio > 1:
        return f"The σ are widened ×{fit.birge_ratio:.3g} to cover the scatter, yet may still understate the error."
    return "The σ assume the model is right and are too small."


def _gravity_section(cal: Calibration) -> str:
    assumed = "assumed" in cal.gravity_source
    box = "box" if assumed else "info"
    return f'<h2>Gravity</h2>\n<p class="{box}">g = {cal.gravity_mps2:.5f} m/s² — {escape(cal.gravity_source)}.</p>'


def _observability_section(cal: Calibration) -> str:
    obs = cal.observability
    if obs is None:
        return (
            '<h2>Observability</h2>\n<p class="info">Not computed for this method; its σ come from '
            f"{escape(cal.fit.uncertainty or 'first-order propagation')}.</p>"
        )
    cond = obs.condition_number
    lines = [
        f"<p>Fisher information rank {obs.fisher_rank} of {len(obs.parameters)} parameters "
        f"(<code>{escape(', '.join(obs.parameters))}</code>); condition number "
        f"{'infinite (some direction unobservable)' if cond is None else f'{cond:.3g}'}"
        " (of the scaled information matrix).</p>"
    ]
    if obs.crb_1sigma:
        est = angle_estimates(cal)
        head = "".join(f"<th>{a} (deg)</th>" for a in ANGLES)
        rows = [f"<tr><th>1σ</th>{head}</tr>"]
        fit_cells = "".join(f'<td class="num">{_num(est[a].sigma, ".3g")}</td>' for a in ANGLES)
        rows.append(f"<tr><td>this fit (<code>{escape(', '.join(cal.model))}</code>)</td>{fit_cells}</tr>")
        for model, bounds in obs.crb_1sigma.items():
            if bounds is not None:
                values = (bounds.roll_deg, bounds.pitch_deg, bounds.yaw_deg, bounds.slope_deg)
                cells = "".join(f'<td class="num">{_num(v, ".3g")}</td>' for v in values)
            else:
                cells = f'<td colspan="{len(ANGLES)}">singular: not determined by these stops</td>'
            rows.append(f"<tr><td>Cramér–Rao bound, <code>{escape(model)}</code></td>{cells}</tr>")
        lines.append("<table>" + "".join(rows) + "</table>")
    lines.append(f'<p class="small">{escape(obs.crb_note)}.</p>')
    return "<h2>Observability</h2>\n" + "\n".join(lines)


def _figures_section(
    cal: Calibration, table: StopTable | None, image_format: ImageFormat, timeline: Timeline | None
) -> str:
    out = ["<h2>Figures</h2>"]
    shown: list[tuple[Figure, str]] = []
    if timeline is not None:
        shown.append((figures.log_over_time(timeline), _timeline_caption(timeline)))
    else:
        out.append(_no_timeline())
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
            f"pass the stop table (<code>{option('stops')}</code>). The residual figures below come from the result "
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
    if (cal.observability is not None and cal.observability.crb_1sigma) or cal.method == "paper":
        shown.append(
            (
                figures.uncertainty_vs_crb(cal),
                "The 1σ of each angle from this fit beside the Cramér–Rao bound of each model for this very stop set.",
            )
        )
    entries: dict[str, ModelStep] = {step_label(i, step): step for i, step in enumerate(cal.model_steps)}
    if entries:
        shown.append(
            (figures.angles(entries), "Angles ± 1σ after each model step: how much each moved as effects were added.")
        )
    out += [figure_html(fig, caption, image_format, k) for k, (fig, caption) in enumerate(shown, start=1)]
    return "\n".join(out)


def _timeline_caption(tl: Timeline) -> str:
    drawn = (
        f"min and max per pixel column of its {tl.samples} samples"
        if tl.acc_mps2.decimated
        else f"all {tl.samples} samples"
    )
    parts = [f"The log over time: the accelerometer's sensor axes ({drawn})"]
    if tl.speed_mps is not None:
        offset = tl.speed_offset_s
        moved = f" (the driving fit adds {offset:+.3g} s to its times to put them on the IMU's clock)" if offset else ""
        parts.append(f"the speed on the right-hand axis, as logged{moved}")
    if tl.stops:
        parts.append(
            "shaded: the stops, numbered as in the stop table, by what the fit did with them; hatched without a "
            "number: still periods detection did not keep as a stop (too short once trimmed, too few samples, or "
            "not the longest piece in a protocol row)"
        )
    if tl.driving_s:
        parts.append(f"bottom band: the intervals the driving fit used (calibrated from: {tl.driving_use})")
    return "; ".join(parts) + "."


def _no_timeline() -> str:
    how = option("timeline")
    how = f"mountcal calibrate LOG … {how}" if how.startswith("--") else f"{how}timeline_of(calibrate_log(LOG))"
    return (
        '<p class="info">The log over time (stops and driving intervals marked) is not drawn: this report was made '
        f"without the log's samples. Make it from the log (<code>{escape(how)}</code>).</p>"
    )


def _notes_section(cal: Calibration, table: StopTable | None) -> str:
    notes = list(cal.notes)
    if table is not None:
        notes += list(table.notes)
    if not notes:
        return ""
    return '<h2>Notes</h2>\n<ul class="box">' + "".join(f"<li>{escape(n)}</li>" for n in notes) + "</ul>"


def _provenance_section(cal: Calibration) -> str:
    prov = to_plain(cal.provenance)
    rows = "".join(f"<tr><th>{escape(str(k))}</th><td>{escape(_plain(v))}</td></tr>" for k, v in prov.items())
    conv_rows = "".join(
        f"<tr><th>{escape(str(k))}</th><td>{escape(_plain(v))}</td></tr>" for k, v in CONVENTIONS.items()
    )
    q = ", ".join(f"{x:.9f}" for x in cal.rot_vs.as_quat())
    return (
        "<h2>Provenance and conventions</h2>\n<table>"
        + rows
        + f"<tr><th>rotation quaternion (x, y, z, w)</th><td><code>{q}</code>"
        + ("" if cal.yaw_determined else f"<br>{escape(cal.frame)}")
        + "</td></tr>"
        + conv_rows
        + f"<tr><th>format</th><td>{escape(FORMAT)} version {FORMAT_VERSION}</td></tr></table>"
    )


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
