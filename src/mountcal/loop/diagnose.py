"""Residual analysis after a fit: does the model explain the stops, and if not, how not?

Every test compares the whitened residuals with a structure they would show if an effect were
missing — harmonics against heading, the gravity direction, slow drift across the session,
temperature and hysteresis, offsets per site, the norm against g, single stops off in |a| or in
heading, a step in the bias or the mounting at one stop (:mod:`mountcal.loop.change_points`), scatter
against heading, the one stop the others do not predict — and returns its size
and its p-value; :func:`mountcal.core.pvalues.unexplained` holds the family's false-alarm rate (Holm). docs/effects.md
("Unexplained structure") gives each test's null and what it points at.
"""

from __future__ import annotations

import numpy as np

from mountcal.core.conventions import G_N, FloatArray
from mountcal.core.errors import FitFailed, NotEnoughInformation
from mountcal.core.findings import Finding
from mountcal.core.pvalues import chi2_logsf, f_logsf
from mountcal.estimate import effects as registry
from mountcal.estimate import full
from mountcal.loop.change_points import change_points, largest_bias_step
from mountcal.stops.table import StopTable

HARMONICS = (1, 2, 3, 4)
DRIFT_MODES = 3  # cosine modes of stop order tested for slow drift (a random walk puts most of its power there)
VARIANCE_DRAWS = 400  # simulated residual sets for the null of the variance test
VARIANCE_SIMULATED_STOPS = 60  # above this many stops leverage is small: the asymptotic null (no simulation)


def analyse(table: StopTable, fit: full.Fit, rows: np.ndarray | None = None) -> list[Finding]:
    """Every residual test the table's columns allow (docs/effects.md, "Unexplained structure").

    ``rows`` are the stops' rows in the user's table (0-based; default 0…n−1), for the findings that name a
    stop: the model choice may have left some out.

    Each projection test asks whether adding a set of directions to the linearised model explains
    significantly more of the whitened residual: the directions are first made orthogonal to the
    model's Jacobian (what the fit can already absorb), so with known stop noise the explained part
    is exactly χ²(rank) under the model, and F(rank, dof − rank) when the noise was estimated.
    """
    model = full.StaticModel(table, fit.terms, fit.state.g_mps2)
    r = model.residual(fit.state)
    basis = _span(model.jacobian(fit.state))
    n = len(table)
    findings = [_chi2(fit)]
    tests: list[tuple[str, str, FloatArray]] = []
    beta = table.beta_rad if table.beta_rad is not None and table.headings != "none" else fit.state.beta_rad
    harmonics = []
    if beta is not None and beta.size == n:
        distinct = np.unique(np.round(np.mod(beta, 2 * np.pi), 6)).size
        for k in (k for k in HARMONICS if 2 * k < distinct):  # above Nyquist kβ aliases a lower harmonic
            x = np.column_stack([np.cos(k * beta), np.sin(k * beta)])
            harmonics.append(_per_axis(model.whiten, x))
            tests.append((f"harmonic_{k}beta", f"residual varying as {k}β with heading", harmonics[-1]))
    u = model.predict(fit.state) / fit.state.g_mps2  # the gravity direction in the sensor frame, in g
    pairs = [u[:, i] * u[:, j] for i in range(3) for j in range(i, 3)]
    gravity_tests = (
        ("gravity_linear", "residual linear in the gravity direction (scale, cross-axis, g-sensitive axes)", u),
        ("gravity_quadratic", "residual quadratic in the gravity direction (nonlinearity)", np.column_stack(pairs)),
    )
    if fit.state.slope_rad.size > 1:  # on one slope u is affine in cos β, sin β: these are the harmonics again
        known = _span(np.hstack([basis, *harmonics]))
        for name, what, x in gravity_tests:
            d = _per_axis(model.whiten, x)
            if _outside(d, known).shape[1] > 0:
                tests.append((name, what, d))
    order = time_order(table)
    if n > 2 * DRIFT_MODES:
        rank = np.empty(n)
        rank[order] = np.arange(n)
        x = np.cos(np.pi * np.outer(rank + 0.5, np.arange(1, DRIFT_MODES + 1)) / n)
        tests.append(
            (
                "drift",
                "slow drift across the session (the first cosine modes of stop order)",
                _per_axis(model.whiten, x),
            )
        )
    for effect in registry.registered().values():  # the test against a covariate carries its effect's name
        covariate = effect.covariate(table)
        if covariate is not None:
            tests.append((effect.name, covariate[0], _per_axis(model.whiten, covariate[1])))
    if table.temperature_c is not None and np.ptp(table.temperature_c) > 0:
        rising = np.sign(np.gradient(table.temperature_c[order]))
        hyst = np.empty(n)
        hyst[order] = rising
        if np.ptp(hyst) > 0:  # the sensor both warmed and cooled: a bias that depends on which is hysteresis
            what = "residual offset between warming and cooling stops (thermal hysteresis)"
            tests.append(("hysteresis", what, _per_axis(model.whiten, hyst[:, None])))
    if table.site is not None and np.unique(table.site).size > 1:
        sites = np.unique(table.site)
        x = (table.site[:, None] == sites[None, 1:]).astype(float)
        tests.append(("site_offsets", "residual offset per site", _per_axis(model.whiten, x)))
    along = np.einsum("nij,nj->ni", model.whiten, u / np.linalg.norm(u, axis=1, keepdims=True)).reshape(-1, 1)
    tests.append(("norm", "common offset of |a| from the model's g", along))
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    unwhiten: FloatArray = eye if table.cov_s is None else np.asarray(np.linalg.cholesky(table.cov_s), dtype=float)
    for name, what, d in tests:
        findings.append(_projection(r, d, basis, name, what, fit, unwhiten))
    per_stop = [("stop_norm", "|a| of single stops off the model's g (vibration rectification, shocks)", along)]
    if beta is not None and beta.size == n:
        tangent_v = np.column_stack([-np.sin(beta), -np.cos(beta), np.zeros(n)])
        tangent = model.carry(fit.state, fit.state.rot_vs.inv().apply(tangent_v))
        what = "single stops turned about the vertical (errors in the headings)"
        per_stop.append(("stop_heading", what, np.einsum("nij,nj->ni", model.whiten, tangent).reshape(-1, 1)))
    for name, what, v in per_stop:
        findings.append(_per_stop(r, v.reshape(n, 3), basis, name, what, fit, unwhiten))
    rows = np.arange(n) if rows is None else np.asarray(rows)
    findings += change_points(r, model.whiten, unwhiten, u, basis, order, fit.noise_known, fit.dof, rows)
    if beta is not None and beta.size == n:
        findings.append(
            _variance(r, basis, np.column_stack([np.cos(beta), np.sin(beta), np.cos(2 * beta), np.sin(2 * beta)]))
        )
    findings.append(_single_stop(r, basis, fit, rows))
    return findings


def time_order(table: StopTable) -> np.ndarray:
    """The stops in the order they were taken: by ``t_s`` where logged, else as listed."""
    return np.argsort(table.t_s, kind="stable") if table.t_s is not None else np.arange(len(table))


def step_alternative(table: StopTable, r: FloatArray, whiten: FloatArray, jac: FloatArray) -> tuple[float, int]:
    """Δχ² of the bias step (at one stop, in time order) that explains most of the residual ``r`` beyond the
    span of ``jac``, and the row of the first stop after it (−1 when the stops allow no split)."""
    return largest_bias_step(r, whiten, _span(jac), time_order(table))


def heading_harmonics(whiten: FloatArray, beta: FloatArray, ks: tuple[int, ...]) -> FloatArray | None:
    """Whitened directions of the heading harmonics ``ks`` per axis, those below Nyquist (None if none are)."""
    distinct = np.unique(np.round(np.mod(beta, 2 * np.pi), 6)).size
    x = [np.column_stack([np.cos(k * beta), np.sin(k * beta)]) for k in ks if 2 * k < distinct]
    return _per_axis(whiten, np.hstack(x)) if x else None


def competing_explanations(table: StopTable, fit: full.Fit) -> dict[str, tuple[float, int]]:
    """What the structures that follow time, as a covariate term does, explain of the fit's residual beyond its
    model: ``{name: (Δχ², parameters)}`` for a bias step at one stop in time order (its location one parameter
    more) and a slow drift (the first cosine modes of stop order per axis). Δχ² in units of the stop noise
    (scaled by the fit's noise estimate when the noise is not known)."""
    model = full.StaticModel(table, fit.terms, fit.state.g_mps2)
    r = model.residual(fit.state)
    jac = model.jacobian(fit.state)
    n = len(table)
    scale = 1.0 if fit.noise_known else max(fit.noise_scale, 1e-300) ** 2
    out: dict[str, tuple[float, int]] = {}
    explained, at = step_alternative(table, r, model.whiten, jac)
    if at >= 0:
        out["a bias step"] = (explained / scale, 4)
    if n > 2 * DRIFT_MODES:
        rank = np.empty(n)
        rank[time_order(table)] = np.arange(n)
        x = np.cos(np.pi * np.outer(rank + 0.5, np.arange(1, DRIFT_MODES + 1)) / n)
        found = projection_test(r, _per_axis(model.whiten, x), jac, "drift", fit)
        if found.statistic is not None and found.dof:
            out["a slow drift"] = (float(found.statistic) / scale, int(found.dof))
    return out


def projection_test(r: FloatArray, d: FloatArray, basis: FloatArray, test: str, fit: full.Fit) -> Finding:
    """Does adding the (whitened) directions ``d`` to those of ``basis`` explain significantly more of ``r``?
    (Its ``size`` is in whitened units.)"""
    n = len(r) // 3
    return _projection(r, d, _span(basis), test, test, fit, np.broadcast_to(np.eye(3), (n, 3, 3)))


def _per_axis(whiten: FloatArray, x: FloatArray) -> FloatArray:
    """Whitened directions of an effect ``x[:, c]`` along each sensor axis, shape (3n, 3·k)."""
    n, k = x.shape
    return np.asarray(np.einsum("nij,nc->nicj", whiten, x), dtype=np.float64).reshape(3 * n, 3 * k)


def _span(a: FloatArray, tol: float = 1e-6) -> FloatArray:
    """Orthonormal basis of the column space of ``a`` (singular values below ``tol`` of the largest dropped).

    From the eigenvectors of the small Gram matrix, twice (the second pass restores the orthogonality
    the first loses to rounding): O(rows·cols²) without a dense SVD of the tall matrix.
    """
    norms = np.linalg.norm(a, axis=0)
    q = a[:, norms > 0] / norms[norms > 0]
    for cut in (tol, 1e-3):
        if q.shape[1] == 0:
            break
        lam, vec = np.linalg.eigh(q.T @ q)
        keep = lam > cut**2 * max(float(lam[-1]), 1e-300)
        q = q @ (vec[:, keep] / np.sqrt(lam[keep]))
    return np.ascontiguousarray(q)


def _outside(d: FloatArray, basis: FloatArray) -> FloatArray:
    """Orthonormal basis of what the directions ``d`` add to ``basis`` (dropping what is ≥ 99.99 % inside it)."""
    norms = np.linalg.norm(d, axis=0)
    d = d[:, norms > 0] / norms[norms > 0]
    rest = d - basis @ (basis.T @ d)
    return _span(rest, tol=1e-4) if np.max(np.linalg.norm(rest, axis=0), initial=0.0) > 1e-4 else rest[:, :0]


def _projection(
    r: FloatArray, d: FloatArray, basis: FloatArray, test: str, what: str, fit: full.Fit, unwhiten: FloatArray
) -> Finding:
    """Δχ² of adding the directions ``d`` to the linearised model (exact χ² / F under it).

    From m×m Gram matrices (one pass over the 3n rows): with B = Qᵀd, the part of d outside the
    model's span has Gram ``dᵀd − BᵀB`` and meets the residual in ``dᵀr − Bᵀ(Qᵀr)``; directions whose
    outside part is below 10⁻⁴ of their length count as inside.
    """
    norms = np.sqrt(np.einsum("ij,ij->j", d, d))
    d = d[:, norms > 0] / norms[norms > 0]
    b = basis.T @ d
    lam, vec = np.linalg.eigh(d.T @ d - b.T @ b)
    keep = lam > 1e-8
    dof = int(np.sum(keep))
    if dof == 0:
        why = "no test: the fitted model already absorbs these directions"
        return Finding(test, what, why, None, 0, None, None, why)
    c = vec[:, keep].T @ (d.T @ r - b.T @ (basis.T @ r))
    explained = float(np.sum(c**2 / lam[keep]))
    if fit.noise_known:
        logp = float(chi2_logsf(explained, dof))
    else:
        resid_dof = fit.dof - dof
        if resid_dof < 1:
            why = "no test: too few degrees of freedom left to estimate the noise beside it"
            return Finding(test, what, why, None, dof, None, None, why)
        rest = max(float(r @ r) - explained, 1e-300)
        logp = float(f_logsf((explained / dof) / (rest / resid_dof), dof, resid_dof))
    # Size in physical units: the fitted structure's RMS length per stop, back in m/s².
    coef = vec[:, keep] @ (c / lam[keep])
    structure = d @ coef - basis @ (b @ coef)
    fitted = np.einsum("nij,nj->ni", unwhiten, structure.reshape(-1, 3))
    amp = float(np.sqrt(np.mean(np.sum(fitted**2, axis=1))))
    return Finding(test, what, f"{amp * 1e3 / G_N:.3g} mg RMS", explained, dof, float(np.exp(logp)), logp / np.log(10))


def _per_stop(
    r: FloatArray, v: FloatArray, basis: FloatArray, test: str, what: str, fit: full.Fit, unwhiten: FloatArray
) -> Finding:
    """Δχ² of a free offset at every stop along its own direction ``v[i]`` (whitened), as :func:`_projection`.

    The n directions have disjoint supports, so the statistic ``cᵀ(I − BᵀB)⁻¹c`` (c = Dᵀr, B = QᵀD)
    comes from the p×p matrix BBᵀ: O(n p²) where a dense projection would be O(n³). Directions the
    fit absorbs (eigenvalues of BBᵀ at 1) leave the test with one degree of freedom fewer each.
    """
    n = v.shape[0]
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    c = np.einsum("ni,ni->n", v, r.reshape(n, 3))
    b = np.einsum("nip,ni->pn", basis.reshape(n, 3, -1), v)
    lam, vec = np.linalg.eigh(b @ b.T)
    inside = lam > 1.0 - 1e-6
    proj = vec[:, ~inside].T @ (b @ c)
    explained = float(c @ c + np.sum(proj**2 / (1.0 - lam[~inside])))
    dof = n - int(np.sum(inside))
    if dof < 1 or (not fit.noise_known and fit.dof - dof < 1):
        why = "no test: the fitted model already absorbs these directions, or no degrees of freedom are left"
        return Finding(test, what, why, None, max(dof, 0), None, None, why)
    if fit.noise_known:
        logp = float(chi2_logsf(explained, dof))
    else:
        rest = max(float(r @ r) - explained, 1e-300)
        logp = float(f_logsf((explained / dof) / (rest / (fit.dof - dof)), dof, fit.dof - dof))
    fitted = np.einsum("nij,nj->ni", unwhiten, c[:, None] * v)
    amp = float(np.sqrt(np.mean(np.sum(fitted**2, axis=1))))
    return Finding(test, what, f"{amp * 1e3 / G_N:.3g} mg RMS", explained, dof, float(np.exp(logp)), logp / np.log(10))


def _variance(r: FloatArray, basis: FloatArray, x: FloatArray) -> Finding:
    """Residual variance against heading (Breusch–Pagan on the per-stop |w|²), null by simulation.

    The per-stop squared residuals are not χ²-exact once the fit has absorbed part of them, so the
    statistic's null is simulated under the linearised model (a fixed seed: the same answer every
    time) and its tail taken from the scaled χ² with the simulated mean and variance.
    """
    n = x.shape[0]
    what = "residual scatter varying with heading (1β, 2β)"
    if n < 2 * (x.shape[1] + 1):
        why = "no test: too few stops to see how their scatter varies"
        return Finding("variance_heading", what, why, None, x.shape[1], None, None, why)
    design = np.column_stack([np.ones(n), x])

    def stat(res: FloatArray) -> FloatArray:  # res shape (3n, S)
        d2 = np.sum(res.reshape(n, 3, -1) ** 2, axis=1)
        d2 = d2 / np.mean(d2, axis=0)
        coef, *_ = np.linalg.lstsq(design, d2, rcond=None)
        fitted = design @ coef
        return np.asarray(np.sum((fitted - 1.0) ** 2, axis=0))

    if n <= VARIANCE_SIMULATED_STOPS:
        e = np.random.default_rng(0).standard_normal((r.size, VARIANCE_DRAWS))
        null = stat(e - basis @ (basis.T @ e))
        mean, var = float(np.mean(null)), max(float(np.var(null)), 1e-300)
        a, nu = var / (2 * mean), 2 * mean**2 / var
    else:  # leverage is negligible: |w_i|²/3 has variance 2/3, so the statistic is (2/3)·χ²(k)
        a, nu = 2.0 / 3.0, float(x.shape[1])
    s = float(stat(r[:, None])[0])
    logp = float(chi2_logsf(s / a, nu))
    return Finding(
        "variance_heading",
        what,
        f"{np.sqrt(s / n):.2f} relative",
        s,
        x.shape[1],
        float(np.exp(logp)),
        logp / np.log(10),
    )


def _single_stop(r: FloatArray, basis: FloatArray, fit: full.Fit, rows: np.ndarray) -> Finding:
    """The stop the others predict worst, Bonferroni over the stops.

    Deleting stop i from the linearised fit leaves ``r_iᵀ (I − H_ii)⁻¹ r_i``, exactly χ²(rank) with
    known noise (externally studentised, F, when the noise is estimated); ``H_ii`` is the stop's
    block of the hat matrix (a stop whose own heading is fitted keeps two directions of three).
    """
    n = r.size // 3
    what = "one stop the others do not predict"
    q = basis.reshape(n, 3, -1)
    m = np.eye(3) - q @ q.transpose(0, 2, 1)
    rs = r.reshape(n, 3)
    if fit.state.beta_rad.size == 0:  # the blocks are regular unless one stop alone sets a parameter
        k = np.where(np.linalg.det(m) > 1e-9, 3, 0)
        d2 = np.zeros(n)
        full_rank = k == 3
        d2[full_rank] = np.einsum(
            "ni,ni->n", rs[full_rank], np.linalg.solve(m[full_rank], rs[full_rank, :, None])[..., 0]
        )
    else:  # each stop's own heading is fitted: its block is singular along it
        lam, vec = np.linalg.eigh(m)
        keep = lam > 1e-9
        proj = np.einsum("nij,ni->nj", vec, rs)
        d2 = np.sum(np.where(keep, proj**2 / np.where(keep, lam, 1.0), 0.0), axis=1)
        k = keep.sum(axis=1)
    ok = k > 0
    if not np.any(ok):
        why = "no test: no stop can be predicted from the others"
        return Finding("single_stop", what, why, None, 3, None, None, why)
    if fit.noise_known:
        logp_each = chi2_logsf(d2[ok], k[ok])
    else:
        rest_dof = fit.dof - k[ok]
        if np.any(rest_dof < 1):
            why = "no test: too few degrees of freedom left to estimate the noise without a stop"
            return Finding("single_stop", what, why, None, 3, None, None, why)
        rest = np.maximum(float(r @ r) - d2[ok], 1e-300)
        logp_each = f_logsf((d2[ok] / k[ok]) / (rest / rest_dof), k[ok], rest_dof)
    worst = int(np.argmin(logp_each))
    stop = int(np.flatnonzero(ok)[worst])
    logp = min(float(logp_each[worst]) + float(np.log(np.sum(ok))), 0.0)
    return Finding(
        "single_stop",
        what,
        f"stop {int(rows[stop]) + 1}: held-out χ² {d2[stop]:.1f} on {k[stop]}",
        float(d2[stop]),
        int(k[stop]),
        float(np.exp(logp)),
        logp / np.log(10),
    )


def leave_one_out(table: StopTable, fit: full.Fit) -> tuple[FloatArray, FloatArray]:
    """Externally studentised stop residuals: each stop predicted by a fit of the others.

    Closed form at the fit's optimum, O(n p²) for all n stops (an exact refit per stop is O(n² p²)):
    deleting stop i's rows from the linearised problem moves the parameters by
    ``(F − J_iᵀJ_i)⁻¹ J_iᵀ r_i``, so the held-out whitened miss is ``(I − H_ii)⁻¹ r_i`` with
    ``H_ii = J_i F⁻¹ J_iᵀ`` the stop's 3×3 block of the hat matrix (Cook & Weisberg's deletion
    formulas for a block of rows). When the headings are fitted, each stop's own β_i drops out with
    it: the others see the stop through ``P_i``, the projection orthogonal to ∂r_i/∂β_i, and the
    held-out prediction keeps β_i at its fitted value. :func:`leave_one_out_refit` is the exact
    reference it is tested against.

    Returns
    -------
    d2 : ndarray, shape (n,)
        Squared Mahalanobis distance of each held-out stop from its prediction, ~χ²(3); NaN for a
        stop the others cannot predict (it alone determines a parameter).
    press : ndarray, shape (n,)
        Held-out prediction error ``|a_i − â_i(−i)|`` in m/s² (the cross-validation score).
    """
    n = len(table)
    model = full.StaticModel(table, fit.terms, fit.state.g_mps2)
    r = model.residual(fit.state).reshape(n, 3)
    jac = model.jacobian(fit.state)
    p = jac.shape[1] - (n if model.fit_beta else 0)
    g = jac[:, :p].reshape(n, 3, p)
    v = g
    if model.fit_beta:
        b = jac[np.arange(3 * n), p + np.repeat(np.arange(n), 3)].reshape(n, 3)
        bb = np.einsum("ni,ni->n", b, b)
        proj = np.eye(3) - np.einsum("ni,nj->nij", b, b) / np.where(bb > 0, bb, np.inf)[:, None, None]
        v = proj @ g
    a_inv = full.inverse_information(np.einsum("nip,niq->pq", v, v))
    va = v @ a_inv  # V_i A⁻¹, shape (n, 3, p)
    w = np.einsum("nip,ni->np", va, r)  # A⁻¹ V_iᵀ r_i (A symmetric)
    i_q = np.eye(3) - np.einsum("nip,njp->nij", va, v)  # I − H_ii
    ok = np.linalg.eigvalsh(i_q)[:, 0] > 1e-9
    i_q[~ok] = np.eye(3)
    x = np.linalg.solve(i_q, np.einsum("nip,np->ni", v, w)[..., None])[..., 0]
    delta = w + np.einsum("nip,ni->np", va, x)  # Woodbury: (A − V_iᵀV_i)⁻¹ V_iᵀ r_i
    e_w = r + np.einsum("nip,np->ni", g, delta)
    if fit.noise_known:
        scale2 = np.ones(n)
    else:
        dof = fit.dof - 3 + (1 if model.fit_beta else 0)
        chi2 = fit.chi2 - np.einsum("ni,ni->n", r, np.linalg.solve(i_q, r[..., None])[..., 0])
        scale2 = chi2 / dof if dof > 0 else np.full(n, np.nan)
    e = e_w if table.cov_s is None else np.einsum("nij,nj->ni", np.linalg.cholesky(table.cov_s), e_w)
    d2 = np.where(ok, np.einsum("ni,ni->n", e_w, e_w) / scale2, np.nan)
    press = np.where(ok, np.linalg.norm(e, axis=1), np.nan)
    return d2, press


def leave_one_out_refit(table: StopTable, fit: full.Fit) -> tuple[FloatArray, FloatArray]:
    """:func:`leave_one_out` by refitting the model without each stop in turn (O(n²): a reference)."""
    n = len(table)
    d2, press = np.zeros(n), np.zeros(n)
    for i in range(n):
        keep = np.ones(n, dtype=bool)
        keep[i] = False
        sub = table.subset(keep)
        start = fit.state if fit.state.beta_rad.size == 0 else _drop_beta(fit.state, i)
        try:
            f = full.fit(sub, fit.terms, fit.state.g_mps2, start)
        except (FitFailed, NotEnoughInformation):  # a fit that cannot run without this stop cannot judge it either
            d2[i], press[i] = np.nan, np.nan
            continue
        state = f.state if fit.state.beta_rad.size == 0 else _put_beta(f.state, i, fit.state.beta_rad[i])
        for effect in registry.chain(fit.terms):  # values relative to the stops fitted (a mean temperature)
            state = state.with_values(**effect.transfer(state.values, sub, table))
        pred = full.StaticModel(table, fit.terms, fit.state.g_mps2).predict(state)[i]
        e = table.acc_s[i] - pred
        cov = (table.cov_s[i] if table.cov_s is not None else np.eye(3)) * (
            f.noise_scale**2 if not f.noise_known else 1.0
        )
        d2[i] = float(e @ np.linalg.solve(cov, e))
        press[i] = float(np.linalg.norm(e))
    return d2, press


def _drop_beta(state: full.State, i: int) -> full.State:
    from dataclasses import replace

    return replace(state, beta_rad=np.delete(state.beta_rad, i))


def _put_beta(state: full.State, i: int, value: float) -> full.State:
    from dataclasses import replace

    return replace(state, beta_rad=np.insert(state.beta_rad, i, value))


def _chi2(fit: full.Fit) -> Finding:
    if not fit.noise_known or fit.dof <= 0:
        why = (
            "no test: the stop noise is unknown (no sx/sy/sz and n columns), so it was estimated from these residuals"
            if not fit.noise_known
            else "no test: no degrees of freedom are left"
        )
        return Finding("chi2", "scatter beyond the stops' own noise", why, None, fit.dof, None, None, why)
    logp = float(chi2_logsf(fit.chi2, fit.dof))
    return Finding(
        "chi2",
        "scatter beyond the stops' own noise",
        f"χ²/dof = {fit.chi2 / fit.dof:.2f} ({fit.chi2:.1f} on {fit.dof})",
        fit.chi2,
        fit.dof,
        float(np.exp(logp)),
        logp / np.log(10),
    )
