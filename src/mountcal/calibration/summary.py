"""A calibration as text for a person: angles ± 1σ, slope, model, residual, what could not be determined."""

from __future__ import annotations

from mountcal.core.result import Calibration


def summary(cal: Calibration) -> str:
    """A readable summary: angles ± 1σ, slope, model, residual, what could not be determined."""

    def pm(value: float | None, sigma: float | None, unit: str = "°", fmt: str = ".3f") -> str:
        if value is None:
            return "not determined"
        return f"{value:{fmt}}{unit} ± {sigma:{fmt}}{unit}" if sigma is not None else f"{value:{fmt}}{unit}"

    sel = cal.model_selection
    how = "fixed, not chosen" if sel.mode == "fixed" else "auto: " + " → ".join(sel.steps)
    how = how if cal.method == "full" else cal.method  # "paper", or "driving" when there were no stops
    lines = [
        f"mountcal — {cal.method} method, model: {', '.join(cal.model)} ({how})",
        f"  roll   {pm(cal.roll_deg, cal.roll_sigma_deg)}",
        f"  pitch  {pm(cal.pitch_deg, cal.pitch_sigma_deg)}",
        f"  yaw    {pm(cal.yaw_deg, cal.yaw_sigma_deg)}",
        f"  slope  {pm(cal.slope_deg, cal.slope_sigma_deg)}",
    ]
    if cal.systematic is not None:
        from mountcal.loop.systematic import summary_line

        lines.append("  " + summary_line(cal.systematic))
    if cal.bias_mps2 is not None and cal.bias_sigma_mps2 is not None:
        b = ", ".join(f"{v:+.4f} ± {s:.4f}" for v, s in zip(cal.bias_mps2, cal.bias_sigma_mps2, strict=True))
        lines.append(f"  bias   ({b}) m/s² (sensor x, y, z)")
    fit = cal.fit
    chi = f", χ² = {fit.chi2:.1f} on {fit.dof} dof" if fit.chi2 is not None else ""
    if fit.p_value is not None:
        chi += f" (p = {fit.p_value:.2g})"
    lines.append(f"  residual RMS {cal.residual_rms_mps2:.4g} m/s²{chi}")
    lines.append(f"  gravity {cal.gravity_mps2:.5f} m/s² ({cal.gravity_source})")
    if cal.yaw_reason:
        lines.append(f"  yaw not determined: {cal.yaw_reason}")
    if cal.slope_deg is None:
        lines.append("  slope not determined (see notes)")
    known = {"stated": "stated by", "inferred": "inferred from", "default": "assumed:"}
    lines += [f"  input {c.name}: {c.value} ({known[c.how]} {c.by})" for c in cal.provenance.conventions]
    if cal.checks:
        by = {True: "passed", False: "FAILED", None: "not tested"}
        groups = {v: [c.name for c in cal.checks if c.passed is k] for k, v in by.items()}
        lines.append("  checks " + "; ".join(f"{k}: {', '.join(v)}" for k, v in groups.items() if v))
    lines += [f"  note: {n}" for n in cal.notes]
    if cal.provenance.input_kind:
        lines.append(f"  input: {cal.provenance.input_kind}")
    lines += [f"  input file: {line}" for line in cal.provenance.incomplete_inputs]
    if not cal.confident:
        failed = [f"{c.name} ({c.reason})" for c in cal.checks if c.passed is False]
        found = "; ".join([*(f"{u.what} ({u.size})" for u in cal.unexplained), *failed]) or "see the notes"
        lines.append(f"  NOT CONFIDENT: {found}; rotating with it warns, requiring a confident result refuses it")
    lines.append("  (uncertainties are 1σ)")
    return "\n".join(lines)


__all__ = ["summary"]
