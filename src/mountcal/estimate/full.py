"""Maximum-likelihood fit of the static model on SO(3) (docs/conventions.md §2, §4–6).

Model, with the optional effects of docs/conventions.md §6 (each a *term*)::

    a_s,i = (I + E) · R_vsᵀ · f_v(α_site(i), β_i; g) + b + k · (T_i − T̄) + n_i,   n_i ~ N(0, Σ_i)

terms: ``rotation`` and ``slope`` (always), ``site_slope`` (one α per site), ``bias`` (b),
``temperature`` (k, bias drift per °C), ``gravity`` (g fitted), ``scale`` (E, symmetric: three
scale errors and three cross-axis couplings; its antisymmetric part is a rotation).

The rotation is updated by a left perturbation in the vehicle frame, ``R ← exp([δ]×) R``, so
δ = (δx, δy, δz) are small rotations about the vehicle's x, y and z axes; δz is a pure change of
yaw, which lets us fix yaw exactly when the headings cannot determine it. scipy's least-squares
solvers have no manifold retraction, so the Levenberg–Marquardt loop is written here (a few lines,
exact Jacobians, re-linearised at every step).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.conventions import FloatArray, skew
from mountcal.errors import FitFailed, NotEnoughInformation
from mountcal.estimate.geometry import in_plane_azimuth, level_rotation, phase_yaw, plane_normal, with_yaw
from mountcal.stoptable import StopTable

# "surface" (a random road tilt per stop) lives in the stop covariances, not in the mean model.
TERMS = ("rotation", "slope", "site_slope", "bias", "temperature", "gravity", "scale", "surface")
SCALE_NAMES = ("scale_xx", "scale_yy", "scale_zz", "cross_xy", "cross_xz", "cross_yz")


@dataclass(frozen=True)
class State:
    """A point of the parameter space (units in the names; sensor frame for vectors)."""

    rot_vs: Rotation
    slope_rad: FloatArray  # shape (n_sites,): one α, or one per site
    bias_s: FloatArray  # shape (3,), m/s²
    beta_rad: FloatArray  # shape (n,), fitted only when the headings are unknown
    temp_coeff_s: FloatArray  # shape (3,), m/s² per °C
    g_mps2: float
    scale_e: FloatArray  # shape (6,): E_xx, E_yy, E_zz, E_xy, E_xz, E_yz

    @property
    def scale_matrix(self) -> FloatArray:
        """I + E, shape (3, 3)."""
        e = self.scale_e
        return np.eye(3) + np.array([[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]])


@dataclass(frozen=True)
class Fit:
    """The outcome of one maximum-likelihood fit.

    ``cov`` is the covariance of the parameter vector named by ``names`` (δ in radians about the
    vehicle axes, α in radians, b in m/s², k in m/s²/°C, g in m/s², E unitless, β in radians),
    scaled by ``noise_scale²`` when the stop noise had to be estimated from the residuals.
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
    branch: str | None = None  # why the physical branch is in doubt (None: it fits best, or is exactly equivalent)

    def value(self, name: str) -> float:
        """A fitted scalar by parameter name (as in ``names``)."""
        return float(_flat(self.state, self.names)[self.names.index(name)])

    def sigma(self, name: str) -> float:
        i = self.names.index(name)
        return float(np.sqrt(max(self.cov[i, i], 0.0)))


class StaticModel:
    """Residuals and Jacobians of the static model for one stop table and a set of terms."""

    def __init__(self, table: StopTable, terms: tuple[str, ...], g_mps2: float) -> None:
        unknown = set(terms) - set(TERMS)
        if unknown:
            raise ValueError(f"unknown terms {sorted(unknown)}")
        self.table, self.terms, self.g = table, terms, g_mps2
        n = len(table)
        self.fit_yaw = table.headings != "none"
        self.fit_beta = table.headings == "none"
        self.site_index, self.sites = site_index(table) if "site_slope" in terms else (np.zeros(n, int), ["all"])
        t = table.temperature_c
        self.dtemp = (t - t.mean()) if ("temperature" in terms and t is not None) else np.zeros(n)
        if table.cov_s is not None:
            self.whiten = np.linalg.inv(np.linalg.cholesky(table.cov_s))  # e' = C⁻¹ e has unit covariance
        else:
            self.whiten = np.broadcast_to(np.eye(3), (n, 3, 3))
        names = ["rot_x", "rot_y"] + (["rot_z"] if self.fit_yaw else [])
        names += ["slope"] if len(self.sites) == 1 else [f"slope_{s}" for s in self.sites]
        if "bias" in terms:
            names += ["bias_x", "bias_y", "bias_z"]
        if "temperature" in terms:
            names += ["temp_x", "temp_y", "temp_z"]
        if "gravity" in terms:
            names += ["gravity"]
        if "scale" in terms:
            names += list(SCALE_NAMES)
        if self.fit_beta:
            names += [f"beta_{i}" for i in range(n)]
        self.names = tuple(names)

    def beta(self, state: State) -> FloatArray:
        return state.beta_rad if self.fit_beta else self.table.beta_rad  # type: ignore[return-value]

    def _parts(self, state: State) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per-stop slope α_i, f_v,i and u_i = Rᵀ f_v,i."""
        alpha = state.slope_rad[self.site_index]
        beta = self.beta(state)
        f_v = _force(alpha, beta, state.g_mps2)
        return alpha, f_v, state.rot_vs.inv().apply(f_v)

    def predict(self, state: State) -> FloatArray:
        _, _, u = self._parts(state)
        return u @ state.scale_matrix.T + state.bias_s + np.outer(self.dtemp, state.temp_coeff_s)

    def residual(self, state: State) -> FloatArray:
        """Whitened residual, shape (3n,)."""
        e = self.table.acc_s - self.predict(state)
        return np.einsum("nij,nj->ni", self.whiten, e).ravel()

    def jacobian(self, state: State) -> FloatArray:
        """Jacobian of the whitened residual, shape (3n, p), at δ = 0."""
        n = len(self.table)
        alpha, f_v, u = self._parts(state)
        beta, g = self.beta(state), state.g_mps2
        pm = state.scale_matrix
        prt = pm @ state.rot_vs.inv().as_matrix()  # (I + E) Rᵀ
        blocks = [prt @ skew(f_v)]  # ∂(Rᵀ f)/∂δ = Rᵀ [f]×
        if not self.fit_yaw:
            blocks[0] = blocks[0][:, :, :2]
        df_da = g * np.column_stack([np.cos(alpha) * np.cos(beta), -np.cos(alpha) * np.sin(beta), -np.sin(alpha)])
        da = np.zeros((n, 3, len(self.sites)))
        da[np.arange(n), :, self.site_index] = df_da @ prt.T
        blocks.append(da)
        if "bias" in self.terms:
            blocks.append(np.broadcast_to(np.eye(3), (n, 3, 3)))
        if "temperature" in self.terms:
            blocks.append(self.dtemp[:, None, None] * np.eye(3))
        if "gravity" in self.terms:
            blocks.append(((f_v / g) @ prt.T)[:, :, None])
        if "scale" in self.terms:
            z = np.zeros(n)
            ux, uy, uz = u.T
            cols = [(ux, z, z), (z, uy, z), (z, z, uz), (uy, ux, z), (uz, z, ux), (z, uz, uy)]
            blocks.append(np.stack([np.column_stack(c) for c in cols], axis=2))
        jac = -np.einsum("nij,njk->nik", self.whiten, np.concatenate(blocks, axis=2)).reshape(3 * n, -1)
        if self.fit_beta:
            df_db = g * np.sin(alpha)[:, None] * np.column_stack([-np.sin(beta), -np.cos(beta), np.zeros(n)])
            local = -np.einsum("nij,nj->ni", self.whiten, df_db @ prt.T)
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
        m = len(self.sites)
        slope = state.slope_rad + step[i : i + m]
        i += m
        bias, temp, g, scale = state.bias_s, state.temp_coeff_s, state.g_mps2, state.scale_e
        if "bias" in self.terms:
            bias, i = bias + step[i : i + 3], i + 3
        if "temperature" in self.terms:
            temp, i = temp + step[i : i + 3], i + 3
        if "gravity" in self.terms:
            g, i = g + float(step[i]), i + 1
        if "scale" in self.terms:
            scale, i = scale + step[i : i + 6], i + 6
        beta = state.beta_rad + step[i:] if self.fit_beta else state.beta_rad
        return State(rot, slope, bias, beta, temp, g, scale)


def site_index(table: StopTable) -> tuple[np.ndarray, list[str]]:
    """Index of each stop's site, and the site names (one site when the table has none)."""
    if table.site is None:
        return np.zeros(len(table), dtype=int), ["all"]
    names, idx = np.unique(table.site.astype(str), return_inverse=True)
    return idx, [str(s) for s in names]


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
    return State(rot, np.array([slope]), np.zeros(3), beta, np.zeros(3), g_mps2, np.zeros(6))


def adapt(state: State, table: StopTable, terms: tuple[str, ...], g_mps2: float) -> State:
    """A start for ``terms`` from a fit of other terms: unused effects zeroed, slopes per site."""
    n_sites = len(site_index(table)[1]) if "site_slope" in terms else 1
    slope = state.slope_rad
    if slope.size != n_sites:
        slope = np.full(n_sites, float(np.mean(slope)))
    return replace(
        state,
        slope_rad=slope,
        bias_s=state.bias_s if "bias" in terms else np.zeros(3),
        temp_coeff_s=state.temp_coeff_s if "temperature" in terms else np.zeros(3),
        g_mps2=state.g_mps2 if "gravity" in terms else g_mps2,
        scale_e=state.scale_e if "scale" in terms else np.zeros(6),
    )


def fit(
    table: StopTable, terms: tuple[str, ...], g_mps2: float, start: State | None = None, max_iter: int = 500
) -> Fit:
    """Maximum-likelihood estimate of the given terms (``rotation`` and ``slope`` always)."""
    model = StaticModel(table, terms, g_mps2)
    if table.cov_s is None and 3 * len(table) <= len(model.names):
        raise NotEnoughInformation(
            f"{table.source}: {len(table)} stops give {3 * len(table)} values and the model {', '.join(terms)} has "
            f"{len(model.names)} parameters, so none are left to estimate the stop noise from. Add stops, fit fewer "
            "terms, or give each stop's noise (the sx, sy, sz, n columns)."
        )
    state = adapt(start if start is not None else initial_state(table, g_mps2), table, terms, g_mps2)
    state, iterations = _levenberg_marquardt(model, state, max_iter)
    state = _canonical(state, table)
    branch = None
    if _unphysical(state):
        state, branch = _physical_branch(model, state, max_iter)
    r = model.residual(state)
    jac = model.jacobian(state)
    fisher = jac.T @ jac
    chi2 = float(r @ r)
    dof = r.size - len(model.names)
    noise_known = table.cov_s is not None
    scale2 = 1.0 if noise_known else (chi2 / dof if dof > 0 else np.nan)
    return Fit(
        state=state,
        terms=terms,
        names=model.names,
        cov=inverse_information(fisher) * scale2,
        fisher=fisher,
        chi2=chi2,
        dof=dof,
        noise_known=noise_known,
        noise_scale=float(np.sqrt(scale2)),
        residual_s=table.acc_s - model.predict(state),
        iterations=iterations,
        branch=branch,
    )


def information(
    table: StopTable, state: State, terms: tuple[str, ...], g_mps2: float
) -> tuple[FloatArray, tuple[str, ...]]:
    """Fisher information ``Jᵀ Σ⁻¹ J`` of the given terms at ``state`` (unit noise if Σ unknown)."""
    model = StaticModel(table, terms, g_mps2)
    if table.headings == "none" and state.beta_rad.size != len(table):
        raise ValueError("state must carry fitted headings when the table has none")
    jac = model.jacobian(adapt(state, table, terms, g_mps2))
    return jac.T @ jac, model.names


def _canonical(state: State, table: StopTable) -> State:
    """α ≥ 0: a negative slope is the same plane seen from the other side.

    Without headings, α > 90° (the vehicle's up axis pointing down) is exactly the mirror of
    π − α with the vehicle turned about its x axis and every β negated: ``Rx(π) f_v(π − α, −β) =
    f_v(α, β)``, so both predict the same stops and physics (α < 90°, +g up) picks the latter.
    """
    state = replace(state, slope_rad=np.angle(np.exp(1j * state.slope_rad)))  # α in (−π, π]
    state = _nonnegative(state, table)
    if table.headings == "none" and np.all(np.cos(state.slope_rad) < 0):
        return replace(
            state,
            rot_vs=_TURN_X * state.rot_vs,
            slope_rad=np.pi - state.slope_rad,
            beta_rad=-state.beta_rad,
        )
    return state


_TURN_X = Rotation.from_euler("x", np.pi)
BRANCH_DCHI2 = 9.0  # a likelihood ratio of ~100:1 between the two branches


def _unphysical(state: State) -> bool:
    """A slope outside [0°, 90°): the vehicle's up axis pointing down (docs/conventions.md §1: +g up), or, with
    headings from uphill, a negative slope (the headings would be measured from downhill)."""
    return bool(np.any(np.cos(state.slope_rad) <= 0) or np.any(state.slope_rad < 0))


def _physical_branch(model: StaticModel, state: State, max_iter: int) -> tuple[State, str | None]:
    """The best fit with α in [0°, 90°), from the mirrors of an unphysical optimum, and a note if in doubt.

    With headings the mirror is not an exact symmetry (it would negate every β), so the data
    may tell the two apart; when the physical branch fits clearly worse, the stops contradict
    the model's +g up (a negated axis, a wrong heading direction) and that is reported.
    """
    cost_wrong = float(np.sum(model.residual(state) ** 2))
    physical_slope = np.maximum(np.arccos(np.abs(np.cos(state.slope_rad))), 1e-3)
    best: tuple[float, State] | None = None
    for axis in "xyz":  # the optimum turned half a turn about each vehicle axis, with the slope made physical
        start = replace(state, rot_vs=Rotation.from_euler(axis, np.pi) * state.rot_vs, slope_rad=physical_slope)
        try:
            found, _ = _levenberg_marquardt(model, start, max_iter)
        except FitFailed:
            continue
        found = _canonical(found, model.table)
        cost_found = float(np.sum(model.residual(found) ** 2))
        if not _unphysical(found) and (best is None or cost_found < best[0]):
            best = (cost_found, found)
    mirror = best[1] if best is not None else replace(state, slope_rad=np.clip(physical_slope, 0.0, np.radians(89.9)))
    cost = float(np.sum(model.residual(mirror) ** 2))
    dof = max(model.residual(mirror).size - len(model.names), 1)
    s2 = 1.0 if model.table.cov_s is not None else max(cost_wrong / dof, 1e-300)
    dchi2 = (cost - cost_wrong) / s2
    if dchi2 <= BRANCH_DCHI2:
        return mirror, None
    slope = float(np.degrees(np.mean(state.slope_rad)))
    return mirror, (
        f"the stops fit an unphysical solution (slope {slope:.1f}°: up axis down, or headings from downhill) better "
        f"than any physical one (Δχ² = {dchi2:.1f}): the sensor may not read +g up (a negated or swapped axis), or the "
        "headings run clockwise; the physical branch is reported but is not trustworthy"
    )


def _nonnegative(state: State, table: StopTable) -> State:
    """α ≥ 0: a negative slope is the same plane seen from the other side."""
    if state.slope_rad.size == 1 and state.slope_rad[0] < 0:
        if table.headings == "none":  # ... with every β turned by π
            return replace(state, slope_rad=-state.slope_rad, beta_rad=state.beta_rad + np.pi)
        if table.headings == "relative":  # ... or with the unknown heading offset turned by π
            return replace(state, slope_rad=-state.slope_rad, rot_vs=Rotation.from_euler("z", np.pi) * state.rot_vs)
    return state


def _force(alpha: FloatArray, beta: FloatArray, g: float) -> FloatArray:
    """f_v for per-stop slopes α_i, shape (n, 3) (docs/conventions.md §2)."""
    sa, ca = np.sin(alpha), np.cos(alpha)
    return g * np.column_stack([sa * np.cos(beta), -sa * np.sin(beta), ca])


def _flat(state: State, names: tuple[str, ...]) -> FloatArray:
    """Parameter values in the order of ``names`` (δ as zero: the state is the reference)."""
    out = []
    slopes = iter(state.slope_rad)
    for name in names:
        if name.startswith("rot_"):
            out.append(0.0)
        elif name.startswith("slope"):
            out.append(float(next(slopes)))
        elif name.startswith("bias_"):
            out.append(float(state.bias_s["xyz".index(name[-1])]))
        elif name.startswith("temp_"):
            out.append(float(state.temp_coeff_s["xyz".index(name[-1])]))
        elif name == "gravity":
            out.append(state.g_mps2)
        elif name in SCALE_NAMES:
            out.append(float(state.scale_e[SCALE_NAMES.index(name)]))
        else:  # beta_i
            out.append(float(state.beta_rad[int(name.split("_")[1])]))
    return np.array(out)


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


def inverse_information(fisher: FloatArray) -> FloatArray:
    """Inverse of the information matrix; the pseudo-inverse where it is singular."""
    scale = np.sqrt(np.clip(np.diag(fisher), 1e-300, None))
    normed = fisher / np.outer(scale, scale)
    return np.linalg.pinv(normed, rcond=1e-12, hermitian=True) / np.outer(scale, scale)
