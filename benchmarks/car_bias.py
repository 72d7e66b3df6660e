"""The CANedge car's road-tilt model under simulation: is admitting a 3-D bias right, is the tilt σ right?

Used by benchmarks/car_residual.py (which prints it into docs/real-data-car.md); not run on its own.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from scipy import optimize
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import G_N, angles_from_rot_vs, skew
from mountcal.core.errors import FitFailed
from mountcal.estimate import full
from mountcal.loop import model_choice as effects
from mountcal.stops.table import StopTable

MG = 1e3 / G_N  # m/s² → mg


def surface_sigma(loop: effects.Loop) -> float:
    """The fitted road tilt σ (rad): the final table's covariance less the stops' own, trace (gσ)²·2."""
    fin = loop.final
    own = loop.steps[0].table.subset(np.setdiff1d(np.arange(len(loop.steps[0].table)), fin.excluded)).cov_s
    extra = np.trace(fin.table.cov_s - own, axis1=1, axis2=2)  # type: ignore[operator]
    return float(np.sqrt(max(float(np.mean(extra)), 0.0) / 2) / fin.fit.state.g_mps2)


def _tilt_and_sigma(lp: effects.Loop) -> tuple[np.ndarray, np.ndarray, bool]:
    """Rotation vector of the fit, the tilt σ about vehicle x, y as calibrate reports it (Birge-widened when
    structure is left), and whether calibrate would call it confident (nothing unexplained, tilt σ < 2°)."""
    f = lp.final.fit
    birge = max(1.0, float(np.sqrt(f.chi2 / f.dof))) if lp.unexplained and f.dof > 0 else 1.0
    sig = np.sqrt(np.diag(f.cov)[:2]) * birge
    return f.state.rot_vs, sig, not lp.unexplained and bool(np.degrees(sig.max()) < 2.0)


def bias_separability(loop: effects.Loop, g: float, runs: int, rng: np.random.Generator) -> list[str]:
    """Is admitting a 3-D bias right here? Simulate the car's 5 stops (its headings, places and noise) with no
    horizontal bias, each stop on its own surface, an |a| offset that may drift (as a temperature would), run
    the model loop, and compare the tilt with the truth."""
    fin = loop.final
    raw = loop.steps[0].table
    rot = fin.fit.state.rot_vs
    beta = raw.beta_rad
    assert beta is not None
    sigma_tilt = surface_sigma(loop)
    chol = np.linalg.cholesky(raw.cov_s)  # type: ignore[arg-type]
    out = [
        f"Per-stop road tilt {np.degrees(sigma_tilt):.2f}° (1σ), the fitted mounting, the stops' own noise; "
        f"{runs} runs per row.",
        "",
        "| common slope α | |a| offset, its drift over the stops | loop | bias admitted "
        "| median |b_h| fitted (m/s², truth 0) | confident by the tilt about vehicle x, y "
        "| tilt error / σ about vehicle x, y: RMS | within 2σ (all; confident) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    alpha_fit = np.degrees(float(fin.fit.state.slope_rad[0]))
    for alpha_deg, offset, drift in ((0.0, 0.0, 0.0), (alpha_fit, 0.09, 0.0), (alpha_fit, 0.09, 0.05)):
        for name, run in (("now", _loop_now), ("road tilt before outliers", surface_before_outlier)):
            out.append(
                _simulate_row(name, run, raw, rot, beta, g, (alpha_deg, offset, drift), sigma_tilt, chol, runs, rng)
            )
    for name, lr in (
        ("its final model with the road tilt σ by REML", reml(loop, g)),
        ("the loop with the road tilt decided before any outlier", surface_before_outlier(raw, g)),
    ):
        rv, sig, _confident = _tilt_and_sigma(lr)
        f = lr.final.fit
        roll, pitch, _ = np.degrees(angles_from_rot_vs(rv))
        shown = "not admitted"
        if "bias" in f.terms:
            i_b = f.names.index("bias_x")
            sb = np.sqrt(np.diag(f.cov)[i_b : i_b + 3])
            shown = "(" + ", ".join(f"{v:+.3f} ± {e:.3f}" for v, e in zip(f.state.bias_s, sb, strict=True)) + ") m/s²"
        out += [
            "",
            f"The real drive 165, {name}: steps {', '.join(s.added for s in lr.steps)} ({lr.final.reason[:60]}…); "
            f"χ² {f.chi2:.1f} / {f.dof}; bias {shown}; roll {roll:.1f}°, pitch {pitch:.2f}°, tilt σ about vehicle "
            f"x, y {np.degrees(sig[0]):.2f}°, {np.degrees(sig[1]):.2f}°; unexplained: "
            + ("; ".join(f"{u.what} ({u.size})" for u in lr.unexplained) or "none"),
        ]
    return out


def _tilt_error(fitted: Rotation, true: Rotation) -> np.ndarray:
    """Tilt error (rad) about the fitted vehicle x, y axes, whatever the yaw: where the fit puts the true up axis."""
    e = fitted.apply(true.inv().apply([0.0, 0.0, 1.0]))  # the true vehicle z in the fitted vehicle frame
    return np.array([-e[1], e[0]])  # δ = log(R_fit R_trueᵀ) moves the true e_z to (δ_y, −δ_x, 0) in the fit


def reml(lp: effects.Loop, g: float) -> effects.Loop:
    """The final model with its road tilt σ by restricted maximum likelihood (REML) instead of ML.

    ML estimates a variance from the residuals as if the fitted parameters were known; with 5 stops and
    7 parameters most of the scatter is fitted away, so σ comes out small. REML adds log det(Jᵀ Σ⁻¹ J),
    the information of the fitted terms (Patterson & Thompson 1971), which undoes that bias.
    """
    fin = lp.final
    if "surface" not in fin.terms:
        return lp
    own = lp.steps[0].table.subset(np.setdiff1d(np.arange(len(lp.steps[0].table)), fin.excluded))
    rot = fin.fit.state.rot_vs

    def cost(log_s: float) -> tuple[float, StopTable, full.Fit]:
        table = effects.with_surface(own, rot, float(np.exp(log_s)), g)
        f = full.fit(table, fin.terms, g, fin.fit.state)
        logdet = float(np.sum(np.linalg.slogdet(table.cov_s)[1]))  # type: ignore[arg-type]
        return f.chi2 + logdet + float(np.linalg.slogdet(f.fisher)[1]), table, f

    res = optimize.minimize_scalar(
        lambda x: cost(x)[0],
        bounds=(np.log(1e-4), np.log(np.radians(10.0))),
        method="bounded",
        options={"xatol": 0.01},
    )
    _, table, f = cost(float(res.x))
    step = effects.Step(
        "surface (REML)", f"road tilt {np.degrees(np.exp(res.x)):.3g}° by REML", fin.terms, fin.excluded, table, f
    )
    return effects._finish([*lp.steps, step], [])


def surface_before_outlier(table: StopTable, g: float) -> effects.Loop:
    """The proposed order: while the road tilt per stop is on offer and not yet decided, no stop is excluded as
    an outlier (the stop with the largest road tilt is always 'an outlier' against the stops' mm/s² noise).
    Emulated by gating effects._outlier for this one call."""
    original = effects._outlier

    def gated(cur: effects.Step, full_table: StopTable, g_: float, k: int) -> tuple[float, effects.Step] | None:
        if "surface" in effects.candidates(cur.table, cur.terms, True):
            return None
        return original(cur, full_table, g_, k)

    effects._outlier = gated
    try:
        return _loop_now(table, g)
    finally:
        effects._outlier = original


def tilted_surface(table: StopTable, fit: full.Fit, sigma: float, second_order: bool) -> StopTable:
    """The stops' covariance widened by a road tilt τ per stop as it acts: δf = τ × f_v (τ about the vehicle
    x, y axes), which moves the component along gravity by g·sin α·τ as well as the horizontal ones by g·τ;
    with ``second_order`` also the spread g·σ² of the g·|τ|²/2 it takes off along gravity."""
    g = fit.state.g_mps2
    alpha = fit.state.slope_rad[full.site_index(table)[0]]
    beta = table.beta_rad
    assert beta is not None
    f_v = g * np.column_stack([np.sin(alpha) * np.cos(beta), -np.sin(alpha) * np.sin(beta), np.cos(alpha)])
    sk = skew(f_v)
    cov_v = sigma**2 * sk @ np.diag([1.0, 1.0, 0.0]) @ np.swapaxes(sk, 1, 2)
    if second_order:
        cov_v[:, 2, 2] += (g * sigma**2) ** 2
    rm = fit.state.rot_vs.as_matrix()
    return replace(table, cov_s=table.cov_s + rm.T @ cov_v @ rm)  # type: ignore[operator]


def surface_covariance_check(loop: effects.Loop, g: float, runs: int, rng: np.random.Generator) -> list[str]:
    """Is the road-tilt covariance right? The car's 5 stops on a 2.2° slope, each tilted by τ (σ known and
    given to the fit, no bias, no loop): how often is the fitted tilt within 2σ of the truth?"""
    raw = loop.steps[0].table
    rot = loop.final.fit.state.rot_vs
    beta = raw.beta_rad
    assert beta is not None
    chol = np.linalg.cholesky(raw.cov_s)  # type: ignore[arg-type]
    a = float(loop.final.fit.state.slope_rad[0])
    f_v = g * np.column_stack([np.sin(a) * np.cos(beta), -np.sin(a) * np.sin(beta), np.full(len(raw), np.cos(a))])
    out = [
        "| road tilt σ | covariance given to the fit | terms | tilt error / σ about vehicle x, y: RMS | within 2σ |",
        "|---|---|---|---|---|",
    ]
    for sigma_deg in (0.3, 1.19):
        sigma = np.radians(sigma_deg)
        sims = []
        for _ in range(runs):
            tau = rng.normal(0, sigma, (len(raw), 2))
            f_i = Rotation.from_rotvec(np.column_stack([tau, np.zeros(len(raw))])).apply(f_v)
            acc = rot.inv().apply(f_i) + np.einsum("nij,nj->ni", chol, rng.normal(size=(len(raw), 3)))
            sims.append(replace(raw, acc_s=acc))
        for name, terms, widen in (
            ("now: horizontal only, (g·σ)² diag(1, 1, 0)", effects.BASE, None),
            ("τ × f_v (first order)", effects.BASE, False),
            ("τ × f_v and (g·σ²)² along gravity; g fitted", (*effects.BASE, "gravity"), True),
        ):
            z, failed = [], 0
            for sim in sims:
                try:
                    f = full.fit(sim, effects.BASE, g)
                    for _ in range(2):  # the covariance depends on the fit: refit once with the updated one
                        table = (
                            effects.with_surface(sim, f.state.rot_vs, sigma, g)
                            if widen is None
                            else tilted_surface(sim, f, sigma, widen)
                        )
                        f = full.fit(table, terms, g, f.state)
                except FitFailed:
                    failed += 1
                    continue
                z.append(_tilt_error(f.state.rot_vs, rot) / np.sqrt(np.diag(f.cov)[:2]))
            zz = np.array(z)
            out.append(
                f"| {sigma_deg:g}° | {name} | {', '.join(terms)} | {np.sqrt(np.mean(zz[:, 0] ** 2)):.1f}, "
                f"{np.sqrt(np.mean(zz[:, 1] ** 2)):.1f} | {np.mean(np.all(np.abs(zz) <= 2, axis=1)):.0%} "
                f"({len(zz)} fits{f', {failed} did not converge' if failed else ''}) |"
            )
    return out


def _loop_now(table: StopTable, g: float) -> effects.Loop:
    return effects.close_the_loop(table, g, gravity_known=True, alpha=0.001)


def _simulate_row(
    name: str,
    run: Callable[[StopTable, float], effects.Loop],
    raw: StopTable,
    rot: Rotation,
    beta: np.ndarray,
    g: float,
    truth: tuple[float, float, float],
    sigma_tilt: float,
    chol: np.ndarray,
    runs: int,
    rng: np.random.Generator,
) -> str:
    alpha_deg, offset, drift = truth  # common slope (°), offset of |a| (m/s²), its drift over the stops (m/s²)
    vertical = rot.inv().apply([0.0, 0.0, 1.0])
    t = raw.t_s - raw.t_s.mean()  # type: ignore[operator]
    level = offset + drift * t / np.ptp(t)
    admitted, bh, z, conf = 0, [], [], []
    for _ in range(runs):
        tilt = rng.normal(0, sigma_tilt, (len(raw), 2))
        a = np.radians(alpha_deg)
        up = np.column_stack(
            [np.sin(a) * np.cos(beta) + tilt[:, 1], -np.sin(a) * np.sin(beta) - tilt[:, 0], np.ones(len(raw))]
        )
        up /= np.linalg.norm(up, axis=1)[:, None]
        acc = rot.inv().apply(g * up) - level[:, None] * vertical
        acc += np.einsum("nij,nj->ni", chol, rng.normal(size=(len(raw), 3)))
        try:
            lp = run(replace(raw, acc_s=acc), g)
        except Exception:
            continue
        f = lp.final.fit
        if "bias" in f.terms:
            admitted += 1
            b_v = rot.apply(f.state.bias_s)
            bh.append(float(np.hypot(b_v[0], b_v[1])))
        rv, sig, c = _tilt_and_sigma(lp)
        z.append(_tilt_error(rv, rot) / sig)
        conf.append(c)
    zz, cc = np.array(z), np.array(conf)
    inside = np.all(np.abs(zz) <= 2, axis=1)
    return (
        f"| {alpha_deg:.1f}° | {-offset * MG:+.1f} mg, drift {drift * MG:.1f} mg | {name} | "
        f"{admitted / max(len(zz), 1):.0%} | "
        f"{np.median(bh) if bh else float('nan'):.3f} | {np.mean(cc):.0%} | "
        f"{np.sqrt(np.mean(zz[:, 0] ** 2)):.1f}, {np.sqrt(np.mean(zz[:, 1] ** 2)):.1f} | "
        f"{np.mean(inside):.0%}; {np.mean(inside[cc]) if cc.any() else float('nan'):.0%} |"
    )
