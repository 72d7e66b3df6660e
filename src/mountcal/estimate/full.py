"""Maximum-likelihood fit of the static model on SO(3) (MODEL.md §2, §4, §5).

Model: ``a_s,i = R_vsᵀ f_v(α, β_i; g) + b + n_i`` with n_i ~ N(0, Σ_i). The rotation is updated
by a left perturbation in the vehicle frame, ``R ← exp([δ]×) R``, so δ = (δx, δy, δz) are small
rotations about the vehicle's x, y and z axes; δz is a pure change of yaw, which lets us fix yaw
exactly when the headings cannot determine it. scipy's least-squares solvers have no notion of a
manifold retraction, so the Levenberg–Marquardt loop is written here (a few lines, exact
Jacobians, re-linearised at every step).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.conventions import FloatArray, skew, specific_force_v
from mountcal.errors import FitFailed
from mountcal.estimate.geometry import in_plane_azimuth, level_rotation, phase_yaw, plane_normal, with_yaw
from mountcal.stoptable import StopTable

TERMS = ("rotation", "slope", "bias")


@dataclass(frozen=True)
class State:
    """A point of the parameter space."""

    rot_vs: Rotation
    slope_rad: float
    bias_s: FloatArray  # shape (3,), m/s², sensor frame
    beta_rad: FloatArray  # shape (n,), fitted only when the headings are unknown


@dataclass(frozen=True)
class Fit:
    """The outcome of one maximum-likelihood fit.

    ``cov`` is the covariance of the parameter vector named by ``names`` (δ in radians about the
    vehicle axes, α in radians, b in m/s², β in radians), already scaled by ``noise_scale²`` when
    the stop noise had to be estimated from the residuals.
    """

    state: State
    terms: tuple[str, ...]
    names: tuple[str, ...]
    cov: FloatArray
    fisher: FloatArray  # unscaled information matrix Jᵀ Σ⁻¹ J
    chi2: float  # Σ rᵢᵀ Σᵢ⁻¹ rᵢ with the stop covariances as given (or unit ones)
    dof: int
    noise_known: bool
    noise_scale: float  # 1 when Σ_i are known; σ̂ (m/s²) when estimated
    residual_s: FloatArray  # shape (n, 3), m/s²
    iterations: int


class StaticModel:
    """Residuals and Jacobians of the static model for one stop table and a set of terms."""

    def __init__(self, table: StopTable, terms: tuple[str, ...], g_mps2: float) -> None:
        self.table, self.terms, self.g = table, terms, g_mps2
        self.fit_yaw = table.headings != "none"
        self.fit_beta = table.headings == "none"
        n = len(table)
        if table.cov_s is not None:
            chol = np.linalg.cholesky(table.cov_s)
            self.whiten = np.linalg.inv(chol)  # e' = C⁻¹ e has unit covariance
        else:
            self.whiten = np.broadcast_to(np.eye(3), (n, 3, 3))
        names = ["rot_x", "rot_y"] + (["rot_z"] if self.fit_yaw else []) + ["slope"]
        if "bias" in terms:
            names += ["bias_x", "bias_y", "bias_z"]
        if self.fit_beta:
            names += [f"beta_{i}" for i in range(n)]
        self.names = tuple(names)

    def beta(self, state: State) -> FloatArray:
        return state.beta_rad if self.fit_beta else self.table.beta_rad  # type: ignore[return-value]

    def predict(self, state: State) -> FloatArray:
        f_v = specific_force_v(state.slope_rad, self.beta(state), self.g)
        return state.rot_vs.inv().apply(f_v) + state.bias_s

    def residual(self, state: State) -> FloatArray:
        """Whitened residual, shape (3n,)."""
        e = self.table.acc_s - self.predict(state)
        return np.einsum("nij,nj->ni", self.whiten, e).ravel()

    def jacobian(self, state: State) -> FloatArray:
        """Jacobian of the whitened residual, shape (3n, p), at δ = 0."""
        n = len(self.table)
        beta, a = self.beta(state), state.slope_rad
        f_v = specific_force_v(a, beta, self.g)
        rt = state.rot_vs.inv().as_matrix()
        cols = [rt @ skew(f_v)]  # ∂(Rᵀ f)/∂δ = Rᵀ [f]×, shape (n, 3, 3)
        if not self.fit_yaw:
            cols[0] = cols[0][:, :, :2]
        df_da = self.g * np.column_stack([np.cos(a) * np.cos(beta), -np.cos(a) * np.sin(beta), -np.full(n, np.sin(a))])
        cols.append((df_da @ rt.T)[:, :, None])
        if "bias" in self.terms:
            cols.append(np.broadcast_to(np.eye(3), (n, 3, 3)))
        blocks = np.concatenate(cols, axis=2)  # (n, 3, p_global)
        jac = -np.einsum("nij,njk->nik", self.whiten, blocks).reshape(3 * n, -1)
        if self.fit_beta:
            df_db = self.g * np.sin(a) * np.column_stack([-np.sin(beta), -np.cos(beta), np.zeros(n)])
            local = -np.einsum("nij,nj->ni", self.whiten, df_db @ rt.T)  # (n, 3)
            jb = np.zeros((3 * n, n))
            jb[np.arange(3 * n), np.repeat(np.arange(n), 3)] = local.ravel()
            jac = np.hstack([jac, jb])
        return jac

    def retract(self, state: State, step: np.ndarray) -> State:
        k = 3 if self.fit_yaw else 2
        delta = np.zeros(3)
        delta[:k] = step[:k]
        i = k
        rot = Rotation.from_rotvec(delta) * state.rot_vs
        slope = state.slope_rad + step[i]
        i += 1
        bias = state.bias_s
        if "bias" in self.terms:
            bias = bias + step[i : i + 3]
            i += 3
        beta = state.beta_rad + step[i:] if self.fit_beta else state.beta_rad
        return State(rot, float(slope), bias, beta)


def initial_state(table: StopTable, g_mps2: float) -> State:
    """Closed-form start: plane normal, in-plane phase, slope from the circle's radius."""
    acc = table.acc_s
    normal = plane_normal(acc)
    rot_level = level_rotation(normal)
    if table.beta_rad is not None and table.headings != "none":
        rot = with_yaw(rot_level, phase_yaw(acc, table.beta_rad, rot_level))
        beta = np.zeros(0)
    else:
        rot = rot_level
        beta = -in_plane_azimuth(acc, rot_level)
    up = acc @ normal
    radius = np.linalg.norm(acc - np.outer(up, normal), axis=1).mean()
    slope = max(float(np.arctan2(radius, up.mean())), 1e-3)  # sin α = 0 would hide yaw and β
    return State(rot, slope, np.zeros(3), beta)


def fit(
    table: StopTable, terms: tuple[str, ...], g_mps2: float, start: State | None = None, max_iter: int = 500
) -> Fit:
    """Maximum-likelihood estimate of the given terms (``rotation`` and ``slope`` always)."""
    model = StaticModel(table, terms, g_mps2)
    state = start if start is not None else initial_state(table, g_mps2)
    if "bias" not in terms:
        state = replace(state, bias_s=np.zeros(3))
    state, iterations = _levenberg_marquardt(model, state, max_iter)
    if table.headings == "none" and state.slope_rad < 0:  # α < 0 is α > 0 with every β turned by π
        state = replace(state, slope_rad=-state.slope_rad, beta_rad=state.beta_rad + np.pi)
    if table.headings == "relative" and state.slope_rad < 0:  # ... or with the unknown offset turned by π
        state = replace(state, slope_rad=-state.slope_rad, rot_vs=Rotation.from_euler("z", np.pi) * state.rot_vs)
    r = model.residual(state)
    jac = model.jacobian(state)
    fisher = jac.T @ jac
    chi2 = float(r @ r)
    dof = r.size - len(model.names)
    noise_known = table.cov_s is not None
    scale2 = 1.0 if noise_known else (chi2 / dof if dof > 0 else np.nan)
    cov = _inverse(fisher) * scale2
    return Fit(
        state=state,
        terms=terms,
        names=model.names,
        cov=cov,
        fisher=fisher,
        chi2=chi2,
        dof=dof,
        noise_known=noise_known,
        noise_scale=float(np.sqrt(scale2)),
        residual_s=table.acc_s - model.predict(state),
        iterations=iterations,
    )


def information(
    table: StopTable, state: State, terms: tuple[str, ...], g_mps2: float
) -> tuple[FloatArray, tuple[str, ...]]:
    """Fisher information ``Jᵀ Σ⁻¹ J`` of the given terms at ``state`` (unit noise if Σ unknown)."""
    model = StaticModel(table, terms, g_mps2)
    if table.headings == "none" and state.beta_rad.size != len(table):
        raise ValueError("state must carry fitted headings when the table has none")
    jac = model.jacobian(state)
    return jac.T @ jac, model.names


def _levenberg_marquardt(model: StaticModel, state: State, max_iter: int) -> tuple[State, int]:
    """Levenberg–Marquardt with Marquardt scaling and Nielsen's damping update."""
    r = model.residual(state)
    cost = float(r @ r)
    lam, nu = 1e-3, 2.0
    for it in range(1, max_iter + 1):
        jac = model.jacobian(state)
        a = jac.T @ jac
        grad = jac.T @ r
        diag = np.clip(np.diag(a), 1e-300, None)
        # Converged when the residual is orthogonal to every Jacobian column (a scale-free test).
        if np.max(np.abs(grad) / np.sqrt(diag * max(cost, 1e-300))) < 1e-9:
            return state, it
        try:
            step = np.linalg.solve(a + lam * np.diag(diag), -grad)
        except np.linalg.LinAlgError as err:
            raise FitFailed(f"the normal equations are singular at iteration {it}") from err
        trial = model.retract(state, step)
        r_trial = model.residual(trial)
        cost_trial = float(r_trial @ r_trial)
        if not np.isfinite(cost_trial):
            raise FitFailed(f"the fit produced a non-finite residual at iteration {it}")
        predicted = float(-step @ grad - 0.5 * step @ a @ step)
        if cost_trial <= cost:
            gain = (cost - cost_trial) / max(2 * predicted, 1e-300)
            small = cost - cost_trial <= 1e-13 * max(cost, 1e-300) or np.max(np.abs(step)) < 1e-13
            state, r, cost = trial, r_trial, cost_trial
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
            nu = 2.0
            if small:
                return state, it
        else:
            lam *= nu
            nu *= 2.0
            if lam > 1e16:
                return state, it  # no descent direction left: at a minimum to machine precision
    raise FitFailed(f"no convergence in {max_iter} iterations (cost {cost:.6g})")


def _inverse(fisher: FloatArray) -> FloatArray:
    """Inverse of the information matrix; the pseudo-inverse where it is singular."""
    scale = np.sqrt(np.clip(np.diag(fisher), 1e-300, None))
    normed = fisher / np.outer(scale, scale)
    return np.linalg.pinv(normed, rcond=1e-12, hermitian=True) / np.outer(scale, scale)
