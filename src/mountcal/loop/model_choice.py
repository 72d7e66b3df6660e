"""Closing the loop: from a residual to the effect the model lacks, and back (docs/conventions.md §6).

Starting from the base model (rotation, slope), each round tries every registered effect
(:mod:`mountcal.estimate.effects`) the table can support — each says when it is a candidate — and the
exclusion of the one stop the others predict worst (``outlier``). An effect is a candidate only
when the data can separate it: its Fisher information must be full rank with the terms already in
the model, and the tilt must stay determined; otherwise it is reported as confounded. The most
significant candidate (likelihood ratio, or F-test when the noise is estimated; Bonferroni over
the candidates) is added when it passes at ``alpha`` *and* improves the held-out (leave-one-stop-
out) prediction. What the final model still leaves in the residual is reported as unexplained.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np
from scipy import optimize
from scipy.spatial.transform import Rotation

from mountcal.core.errors import FitFailed
from mountcal.core.findings import Finding
from mountcal.core.pvalues import FAMILY_ALPHA, chi2_logsf, nested_test, unexplained
from mountcal.core.result import Declined, EffectValue
from mountcal.estimate import effects as registry
from mountcal.estimate import full
from mountcal.loop import heading_scatter
from mountcal.loop.diagnose import (
    analyse,
    competing_explanations,
    leave_one_out,
    step_alternative,
)
from mountcal.loop.half_turn import half_turn_note
from mountcal.loop.separability import (
    ALIAS_SHARE,
    PLACE_COLUMNS,
    covers,
    heading_alias,
    heading_share,
    inseparable,
    refuse_inseparable,
)
from mountcal.loop.steps import Loop, Step, held_neg2loglik, neg2loglik
from mountcal.stops.table import StopTable

log = logging.getLogger(__name__)
BASE = full.BASE
MAX_ROUNDS = 6
MAX_SURFACE_TILT_DEG = 3.0  # roads and car parks: cross slopes and grades of a few degrees at most
SAME_PLACE_M = 30.0  # stops farther apart than this may stand on different surfaces
PROGRESS_STOPS = 2000  # from this many stops a model choice takes seconds: its rounds are logged at INFO


def candidates(table: StopTable, terms: tuple[str, ...], gravity_known: bool) -> list[str]:
    """Effects the table's columns allow that are not yet in the model."""
    out = [e.name for e in registry.registered().values() if e.candidate(table, gravity_known)]
    if table.cov_s is not None and _moved(table):
        out.append("surface")
    if heading_scatter.candidate(table):
        out.append(heading_scatter.NAME)
    return [c for c in out if c not in terms]


def _moved(table: StopTable) -> bool:
    """Were the stops made at different places (so possibly on different surfaces)?"""
    if table.site is not None and np.unique(table.site).size > 1:
        return True
    if table.lat_deg is None:
        return False
    north = np.radians(table.lat_deg) * 6.371e6
    east = (
        np.radians(table.lon_deg) * 6.371e6 * np.cos(np.radians(np.mean(table.lat_deg)))
        if table.lon_deg is not None
        else np.zeros(len(table))
    )
    return bool(max(np.ptp(north), np.ptp(east)) > SAME_PLACE_M)


def close_the_loop(
    table: StopTable,
    g_mps2: float,
    gravity_known: bool,
    alpha: float = 0.01,
    fixed: tuple[str, ...] | None = None,
    g_prior: float | None = None,
) -> Loop:
    """Run the loop (or, with ``fixed`` terms, just the base and the fixed model).

    ``g_prior``: the gravity assumed before the stops' position gave ``g_mps2`` (a first step
    then shows what local gravity changes).
    """
    steps = []
    if g_prior is not None:
        naive = full.fit(table, BASE, g_prior)
        steps.append(
            Step("start", f"the paper's model with standard gravity {g_prior:.5f} m/s²", BASE, (), table, naive)
        )
        base = full.fit(table, BASE, g_mps2, naive.state)
        steps.append(
            Step(
                registry.gravity_term(),
                f"local gravity {g_mps2:.5f} m/s² (WGS 84 normal gravity at the stops' position)",
                BASE,
                (),
                table,
                base,
            )
        )
    else:
        base = full.fit(table, BASE, g_mps2)
        steps.append(Step("start", "the paper's model: rotation and slope", BASE, (), table, base))
    declined: list[Declined] = []
    if fixed is not None:
        if fixed != BASE:
            refuse_inseparable(steps[-1], fixed, g_mps2)
            f = full.fit(table, fixed, g_mps2, base.state)
            steps.append(Step("fixed", "terms fixed by the model asked for", fixed, (), table, f))
        return _finish(steps, declined)
    level = logging.INFO if len(table) >= PROGRESS_STOPS else logging.DEBUG
    for round_ in range(1, MAX_ROUNDS + 1):
        t0 = time.perf_counter()
        log.log(
            level,
            "model choice on %d stops, round %d (at most %d): testing effects against %s",
            len(table),
            round_,
            MAX_ROUNDS,
            ", ".join(steps[-1].terms),
        )
        step = _next_step(steps[-1], table, g_mps2, gravity_known, alpha, declined)
        if step is None:
            step, analysed = _named_by_residual(steps[-1], len(table), g_mps2, gravity_known, alpha, declined)
        if step is None:
            step, analysed = _scatter_named_by_residual(steps[-1], len(table), g_mps2, analysed, declined)
        took = time.perf_counter() - t0
        log.log(
            level,
            "model choice, round %d: %s (%.1f s)",
            round_,
            "nothing more to add" if step is None else f"{step.added} added",
            took,
        )
        if step is None:
            return _finish(steps, declined, analysed)
        steps.append(step)
    return _finish(steps, declined)


def _finish(steps: list[Step], declined: list[Declined], findings: list[Finding] | None = None) -> Loop:
    """The loop's result; ``findings``: the final model's residual analysis, when already made."""
    last, n_rows = steps[-1], len(steps[0].table)
    findings = findings if findings is not None else analyse(last.table, last.fit, _rows(last, n_rows))
    doubts = [d for i in range(1, len(steps)) if (d := _step_or_covariate(steps[i - 1], steps[i], n_rows))]
    return Loop(steps, declined, findings, doubts)


def _rows(step: Step, n_rows: int) -> np.ndarray:
    """The rows of the user's table (0-based) that ``step``'s stops are: findings name those."""
    return np.delete(np.arange(n_rows), list(step.excluded))


def _step_or_covariate(before: Step, step: Step, n_rows: int) -> str | None:
    """Why a term driven by a logged covariate that changes with time (temperature) may be the wrong
    explanation: a bias step at one stop (a restart, a knock) explains the stops it was chosen on as well.

    Both follow time, the stops cannot tell them apart, and they move the angles differently; the loop
    keeps the covariate (its effect is the one the model has), the result is not confident. None when the
    term is no covariate or explains more than any step.
    """
    effect = registry.registered().get(step.added)  # None for the loop's own steps (outlier, surface)
    if effect is None or not any(c not in PLACE_COLUMNS for c in effect.needs) or step.excluded != before.excluded:
        return None
    model = full.StaticModel(before.table, before.terms, before.fit.state.g_mps2)
    r = model.residual(before.fit.state)
    explained, at = step_alternative(before.table, r, model.whiten, model.jacobian(before.fit.state))
    gain = before.fit.chi2 - step.fit.chi2
    if at < 0 or explained < gain:
        return None
    return (
        f"a bias step from stop {int(_rows(before, n_rows)[at]) + 1} on (a restart, a knock) explains the stops "
        f"as well as the {step.added} term does (Δχ² {explained:.1f} against {gain:.1f}): both follow time, "
        "these stops cannot tell them apart and they move the angles differently — the result keeps "
        f"{step.added}; note restarts, or let the {', '.join(effect.needs)} rise and fall more than once over "
        "the session, to separate them"
    )


def _next_step(
    cur: Step, table: StopTable, g: float, gravity_known: bool, alpha: float, declined: list[Declined]
) -> Step | None:
    options: list[tuple[float, Step]] = []
    names = candidates(cur.table, cur.terms, gravity_known)
    k = len(names) + 1  # the outlier test is one more candidate
    for name in names:
        if name == "surface":
            try:
                option = _surface(cur, g, k)
            except FitFailed as err:  # a random road tilt that leaves the fit adrift is not taken
                _decline(declined, name, f"its fit failed ({err}): {_why_adrift(cur)}", len(cur.excluded))
                continue
            if option is not None:
                options.append(option)
            continue
        if name == heading_scatter.NAME:
            if heading_scatter.found_structured(declined):
                continue
            try:
                scatter = heading_scatter.heading_scatter_step(cur, g, k)
            except FitFailed as err:
                _decline(declined, name, f"its fit failed ({err}): {_why_adrift(cur)}", len(cur.excluded))
                continue
            if isinstance(scatter, str):
                _decline(declined, name, scatter, len(cur.excluded))
            elif scatter is not None:
                options.append(scatter)
            continue
        effect = registry.get(name)
        terms = (*cur.terms, *(r for r in effect.requires if r not in cur.terms), name)
        covered = effect.covered_by()
        if covered is not None and covers(cur, covered[0], names, g):
            _decline(declined, name, covered[1], len(cur.excluded))
            continue
        problem = inseparable(cur, terms, g)
        if problem:
            _decline(declined, name, problem, len(cur.excluded))
            continue
        if cur.fit.dof - effect.extra(cur.table) < 1:
            _decline(declined, name, "not enough stops to test it", len(cur.excluded))
            continue
        try:
            f = full.fit(cur.table, terms, g, cur.fit.state)
        except FitFailed as err:  # a candidate that does not converge is not taken
            _decline(declined, name, f"its fit failed ({err})", len(cur.excluded))
            continue
        odd = next((w for e in registry.chain(terms) if (w := e.implausible(f.state.values[e.name], g))), None)
        if odd:
            _decline(declined, name, odd, len(cur.excluded))
            continue
        alias = heading_alias(cur, f, name)
        if alias:
            _decline(declined, name, alias, len(cur.excluded))
            continue
        logp, test = nested_test(cur.fit.chi2, f.chi2, len(f.names) - len(cur.fit.names), f.noise_known, f.dof)
        options.append(
            (logp + np.log(k), Step(name, f"{test}, p = {np.exp(logp):.3g}", terms, cur.excluded, cur.table, f))
        )
    outlier = _outlier(cur, table, g, k)
    if outlier is not None:
        options.append(outlier)
    if not options:
        return None
    options.sort(key=lambda o: o[0])
    logp_adj, best = options[0]
    if logp_adj >= np.log(alpha):
        for lp, s in options:
            _decline(
                declined,
                s.added,
                f"not significant: {s.reason} (Bonferroni-adjusted p = {min(np.exp(lp), 1.0):.3g} ≥ {alpha:g})",
                len(cur.excluded),
            )
        return None
    if best.added == "outlier":
        best = _covariate_or_outlier(best, [o for lp, o in options[1:] if lp < np.log(alpha)], cur, declined)
    if best.added not in NOISE_MODEL_STEPS:  # those change the noise model, not the prediction
        best = _among_exclusive(best, [o for lp, o in options[1:] if lp < np.log(alpha)], g, declined)
        cur_loo, new_loo = _loo_rms(cur), _loo_rms(best)
        if not (new_loo < cur_loo):
            _decline(
                declined,
                best.added,
                f"significant ({best.reason}) but it does not improve the held-out "
                f"prediction ({new_loo * 1e3:.3g} vs {cur_loo * 1e3:.3g} mm/s²)",
                len(cur.excluded),
            )
            return None
        return Step(best.added, best.reason, best.terms, best.excluded, best.table, best.fit, new_loo)
    return best


def _named_by_residual(
    cur: Step, n_rows: int, g: float, gravity_known: bool, alpha: float, declined: list[Declined]
) -> tuple[Step | None, list[Finding] | None]:
    """The term the final residual names, when the loop declined it: tried against what it competes with.

    A residual test that carries an effect's name (``temperature``) and that the family's test rejects says
    the model lacks that effect — yet the loop may have declined it, because the candidates' Bonferroni cost hid
    it, or because it excluded a stop the covariate explains. The term is then fitted and compared, by Akaike's
    criterion on the same residual, with the structures that follow time as it does — a bias step at one stop, a
    slow drift (:func:`mountcal.loop.diagnose.competing_explanations`). It is taken when it explains the stops better
    for its number of parameters than each of them and its likelihood ratio passes at ``alpha``; otherwise the
    finding stays, with the better explanation in the reason. A covariate that itself follows the headings
    (:func:`heading_share`) is left to the guard of :func:`heading_alias`: no stop data can tell it from a
    heading pattern.
    """
    covariates = sorted(
        name
        for name, effect in registry.registered().items()
        if name not in cur.terms and _covariate(name) and effect.candidate(cur.table, gravity_known)
    )
    if not covariates:  # no logged covariate a residual test could name: nothing to analyse for
        return None, None
    findings = analyse(cur.table, cur.fit, _rows(cur, n_rows))
    named = {f.test for f in unexplained(findings)}
    for name in (c for c in covariates if c in named):
        effect = registry.get(name)
        terms = (*cur.terms, *(r for r in effect.requires if r not in cur.terms), name)
        added = sum(registry.get(t).extra(cur.table) for t in terms if t not in cur.terms)
        if inseparable(cur, terms, g) is not None or cur.fit.dof - added < 1:
            continue
        try:
            f = full.fit(cur.table, terms, g, cur.fit.state)
        except FitFailed:
            continue
        if any(e.implausible(f.state.values[e.name], g) for e in registry.chain(terms)):
            continue
        beta = cur.table.beta_rad if cur.table.beta_rad is not None else cur.fit.state.beta_rad
        if beta is not None and beta.size == len(cur.table) and heading_share(cur.table, effect, beta) >= ALIAS_SHARE:
            continue  # it follows the headings: the stops cannot tell it from a heading pattern (the guard said so)
        k = len(f.names) - len(cur.fit.names)
        scale = 1.0 if cur.fit.noise_known else max(cur.fit.noise_scale, 1e-300) ** 2
        gain = (cur.fit.chi2 - f.chi2) / scale
        rivals = competing_explanations(cur.table, cur.fit)
        aic = {rival: 2 * dof - explained for rival, (explained, dof) in rivals.items()}
        best = min(aic, key=lambda x: aic[x], default=None)
        logp, test = nested_test(cur.fit.chi2, f.chi2, k, f.noise_known, f.dof)
        if best is not None and aic[best] <= 2 * k - gain:
            _decline(
                declined,
                name,
                f"the residual names it, but {best} explains these stops better for its size (Akaike: "
                f"{aic[best]:.1f} against {2 * k - gain:.1f})",
                len(cur.excluded),
            )
            continue
        if logp >= np.log(alpha):
            continue
        versus = ", ".join(f"{rival} {aic[rival]:.1f}" for rival in aic)
        reason = (
            f"named by the residual test; {test}, p = {np.exp(logp):.3g}; it explains the stops better for its size "
            f"than what it competes with (Akaike {2 * k - gain:.1f} against {versus or 'nothing testable'})"
        )
        return Step(name, reason, terms, cur.excluded, cur.table, f, _loo_rms(cur)), None
    return None, findings


def _scatter_named_by_residual(
    cur: Step, n_rows: int, g: float, findings: list[Finding] | None, declined: list[Declined]
) -> tuple[Step | None, list[Finding] | None]:
    """Each stop's heading error, where the final residual names it ("single stops turned about the vertical") and
    its likelihood ratio passes at the residual tests' own level. Headings set by eye are never exact: the
    Bonferroni cost of every candidate can hide an error the residual still shows, and the noise model adds no
    term to the prediction (the angles stay; yaw's σ takes the headings' scatter in)."""
    if (
        heading_scatter.NAME in cur.terms
        or not heading_scatter.candidate(cur.table)
        or heading_scatter.found_structured(declined)
    ):
        return None, findings
    findings = analyse(cur.table, cur.fit, _rows(cur, n_rows)) if findings is None else findings
    if "stop_heading" not in {f.test for f in unexplained(findings)}:
        return None, findings
    try:
        scatter = heading_scatter.heading_scatter_step(cur, g, 1)
    except FitFailed:
        return None, findings
    if isinstance(scatter, str):
        _decline(declined, heading_scatter.NAME, scatter, len(cur.excluded))
    if scatter is None or isinstance(scatter, str) or scatter[0] >= np.log(FAMILY_ALPHA):
        return None, findings
    step = scatter[1]
    return replace(
        step, reason=f"named by the residual test (single stops turned about the vertical); {step.reason}"
    ), None


def _why_adrift(cur: Step) -> str:
    """Why a fit of these stops may wander without converging: the parameters the values leave nearly free."""
    n, p = len(cur.table), len(cur.fit.names)
    free = " (each stop's heading is a free parameter: the table gives none)" if cur.fit.state.beta_rad.size else ""
    return (
        f"{n} stops give {3 * n} values for the model's {p} parameters{free}, and with a random road tilt per stop "
        "their horizontal readings weigh almost nothing, so some parameters are left nearly undetermined"
    )


def _covariate_or_outlier(outlier: Step, rivals: list[Step], cur: Step, declined: list[Declined]) -> Step:
    """The outlier, or a significant term driven by a logged covariate that explains the stops better.

    A sensor drifting with temperature over a session makes its first or last stop the one the others
    predict worst: excluding it is then significant too, and more so than the term with its extra parameters,
    and once it is gone the rest of the covariate may follow the headings (which the guard declines). The two
    are compared by Akaike's criterion, the excluded stop counted as three free parameters (its own mean).
    """
    terms = [s for s in rivals if s.added not in NOISE_MODEL_STEPS and _covariate(s.added)]
    if not terms:
        return outlier
    scale = 1.0 if cur.fit.noise_known else max(cur.fit.noise_scale, 1e-300) ** 2
    aic_out = (outlier.fit.chi2 / scale) + 2 * (len(outlier.fit.names) + 3)
    best = min(terms, key=lambda s: s.fit.chi2 / scale + 2 * len(s.fit.names))
    aic_term = best.fit.chi2 / scale + 2 * len(best.fit.names)
    if aic_term >= aic_out:
        return outlier
    _decline(
        declined,
        "outlier",
        f"{outlier.reason}; but the {best.added} term explains the stops better for its size (Akaike {aic_term:.1f} "
        f"against {aic_out:.1f} with the stop left out)",
        len(cur.excluded),
    )
    return best


def _covariate(name: str) -> bool:
    """Is the effect driven by a logged covariate (a column other than the place)?"""
    effect = registry.registered().get(name)
    return effect is not None and any(c not in PLACE_COLUMNS for c in effect.needs)


def _outlier(cur: Step, table: StopTable, g: float, k: int) -> tuple[float, Step] | None:
    n = len(cur.table)
    if n - 1 < 4 or cur.fit.dof - 3 < 1:
        return None
    if len(cur.excluded) >= max(1, len(table) // 10):
        return None  # more misfits than that is structure, not a few bad stops: leave it to the diagnostics
    d2, press = leave_one_out(cur.table, cur.fit)
    if not np.any(np.isfinite(d2)):
        return None
    i = int(np.nanargmax(d2))
    logp = float(chi2_logsf(d2[i], 3)) + np.log(n)  # the worst of n stops
    original = int(np.delete(np.arange(len(table)), list(cur.excluded))[i])
    keep = np.ones(n, dtype=bool)
    keep[i] = False
    sub = cur.table.subset(keep)
    start = cur.fit.state if cur.fit.state.beta_rad.size == 0 else _without_beta(cur.fit.state, i)
    try:
        f = full.fit(sub, cur.terms, g, start)
    except FitFailed:  # the others alone cannot be fitted: they cannot judge it either
        return None
    beta = "" if table.beta_rad is None else f", β = {np.degrees(table.beta_rad[original]) % 360:.0f}°"
    turned = half_turn_note(cur.table, i, cur.terms, g, f)
    reason = (
        f"stop {original + 1}{beta} is not predicted by the others: held-out miss {press[i] * 1e3:.3g} mm/s², "
        f"χ²(3) = {d2[i]:.1f}, p = {min(np.exp(logp), 1.0):.3g} (worst of {n})" + (f"; {turned}" if turned else "")
    )
    step = Step("outlier", reason, cur.terms, (*cur.excluded, original), sub, f)
    return logp + np.log(k), step


def with_surface(table: StopTable, rot_vs: Rotation, sigma_rad: float, g: float) -> StopTable:
    """The table with each stop's covariance widened by a random road tilt of ``sigma_rad`` (1σ per axis).

    A tilt δ of the surface about the vehicle's x and y axes moves f_v by g·(δ × e_z): horizontal in
    the vehicle frame, so the extra covariance is ``(g σ)² Rᵀ diag(1, 1, 0) R`` in the sensor frame.
    """
    rm = rot_vs.as_matrix()
    extra = (g * sigma_rad) ** 2 * rm.T @ np.diag([1.0, 1.0, 0.0]) @ rm
    return replace(table, cov_s=table.cov_s + extra)


def _surface(cur: Step, g: float, k: int) -> tuple[float, Step] | None:
    """A random road tilt per stop (stops on different surfaces): its σ by maximum likelihood.

    The search runs with the mean model held at the current fit (O(n) per trial, no refit); three
    refits around its optimum then give the profile likelihood's curvature and, as their parabola's
    vertex, its own optimum; one more at the largest road tilt checks that the profile does not fall
    to the bound — three to five fits instead of one per trial of a search. Where the vertex is not
    close to the held optimum the profile is searched directly.
    """
    if cur.table.cov_s is None or cur.fit.dof < 2:
        return None
    base = cur.table
    rot = cur.fit.state.rot_vs
    resid = cur.fit.residual_s

    def held(log_sigma: float) -> float:
        return held_neg2loglik(resid, with_surface(base, rot, float(np.exp(log_sigma)), g).cov_s)  # type: ignore[arg-type]

    def cost(log_sigma: float, start: full.State) -> tuple[float, StopTable, full.Fit]:
        table = with_surface(base, rot, float(np.exp(log_sigma)), g)
        f = full.fit(table, cur.terms, g, start)
        return neg2loglik(table, f), table, f

    lower, upper = float(np.log(1e-5)), float(np.log(np.radians(MAX_SURFACE_TILT_DEG)))
    x = float(optimize.minimize_scalar(held, bounds=(lower, upper), method="bounded", options={"xatol": 0.01}).x)
    h = 0.05
    value, table, f = cost(x, cur.fit.state)
    if x < lower + 2 * h:  # no tilt with the model held; refitting finds none either where a search would look first
        curvature = (held(x + h) - 2 * held(x) + held(x - h)) / h**2
        near = all(cost(t, f.state)[0] >= value for t in lower + np.array([0.382, 0.618]) * (upper - lower))
    else:
        below, above = cost(x - h, f.state)[0], cost(x + h, f.state)[0]
        if cost(upper, f.state)[0] < min(value, below, above):
            return None  # the profile falls all the way to the bound: more tilt than roads have, not this effect
        curvature = (above - 2 * value + below) / h**2
        shift = -(above - below) / (2 * h * curvature) if curvature > 0 else np.inf
        near = abs(shift) <= 2 * h and lower <= x + shift <= upper  # the profile's optimum is next to the held one
        if near:  # ... at the vertex of its parabola
            x += shift
            value, table, f = cost(x, f.state)
    if not near:  # refitting moves the optimum far (a stop with a large pull): search the profile itself
        res = optimize.minimize_scalar(
            lambda t: cost(t, cur.fit.state)[0], bounds=(lower, upper), method="bounded", options={"xatol": 0.01}
        )
        x = float(res.x)
        value, table, f = cost(x, cur.fit.state)
        curvature = (cost(x + h, cur.fit.state)[0] - 2 * value + cost(x - h, cur.fit.state)[0]) / h**2
    stat = max(neg2loglik(base, cur.fit) - value, 0.0)
    logp = float(chi2_logsf(stat, 1))
    sigma = float(np.exp(x))
    if x > upper - 0.05:
        return None  # the scatter needs more tilt than roads have: not this effect
    rel = float(np.sqrt(2.0 / curvature)) if curvature > 0 else float("nan")
    reason = (
        f"stops on different surfaces: a random road tilt of {np.degrees(sigma):.3g}° (1σ, ±{rel:.0%}) per stop; "
        f"likelihood ratio χ²(1) = {stat:.1f}, p = {np.exp(logp):.3g}"
    )
    terms = (*cur.terms, "surface")
    step = Step("surface", reason, terms, cur.excluded, table, replace(f, terms=terms))
    return logp + np.log(k), step


def _without_beta(state: full.State, i: int) -> full.State:
    from dataclasses import replace

    return replace(state, beta_rad=np.delete(state.beta_rad, i))


NOISE_MODEL_STEPS = ("outlier", "surface", heading_scatter.NAME)


def _among_exclusive(best: Step, rivals: list[Step], g: float, declined: list[Declined]) -> Step:
    """The best of the significant candidates that cannot be fitted together, by Akaike's criterion.

    Nested tests cannot choose between two effects the stops cannot separate from each other (on two
    slopes a bias and a scale error: E·g·e_z is a constant); greedily taking the more significant one
    would then shut the other out for good, so the one whose model fits better for its size is taken.
    """
    exclusive = [  # only a rival that fits better for its size could be taken instead: the others need no check
        r
        for r in rivals
        if r.added not in NOISE_MODEL_STEPS
        and _aic(r.fit) < _aic(best.fit)
        and inseparable(best, (*best.terms, *(t for t in r.terms if t not in best.terms)), g) is not None
    ]
    if not exclusive:
        return best
    chosen = min([best, *exclusive], key=lambda s: _aic(s.fit))
    for other in (s for s in [best, *exclusive] if s is not chosen):
        _decline(
            declined,
            other.added,
            f"it and {chosen.added} cannot both be fitted to these stops; {chosen.added} fits them better for its "
            f"number of parameters (Akaike: {_aic(chosen.fit):.1f} vs {_aic(other.fit):.1f})",
            len(best.excluded),
        )
    return chosen


def _aic(fit: full.Fit) -> float:
    """Akaike's criterion, −2 log L + 2p up to a constant shared by models of the same stops."""
    n = fit.residual_s.size
    fit_term = fit.chi2 if fit.noise_known else n * np.log(fit.chi2 / n)
    return float(fit_term + 2 * len(fit.names))


def _loo_rms(step: Step) -> float:
    """RMS of the held-out misses; NaN when no stop can be held out (each alone sets a parameter),
    so a candidate is then declined: nothing shows it predicts better."""
    _, press = leave_one_out(step.table, step.fit)
    finite = press[np.isfinite(press)]
    return float(np.sqrt(np.mean(finite**2))) if finite.size else float("nan")


def _decline(declined: list[Declined], effect: str, why: str, round_: int) -> None:
    declined.append(Declined(effect, why))


def effect_values(fit: full.Fit) -> tuple[EffectValue, ...]:
    """The fitted values ± 1σ of every effect term of a fit, each as its effect reports it."""
    out = []
    flat = full.parameter_values(fit.state, fit.names)
    sigma = np.sqrt(np.clip(np.diag(fit.cov), 0.0, None))
    for effect in registry.chain(fit.terms):
        idx = list(fit.owned[effect.name])
        names = tuple(fit.names[i] for i in idx)
        out.append(effect.report(flat[idx], sigma[idx], names))
    return tuple(out)
