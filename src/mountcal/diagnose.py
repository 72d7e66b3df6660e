"""Residual analysis after a fit: does the model explain the stops, and if not, how not?

Every test compares the whitened residuals with a structure they would show if an effect were
missing — harmonics against heading, trends against time, temperature and stop order, offsets
per site, the norm against g, single stops that the others do not predict — and returns its size
and its p-value. docs/conventions.md §6 lists the effects these point at.
"""

from __future__ import annotations

import numpy as np

from mountcal.conventions import FloatArray
from mountcal.estimate import full
from mountcal.pvalues import chi2_logsf, f_logsf
from mountcal.result import Finding
from mountcal.stoptable import StopTable


def whitened(table: StopTable, fit: full.Fit) -> FloatArray:
    """Per-stop residuals in units of their σ, shape (n, 3) (noise scale applied when estimated)."""
    model = full.StaticModel(table, fit.terms, fit.state.g_mps2)
    return model.residual(fit.state).reshape(-1, 3) / fit.noise_scale


def vehicle_residual(fit: full.Fit) -> FloatArray:
    """Per-stop residuals rotated into the vehicle frame, m/s², shape (n, 3)."""
    return fit.state.rot_vs.apply(fit.residual_s)


def analyse(table: StopTable, fit: full.Fit) -> list[Finding]:
    """All residual tests that the table's columns allow."""
    w = whitened(table, fit)
    n = len(table)
    findings = [_chi2(fit)]
    beta = table.beta_rad if table.beta_rad is not None and table.headings != "none" else fit.state.beta_rad
    if beta is not None and beta.size == n:
        for k in (1, 2, 3):
            findings.append(
                _regression(
                    w,
                    np.column_stack([np.cos(k * beta), np.sin(k * beta)]),
                    f"harmonic_{k}beta",
                    f"residual varying as {k}β with heading",
                    fit,
                    table,
                )
            )
    for name, x in (("time", table.t_s), ("temperature", table.temperature_c), ("order", np.arange(n, dtype=float))):
        if x is not None and np.ptp(x) > 0:
            findings.append(
                _regression(
                    w,
                    (x - x.mean())[:, None],
                    f"trend_{name}",
                    f"residual trend against {name.replace('order', 'stop order')}",
                    fit,
                    table,
                )
            )
    if table.site is not None and np.unique(table.site).size > 1:
        sites = np.unique(table.site)
        x = (table.site[:, None] == sites[None, 1:]).astype(float)
        findings.append(_regression(w, x - x.mean(axis=0), "site_offsets", "residual offset per site", fit, table))
    findings.append(_norm(table, fit))
    return findings


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
        except Exception:  # a fit that cannot run without this stop cannot judge it either
            d2[i], press[i] = np.nan, np.nan
            continue
        state = f.state if fit.state.beta_rad.size == 0 else _put_beta(f.state, i, fit.state.beta_rad[i])
        if "temperature" in fit.terms and table.temperature_c is not None:
            # The refit's bias holds at the others' mean temperature; the prediction uses all stops' mean.
            shift = float(np.mean(table.temperature_c) - np.mean(sub.temperature_c))  # type: ignore[arg-type]
            state = state.with_values(bias=state.bias_s + state.temp_coeff_s * shift)
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


def _regression(w: FloatArray, x: FloatArray, test: str, what: str, fit: full.Fit, table: StopTable) -> Finding:
    """Δχ² of regressing each whitened residual axis on the columns of x (3·k dof)."""
    xx = np.column_stack([x])
    coef, *_ = np.linalg.lstsq(xx, w, rcond=None)
    explained = float(np.sum((xx @ coef) ** 2))
    dof = coef.size
    if fit.noise_known:
        logp = float(chi2_logsf(explained, dof))
    else:
        rest = max(float(np.sum(w**2)) - explained, 1e-300)
        resid_dof = max(fit.dof - dof, 1)
        f_stat = (explained / dof) / (rest / resid_dof)
        logp = float(f_logsf(f_stat, dof, resid_dof))
    # Size in physical units: the fitted structure's RMS amplitude in the vehicle frame.
    sigma = (
        np.sqrt(np.mean(np.diagonal(table.cov_s, axis1=1, axis2=2), axis=1))
        if table.cov_s is not None
        else (np.full(len(table), fit.noise_scale))
    )
    amp = float(np.sqrt(np.mean(((xx @ coef) * sigma[:, None]) ** 2)) * np.sqrt(3))
    return Finding(
        test, what, f"{amp * 1e3 / 9.80665:.3g} mg RMS", explained, dof, float(np.exp(logp)), logp / np.log(10)
    )


def _norm(table: StopTable, fit: full.Fit) -> Finding:
    """|a| against the model's g: a common offset points at gravity, scale or a vertical bias."""
    mag = np.linalg.norm(table.acc_s, axis=1)
    pred = np.linalg.norm(fit.residual_s * 0 + (table.acc_s - fit.residual_s), axis=1)
    d = mag - pred
    var = (
        np.einsum("ni,nij,nj->n", table.acc_s / mag[:, None], table.cov_s, table.acc_s / mag[:, None])
        if table.cov_s is not None
        else np.full(len(table), fit.noise_scale**2)
    )
    stat = float(np.sum(d) ** 2 / np.sum(var))
    logp = float(chi2_logsf(stat, 1))
    return Finding(
        "norm",
        "common offset of |a| from the model's g",
        f"{np.mean(d) * 1e3 / 9.80665:+.3g} mg",
        stat,
        1,
        float(np.exp(logp)),
        logp / np.log(10),
    )
