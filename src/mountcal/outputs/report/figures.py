"""Figures of a calibration, as matplotlib Figures for notebooks and the HTML report.

Every function returns a :class:`matplotlib.figure.Figure` built without pyplot: no global state,
no display; it renders with the Agg canvas (PNG) or as SVG. Axes carry units, angles are in
degrees, residuals in mm/s² (with mg on the right-hand axis), and every estimate is drawn with its
1σ error bar. Frames and signs follow docs/conventions.md: stop means are sensor-frame specific force, the
fitted circle is ``R_vsᵀ f_v(α, β) + b`` (docs/conventions.md §2).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Literal, cast

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from mpl_toolkits.mplot3d import Axes3D

from mountcal.core.conventions import G_N, FloatArray, specific_force_v
from mountcal.core.result import Calibration, ModelStep
from mountcal.estimate import effects
from mountcal.outputs.report.document import ANGLES, Estimate, angle_estimates
from mountcal.outputs.report.timeline import Timeline
from mountcal.stops.table import StopTable

AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")  # x, y, z, the usual convention
MM = 1e3  # m/s² → mm/s²
Frame = Literal["sensor", "vehicle"]
_NICE = (1, 2, 5)


# --- the log over time ----------------------------------------------------------------------------

STOP_STYLES: dict[str, dict[str, Any]] = {  # by StopSpan.status
    "used": {"facecolor": "tab:green", "alpha": 0.22, "label": "stop used by the fit"},
    "left out": {"facecolor": "tab:orange", "edgecolor": "tab:red", "alpha": 0.4, "hatch": "xx",
                 "label": "stop left out by the model choice"},
    "not used": {"facecolor": "0.6", "edgecolor": "0.3", "alpha": 0.35, "hatch": "..",
                 "label": "stop found, not used by the result"},
    "dropped": {"facecolor": "none", "edgecolor": "0.45", "hatch": "////", "label": "still, not kept as a stop"},
}  # fmt: skip
DRIVING_COLOUR = "tab:purple"


def log_over_time(timeline: Timeline) -> Figure:
    """The log over time: accelerometer axes (and speed on its own axis) with the stops and drive marked.

    Each signal is drawn as its min/max envelope per pixel column (:mod:`.timeline`), so spikes
    stay. Stops are shaded by what became of them and numbered as in the stop table; still periods
    detection did not keep are hatched, unnumbered; a band at the bottom marks the intervals the
    driving fit used. Every span carries an id (``stop-N``, ``still-K``, ``driving-K``).
    """
    tl = timeline
    fig = Figure(figsize=(9.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    t0 = tl.t_start_s
    minutes = tl.t_end_s - t0 > 1200.0
    scale = 60.0 if minutes else 1.0

    def x(t: Any) -> Any:
        return (np.asarray(t, dtype=float) - t0) / scale

    acc = tl.acc_mps2
    for k, axis in enumerate("xyz"):
        ax.fill_between(
            x(acc.t_s), acc.low[:, k], acc.high[:, k], color=AXIS_COLOURS[k], lw=0.6, label=f"sensor {axis}"
        )
    ax.set_ylabel("specific force (m/s², sensor axes)")
    axes = [ax]
    if tl.speed_mps is not None:
        right = ax.twinx()
        v = tl.speed_mps
        right.fill_between(x(v.t_s), v.low[:, 0], v.high[:, 0], color="0.15", lw=0.8, label="speed")
        right.set_ylabel("speed (m/s)")
        right.set_ylim(bottom=min(0.0, float(np.nanmin(v.low))) if np.isfinite(v.low).any() else 0.0)
        axes.append(right)
    last_label, unlabelled = -np.inf, 0
    for k, stop in enumerate(tl.stops, start=1):
        style = {key: val for key, val in STOP_STYLES[stop.status].items() if key != "label"}
        span = ax.axvspan(x(stop.t_start_s), x(stop.t_end_s), zorder=0, lw=0, **style)
        span.set_gid(f"stop-{stop.number}" if stop.number is not None else f"still-{k}")
        middle = float(x(0.5 * (stop.t_start_s + stop.t_end_s)))
        if stop.number is None:
            continue
        if middle - last_label >= 0.018 * float(x(tl.t_end_s)):  # numbers that would overlap are left out
            ax.text(middle, 1.0, str(stop.number), transform=ax.get_xaxis_transform(), ha="center", va="bottom",
                    fontsize=7)  # fmt: skip
            last_label = middle
        else:
            unlabelled += 1
    for k, (a, b) in enumerate(tl.driving_s, start=1):
        band = ax.axvspan(x(a), x(b), ymin=0.0, ymax=0.035, color=DRIVING_COLOUR, lw=0, zorder=3)
        band.set_gid(f"driving-{k}")
    handles, labels = [], []
    for drawn in axes:
        h, lab = drawn.get_legend_handles_labels()
        handles += h
        labels += lab
    for status in dict.fromkeys(s.status for s in tl.stops):  # the kinds present, in order of appearance
        style = dict(STOP_STYLES[status])
        labels.append(style.pop("label"))
        handles.append(Patch(**style))
    if tl.driving_s:
        handles.append(Patch(color=DRIVING_COLOUR))
        labels.append(f"intervals the driving fit used (calibrated from: {tl.driving_use})")
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4), fontsize=8)
    ax.set_xlim(0.0, max(float(x(tl.t_end_s)), 1e-9))
    ax.set_xlabel(f"time since the log's start ({'min' if minutes else 's'})")
    ax.grid(alpha=0.3)
    numbered = " (numbers as in the stop table)" if any(s.number is not None for s in tl.stops) else ""
    if unlabelled:
        numbered = f" (numbers as in the stop table; {unlabelled} too close to the one before left unnumbered)"
    ax.set_title(f"The log over time{numbered}", fontsize=11, loc="left", pad=12)
    return fig


# --- stops on the plane and circle ----------------------------------------------------------------


def fitted_circle_s(cal: Calibration, beta_rad: FloatArray) -> FloatArray:
    """Points of the fitted circle in the sensor frame, ``R_vsᵀ f_v(α, β) + b`` (docs/conventions.md §2).

    Parameters
    ----------
    cal : Calibration
        Needs a determined slope.
    beta_rad : ndarray, shape (n,)
        Headings β, radians.

    Returns
    -------
    ndarray, shape (n, 3)
        Specific force, m/s², sensor frame.
    """
    if cal.slope_deg is None:
        raise ValueError("the slope is not determined, so there is no fitted circle")
    force_v = specific_force_v(np.radians(cal.slope_deg), beta_rad, cal.gravity_mps2)
    acc_s = np.asarray(cal.rot_vs.inv().apply(force_v), dtype=np.float64)  # scipy ships no types
    offset = effects.offset_of(cal)
    return acc_s + (np.array(offset.value) if offset is not None else 0.0)


def stops_3d(cal: Calibration, table: StopTable) -> Figure:
    """The stop means on the fitted plane and circle, in 3-D, sensor frame.

    The fitted position of each stop (measured mean minus residual) sits on the circle; the line
    from it ends at the measured mean, with the residual magnified by the factor in the legend so
    that it can be seen against the circle's radius ``g·sin α``.

    Parameters
    ----------
    cal : Calibration
    table : StopTable
        The stops the calibration was fitted to (same order).
    """
    _check_rows(cal, table)
    fig = Figure(figsize=(7.5, 6.4), layout="constrained")
    ax = cast(Axes3D, fig.add_subplot(projection="3d"))
    normal_s = cal.rot_vs.inv().apply([0.0, 0.0, 1.0])  # the vehicle's z axis in sensor coordinates
    fitted_s = table.acc_s - cal.residual_s  # NaN where a left-out stop has no prediction
    if cal.slope_deg is not None:
        circle = fitted_circle_s(cal, np.linspace(0.0, 2.0 * np.pi, 361))
        centre = circle[:-1].mean(axis=0)
        radius = cal.gravity_mps2 * np.sin(np.radians(abs(cal.slope_deg)))
        ax.plot(*circle.T, color="0.35", lw=1.2, label=f"fitted circle (radius g·sin α = {radius:.3g} m/s²)")
        title = "Stops on the fitted plane and circle"
    else:
        centre, radius = (
            table.acc_s.mean(axis=0),
            float(np.max(np.linalg.norm(table.acc_s - table.acc_s.mean(0), axis=1))),
        )
        title = "Stops and the fitted plane (slope not determined: no circle)"
    radius = max(radius, 1e-3 * G_N)
    _plane_patch(ax, centre, normal_s, 1.35 * radius)
    ax.quiver(*centre, *(0.8 * radius * normal_s), color="k", lw=1.5, arrow_length_ratio=0.15)
    ax.text(*(centre + 0.9 * radius * normal_s), "vehicle z", fontsize=9)

    left_out = excluded_stops(cal)
    finite = np.all(np.isfinite(cal.residual_s), axis=1)
    residual = np.where(finite[:, None], cal.residual_s, 0.0)
    kept = ~left_out
    biggest = float(np.max(np.linalg.norm(residual[kept], axis=1))) if kept.any() else 0.0
    gain = _nice_gain(0.25 * radius / biggest) if biggest > 0 else 1.0
    drawn = finite & kept  # stops left out are drawn at their measured mean, not magnified
    shown = np.where(drawn[:, None], fitted_s + gain * residual, table.acc_s)
    for a, b in zip(fitted_s[drawn], shown[drawn], strict=True):
        ax.plot(*np.column_stack([a, b]), color="tab:orange", lw=1.0)
    ax.scatter(*fitted_s[finite].T, marker="x", color="0.2", s=22, label="fitted stop positions")
    times = "" if gain == 1 else f", residual × {gain:g}"
    ax.scatter(*shown[kept].T, color="tab:orange", s=26, depthshade=False, label=f"stop means{times}")
    if left_out.any():
        ax.scatter(
            *shown[left_out].T,
            facecolors="none",
            edgecolors="tab:red",
            s=40,
            depthshade=False,
            label="left out of the fit",
        )
    if table.beta_rad is not None and len(table) <= 24:
        for p, beta in zip(shown, np.degrees(table.beta_rad) % 360.0, strict=True):
            out = (p - centre) / max(float(np.linalg.norm(p - centre)), 1e-12)
            ax.text(*(p + 0.08 * radius * out), f"{beta:.0f}°", fontsize=7)
    far = float(np.nanmax(np.abs(shown - centre))) if shown.size else 0.0
    half = max(1.45 * radius, 1.1 * far)  # every stop inside the box, even one left out far away
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xlabel("sensor x (m/s²)")
    ax.set_ylabel("sensor y (m/s²)")
    ax.set_zlabel("sensor z (m/s²)")
    elev, azim = _view_angles(normal_s)
    ax.view_init(elev=elev, azim=azim)
    ax.set_title(title, fontsize=11)
    ax.legend(loc="upper left", fontsize=8)
    return fig


def _plane_patch(ax: Axes3D, centre: FloatArray, normal: FloatArray, half: float) -> None:
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    u, v = np.meshgrid([-half, half], [-half, half])
    pts = centre[:, None, None] + e1[:, None, None] * u + e2[:, None, None] * v
    ax.plot_surface(pts[0], pts[1], pts[2], color="tab:blue", alpha=0.12, linewidth=0, shade=False)


def _view_angles(normal_s: FloatArray, off_normal_deg: float = 55.0) -> tuple[float, float]:
    """Elevation and azimuth (deg) of a view that sees the circle obliquely, not edge-on or flat."""
    helper = np.eye(3)[int(np.argmin(np.abs(normal_s)))]
    side = np.cross(normal_s, helper)
    side /= np.linalg.norm(side)
    a = np.radians(off_normal_deg)
    eye = np.cos(a) * normal_s + np.sin(a) * side
    return float(np.degrees(np.arcsin(np.clip(eye[2], -1.0, 1.0)))), float(np.degrees(np.arctan2(eye[1], eye[0])))


def _nice_gain(x: float) -> float:
    """The largest of 1, 2, 5, 10, 20, … not above x (at least 1)."""
    if x <= 1:
        return 1.0
    exp = np.floor(np.log10(x))
    best = 1.0
    for m in _NICE:
        if m * 10**exp <= x:
            best = float(m * 10**exp)
    return best


# --- residuals ------------------------------------------------------------------------------------


def residual_vs_heading(cal: Calibration, table: StopTable | None = None, frame: Frame = "sensor") -> Figure:
    """Per-stop residual against heading β (or stop number when β is unknown), mm/s² per axis.

    Parameters
    ----------
    cal : Calibration
    table : StopTable, optional
        Gives β and each stop's 1σ; without it the residuals are drawn per stop number, with
        the common noise σ when the fit estimated one.
    frame : {"sensor", "vehicle"}
        Axes the residual is resolved on.
    """
    if table is not None:
        _check_rows(cal, table)
    residual, names = _residual_in(cal, frame)
    sigma = _stop_sigma(cal, table, frame)
    fig = Figure(figsize=(7.5, 4.0), layout="constrained")
    ax = fig.add_subplot()
    n = residual.shape[0]
    if table is not None and table.beta_rad is not None:
        x = np.degrees(table.beta_rad) % 360.0
        spread = 2.5
        xlabel = "heading β (deg, from uphill, counter-clockwise)"
        if table.headings == "relative":
            xlabel = "heading β (deg, relative: unknown common offset)"
        ax.set_xlim(-15, 375)
        ax.set_xticks(np.arange(0, 361, 30 if n <= 24 else 60))
        title = "Residual against heading"
    else:
        x = np.arange(1, n + 1, dtype=float)
        spread = 0.12
        xlabel = "stop number (headings not known: pass the stop table)" if table is None else "stop number"
        title = "Residual per stop"
    _residual_series(ax, x, residual, sigma, names, spread, excluded_stops(cal))
    _residual_legend(fig, ax, sigma)
    ax.set_xlabel(xlabel)
    ax.set_title(title, fontsize=11)
    return fig


def residual_trends(cal: Calibration, table: StopTable, frame: Frame = "sensor") -> Figure:
    """Per-stop residual against temperature and against time, whichever the table has.

    Raises
    ------
    ValueError
        When the table has neither ``temperature_c`` nor ``t_s``.
    """
    _check_rows(cal, table)
    panels = [
        (v, label) for v, label in ((table.temperature_c, "temperature (°C)"), (table.t_s, "time")) if v is not None
    ]
    if not panels:
        raise ValueError("the stop table has neither temperature_c nor t_s")
    residual, names = _residual_in(cal, frame)
    sigma = _stop_sigma(cal, table, frame)
    fig = Figure(figsize=(7.5 if len(panels) == 1 else 10.0, 4.0), layout="constrained")
    axes = fig.subplots(1, len(panels), sharey=True, squeeze=False)[0]
    for ax, (values, label) in zip(axes, panels, strict=True):
        x = np.asarray(values, dtype=float)
        if label == "time":
            x = x - x.min()
            minutes = x.max() > 1200.0
            x = x / 60.0 if minutes else x
            label = f"time since the first stop ({'min' if minutes else 's'})"
        span = float(np.ptp(x)) if x.size else 0.0
        _residual_series(ax, x, residual, sigma, names, 0.01 * span, excluded_stops(cal), secondary=ax is axes[-1])
        ax.set_xlabel(label)
    _residual_legend(fig, axes[0], sigma)
    axes[0].set_title("Residual against " + " and ".join(p[1].split(" (")[0] for p in panels), fontsize=11, loc="left")
    for ax in axes[1:]:
        ax.set_ylabel("")
    return fig


def _residual_series(
    ax: Axes,
    x: FloatArray,
    residual: FloatArray,
    sigma: FloatArray | None,
    names: Sequence[str],
    spread: float,
    excluded: np.ndarray,
    secondary: bool = True,
) -> None:
    """Residuals in mm/s² with 1σ bars; stops left out of the fit hollow, clipped to the axis if far off."""
    kept = ~excluded
    r_mm = residual * MM
    s_mm = None if sigma is None else sigma * MM
    for k in range(3):
        xs = x + (k - 1) * spread
        ax.errorbar(
            xs[kept],
            r_mm[kept, k],
            yerr=None if s_mm is None else s_mm[kept, k],
            fmt="o",
            ms=4,
            capsize=2,
            color=AXIS_COLOURS[k],
            label=names[k],
        )
    ax.axhline(0.0, color="0.4", lw=0.8)
    if excluded.any():
        inside = np.abs(r_mm[kept]) + (0.0 if s_mm is None else s_mm[kept])
        lim = 1.3 * float(np.nanmax(inside)) if kept.any() and np.isfinite(inside).any() else np.inf
        for k in range(3):
            xs, ys = (x + (k - 1) * spread)[excluded], r_mm[excluded, k]
            ax.plot(xs, np.clip(ys, -lim, lim), "o", ms=6, mfc="none", color=AXIS_COLOURS[k])
        for xi, r in zip(x[excluded], r_mm[excluded], strict=True):
            if np.isfinite(lim) and np.nanmax(np.abs(r)) > lim:  # off the axis: say how far
                text = "(" + ", ".join(f"{v:+.0f}" for v in r) + ") mm/s²"
                ax.annotate(text, (xi, 0.93 * lim), ha="center", fontsize=7, color="0.25")
        ax.plot([], [], "o", mfc="none", color="0.3", label="left out of the fit")
        if np.isfinite(lim):
            ax.set_ylim(-lim * 1.05, lim * 1.05)
    ax.set_ylabel("residual (mm/s²)")
    ax.grid(alpha=0.3)
    if secondary:
        right = ax.secondary_yaxis("right", functions=(_mm_to_mg, _mg_to_mm))
        right.set_ylabel("residual (mg)")


def _residual_legend(fig: Figure, ax: Axes, sigma: FloatArray | None) -> None:
    bars = "error bars: 1σ of each stop mean" if sigma is not None else "no per-stop σ known"
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=len(labels), fontsize=8, title=bars, title_fontsize=8)


def _mm_to_mg(x: Any) -> Any:
    return np.asarray(x) / G_N


def _mg_to_mm(x: Any) -> Any:
    return np.asarray(x) * G_N


def _residual_in(cal: Calibration, frame: Frame) -> tuple[FloatArray, tuple[str, str, str]]:
    if frame == "vehicle":
        if not cal.yaw_determined:  # the rotation only levels: x and y keep the sensor's own heading
            return cal.rot_vs.apply(cal.residual_s), ("levelled x (sensor's heading)", "levelled y", "vehicle z (up)")
        return cal.rot_vs.apply(cal.residual_s), ("vehicle x (forward)", "vehicle y (left)", "vehicle z (up)")
    if frame != "sensor":
        raise ValueError(f"frame must be 'sensor' or 'vehicle', not {frame!r}")
    return cal.residual_s, ("sensor x", "sensor y", "sensor z")


def _stop_sigma(cal: Calibration, table: StopTable | None, frame: Frame) -> FloatArray | None:
    """1σ of each stop mean per axis, shape (n, 3), m/s²; None when unknown."""
    n = cal.residual_s.shape[0]
    if table is not None and table.cov_s is not None:
        cov = table.cov_s
        if frame == "vehicle":
            m = cal.rot_vs.as_matrix()
            cov = m @ cov @ m.T
        return np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
    scale = cal.fit.noise_scale_mps2
    if scale is not None and scale > 0:
        return np.full((n, 3), scale)
    return None


def excluded_stops(cal: Calibration) -> np.ndarray:
    """Boolean mask, shape (n,), of the stops the final fit left out (``fit.excluded_stops``, 1-based,
    or a residual that is not finite)."""
    n = cal.residual_s.shape[0]
    mask = np.asarray(~np.all(np.isfinite(cal.residual_s), axis=1), dtype=np.bool_)
    idx = np.array([k - 1 for k in cal.fit.excluded_stops if 1 <= k <= n], dtype=int)
    mask[idx] = True
    return mask


def _check_rows(cal: Calibration, table: StopTable) -> None:
    if len(table) != cal.residual_s.shape[0]:
        raise ValueError(f"the stop table has {len(table)} stops but the calibration has {cal.residual_s.shape[0]}")


# --- uncertainty and angles -----------------------------------------------------------------------


def uncertainty_vs_crb(cal: Calibration) -> Figure:
    """This fit's 1σ of each angle beside the Cramér–Rao bound of each model (log scale, degrees)."""
    est = angle_estimates(cal)
    crb = {} if cal.observability is None else cal.observability.crb_1sigma
    series: list[tuple[str, dict[str, float | None]]] = [
        (f"this fit ({', '.join(cal.model)})", {a: est[a].sigma if est[a].determined else None for a in ANGLES})
    ]
    for model, bounds in crb.items():
        bound: dict[str, float | None] = {a: None if bounds is None else _positive(bounds[a]) for a in ANGLES}
        series.append((f"CRB {model.replace(',', ', ')}", bound))
    fig = Figure(figsize=(7.5, 3.8), layout="constrained")
    ax = fig.add_subplot()
    height = 0.8 / len(series)
    colours = ("tab:orange", "tab:blue", "tab:purple", "tab:gray", "tab:cyan")
    y0 = np.arange(len(ANGLES))[::-1].astype(float)
    positive = [v for _, vals in series for v in vals.values() if v]
    lo = min(positive) / 3 if positive else 1e-3
    for i, (label, values) in enumerate(series):
        y = y0 + 0.4 - (i + 0.5) * height
        widths = [values[a] or 0.0 for a in ANGLES]
        ax.barh(y, widths, height=height * 0.9, left=0, color=colours[i % len(colours)], label=label)
        for yy, a in zip(y, ANGLES, strict=True):
            v = values[a]
            text = f"{v:.3g}°" if v else ("not determined" if i == 0 else "—")
            ax.text(max(v or lo, lo) * 1.08, yy, text, va="center", fontsize=7)
    ax.set_xscale("log")
    ax.set_xlim(left=lo)
    ax.set_xlim(right=max(positive) * 8 if positive else 1.0)
    ax.set_yticks(y0, list(ANGLES))
    ax.set_xlabel("1σ uncertainty (deg, log scale)")
    ax.set_title("Uncertainty of this fit against the Cramér–Rao bound per model", fontsize=11)
    ax.grid(axis="x", which="both", alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    return fig


def _positive(x: Any) -> float | None:
    return float(x) if isinstance(x, int | float) and np.isfinite(x) and x > 0 else None


def angles(
    entries: Mapping[str, Calibration | ModelStep | Mapping[str, Estimate]],
    truth_deg: Mapping[str, float] | None = None,
    which: Sequence[str] = ANGLES,
) -> Figure:
    """Angles ± 1σ of several calibrations or model steps side by side, one panel per angle.

    Parameters
    ----------
    entries : mapping of label to Calibration, ModelStep, or angle name to Estimate
        In display order (e.g. ``{"paper": cal_paper, "full": cal_full}``).
    truth_deg : mapping, optional
        True values (``roll``, ``pitch``, ``yaw``, ``slope``, degrees), drawn as dashed lines.
    which : sequence of str
        The angles to draw.
    """
    labels = list(entries)
    est = {label: angle_estimates(entry) for label, entry in entries.items()}
    fig = Figure(figsize=(max(7.5, 1.2 * len(labels) * len(which) / 2), 3.6), layout="constrained")
    axes = fig.subplots(1, len(which), squeeze=False)[0]
    x = np.arange(len(labels), dtype=float)
    for ax, name in zip(axes, which, strict=True):
        _estimate_panel(ax, x, [est[label][name] for label in labels])
        if truth_deg is not None and truth_deg.get(name) is not None:
            ax.axhline(float(truth_deg[name]), color="k", ls="--", lw=1, label="truth")
            ax.legend(fontsize=8, loc="best")
        ax.set_xticks(
            x,
            labels,
            rotation=30 if max(map(len, labels)) > 8 else 0,
            ha="right" if max(map(len, labels)) > 8 else "center",
        )
        ax.set_xlim(-0.6, len(labels) - 0.4)
        ax.set_ylabel(f"{name} (deg)")
        ax.set_title(name, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle("Angles with 1σ error bars", fontsize=11)
    return fig


def angles_over_time(
    x: Sequence[float] | FloatArray,
    entries: Sequence[Calibration | ModelStep | Mapping[str, Estimate]],
    xlabel: str,
    which: Sequence[str] = ("roll", "pitch", "yaw"),
    marks: Sequence[float] = (),
) -> Figure:
    """Angles ± 1σ of a series of calibrations (one vehicle's logs) against time or log number.

    Parameters
    ----------
    x : sequence of float, shape (n,)
        Position of each calibration on the horizontal axis (e.g. days since the first log).
    entries : sequence of Calibration or mapping, length n
    xlabel : str
        Label of the horizontal axis, with its unit.
    which : sequence of str
    marks : sequence of float
        Positions to mark with a vertical line (a known or detected remount).
    """
    xs = np.asarray(x, dtype=float)
    est = [angle_estimates(e) for e in entries]
    fig = Figure(figsize=(7.5, 1.0 + 2.0 * len(which)), layout="constrained")
    axes = fig.subplots(len(which), 1, sharex=True, squeeze=False)[:, 0]
    for ax, name in zip(axes, which, strict=True):
        _estimate_panel(ax, xs, [e[name] for e in est])
        for m in marks:
            ax.axvline(m, color="tab:red", ls=":", lw=1.2)
        ax.set_ylabel(f"{name} (deg)")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel(xlabel)
    axes[0].set_title("Mounting angles over time, 1σ error bars" + (" (dotted: remount)" if marks else ""), fontsize=11)
    return fig


def _estimate_panel(ax: Axes, x: FloatArray, values: Sequence[Estimate]) -> None:
    ok = np.array([v.determined for v in values], dtype=bool)
    y = np.array([v.value if v.value is not None else np.nan for v in values], dtype=float)
    s = np.array([v.sigma if v.sigma is not None else np.nan for v in values], dtype=float)
    if ok.any():
        ax.errorbar(x[ok], y[ok], yerr=np.nan_to_num(s[ok]), fmt="o", ms=5, capsize=3, color="tab:blue")
    if (~ok).any():
        base = float(np.nanmean(y)) if ok.any() else 0.0
        for xi in x[~ok]:
            ax.annotate("not\ndetermined", (float(xi), base), ha="center", va="center", fontsize=7, color="0.35")
        if not ok.any():
            ax.set_ylim(-1.0, 1.0)
