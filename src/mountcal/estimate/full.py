"""Maximum-likelihood fit of the static model on SO(3) (docs/conventions.md §2, §4–6).

Model, with the optional effects of docs/conventions.md §6 (each a *term*)::

    a_s,i = effectₖ(… effect₁(R_vsᵀ · f_v(α_site(i), β_i; g)) …) + n_i,   n_i ~ N(0, Σ_i)

terms: ``rotation`` and ``slope`` (always), then the registered effects
(:mod:`mountcal.estimate.effects`: ``bias``, ``temperature``, ``gravity``, ``site_slope``, ``scale``
and any a package adds), applied in their ``order``; the model iterates over them and knows none by
name: an effect with ``slope_per_site`` (``site_slope``) gives each site its own α, one with a
``gravity_index`` sets the gravity in force.

The rotation is updated by a left perturbation in the vehicle frame, ``R ← exp([δ]×) R``, so
δ = (δx, δy, δz) are small rotations about the vehicle's x, y and z axes; δz is a pure change of
yaw, which lets us fix yaw exactly when the headings cannot determine it. scipy's least-squares
solvers have no manifold retraction, so the Levenberg–Marquardt loop is written here (a few lines,
exact Jacobians, re-linearised at every step).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import FloatArray, skew
from mountcal.core.errors import FitFailed, NotEnoughInformation
from mountcal.estimate import effects as registry
from mountcal.estimate.effects import bias, scale, temperature
from mountcal.estimate.geometry import in_plane_azimuth, level_rotation, phase_yaw, plane_normal, with_yaw
from mountcal.stops.table import StopTable

BASE = registry.BASE
NULL_TOL = 1e-10  # relative eigenvalue of the normalised Fisher information counted as zero


def known_terms() -> tuple[str, ...]:
    """Every term a model may name. "surface" (a random road tilt per stop) and "heading_scatter" (an error of each
    stop's own heading) live in the stop covariances."""
    return (*BASE, *registry.registered(), "surface", "heading_scatter")


@dataclass(frozen=True)
class State:
    """A point of the parameter space (units in the names; sensor frame for vectors).

    ``values`` holds each effect's parameters by effect name (absent: the effect is not in the model).
    """

    rot_vs: Rotation
    slope_rad: FloatArray  # shape (n_sites,): one α, or one per site
    beta_rad: FloatArray  # shape (n,), fitted only when the headings are unknown
    g0_mps2: float  # the gravity of the base force
    values: Mapping[str, FloatArray] = field(default_factory=dict)

    def effect(self, name: str, size: int) -> FloatArray:
        return self.values[name] if name in self.values else np.zeros(size)

    @property
    def g_mps2(self) -> float:
        """Gravity in force: fitted when the model has an effect that fits it, else the base one."""
        for effect in registry.chain(tuple(self.values)):
            if effect.gravity_index is not None:
                return float(self.values[effect.name][effect.gravity_index])
        return self.g0_mps2

    # Accessors of three built-in effects for callers that know them (tests, benchmarks); the model and the
    # rest of mountcal use ``values`` through the registry.
    @property
    def bias_s(self) -> FloatArray:
        return self.effect(bias.EFFECT.name, 3)

    @property
    def temp_coeff_s(self) -> FloatArray:
        return self.effect(temperature.EFFECT.name, 3)

    @property
    def scale_e(self) -> FloatArray:
        return self.effect(scale.EFFECT.name, 6)

    @property
    def scale_matrix(self) -> FloatArray:
        """I + E, shape (3, 3)."""
        return scale.scale_matrix(self.scale_e)

    def with_values(self, **values: FloatArray) -> State:
        return replace(self, values={**self.values, **values})


@dataclass(frozen=True)
class Fit:
    """The outcome of one maximum-likelihood fit.

    ``cov`` is the covariance of the parameter vector named by ``names`` (δ in radians about the
    vehicle axes, α in radians, then each effect's parameters, β in radians), scaled by
    ``noise_scale²`` when the stop noise had to be estimated from the residuals. ``jacobian`` is
    that of the whitened residual at the optimum; ``fisher`` = JᵀJ.
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
    jacobian: FloatArray | None = None  # shape (3n, p), of the whitened residual
    owned: Mapping[str, tuple[int, ...]] = field(default_factory=dict)  # each effect's parameters (indexes)

    def value(self, name: str) -> float:
        """A fitted scalar by parameter name (as in ``names``)."""
        return float(parameter_values(self.state, self.names)[self.names.index(name)])

    def sigma(self, name: str) -> float:
        i = self.names.index(name)
        return float(np.sqrt(max(self.cov[i, i], 0.0)))


class StaticModel:
    """Residuals and Jacobians of the static model for one stop table and a set of terms."""

    def __init__(self, table: StopTable, terms: tuple[str, ...], g_mps2: float) -> None:
        unknown = set(terms) - set(known_terms())
        if unknown:
            raise ValueError(f"unknown terms {sorted(unknown)}")
        self.table, self.terms, self.g = table, terms, g_mps2
        n = len(table)
        self.fit_yaw = table.headings != "none"
        self.fit_beta = table.headings == "none"
        self.chain = registry.chain(terms)
        per_site = any(e.slope_per_site for e in self.chain)
        self.site_index, self.sites = site_index(table) if per_site else (np.zeros(n, int), ["all"])
        if table.cov_s is not None:
            self.whiten = np.linalg.inv(np.linalg.cholesky(table.cov_s))  # e' = C⁻¹ e has unit covariance
        else:
            self.whiten = np.broadcast_to(np.eye(3), (n, 3, 3))
        names = ["rot_x", "rot_y"] + (["rot_z"] if self.fit_yaw else [])
        names += ["slope"] if len(self.sites) == 1 else [f"slope_{s}" for s in self.sites]
        self.params = {e.name: e.parameters(table) for e in self.chain}
        for e in self.chain:
            names += self.params[e.name]
        if self.fit_beta:
            names += [f"beta_{i}" for i in range(n)]
        self.names = tuple(names)
        # the parameters each effect reports: its own, and for the slope per site the per-site slopes
        self.owned = {
            e.name: (
                tuple(i for i, p in enumerate(self.names) if p.startswith("slope_"))
                if e.slope_per_site
                else tuple(self.names.index(p) for p in self.params[e.name])
            )
            for e in self.chain
        }

    def beta(self, state: State) -> FloatArray:
        return state.beta_rad if self.fit_beta else self.table.beta_rad  # type: ignore[return-value]

    def _base(self, state: State) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per-stop slope α_i, f_v,i (with the base gravity) and p_i = Rᵀ f_v,i."""
        alpha = state.slope_rad[self.site_index]
        f_v = _force(alpha, self.beta(state), state.g0_mps2)
        return alpha, f_v, state.rot_vs.inv().apply(f_v)

    def _values(self, state: State) -> list[FloatArray]:
        return [state.values[e.name] if e.name in state.values else e.initial(self.table, self.g) for e in self.chain]

    def predict(self, state: State) -> FloatArray:
        _, _, p = self._base(state)
        for effect, values in zip(self.chain, self._values(state), strict=True):
            p = effect.apply(self.table, values, p, state.g0_mps2)[0]
        return p

    def carry(self, state: State, d_base: FloatArray) -> FloatArray:
        """Changes ``d_base`` (n, 3) of the base force ``p`` as the prediction sees them: through every effect's
        derivative by ``p`` (a scale matrix turns and stretches them)."""
        _, _, p = self._base(state)
        for effect, values in zip(self.chain, self._values(state), strict=True):
            p, _, d_p = effect.apply(self.table, values, p, state.g0_mps2)
            if d_p is not None:
                d_base = d_base @ d_p.T if d_p.ndim == 2 else np.einsum("nij,nj->ni", d_p, d_base)
        return d_base

    def residual(self, state: State) -> FloatArray:
        """Whitened residual, shape (3n,)."""
        e = self.table.acc_s - self.predict(state)
        return np.asarray(np.einsum("nij,nj->ni", self.whiten, e), dtype=np.float64).ravel()

    def jacobian(self, state: State) -> FloatArray:
        """Jacobian of the whitened residual, shape (3n, p), at δ = 0: the base force's columns carried
        through each effect (chain rule), then each effect's own."""
        return self.with_heading_offset(state)[0]

    def with_heading_offset(self, state: State) -> tuple[FloatArray, FloatArray]:
        """:meth:`jacobian`, and the whitened residual's Jacobian against one error common to every stop's
        heading, shape (3n,), in one pass."""
        jac, local = self._jacobians(state)
        if self.fit_beta:  # each fitted heading moves its own stop only
            n = len(self.table)
            jb = np.zeros((3 * n, n))
            jb[np.arange(3 * n), np.repeat(np.arange(n), 3)] = local
            jac = np.hstack([jac, jb])
        return jac, local

    def _jacobians(self, state: State) -> tuple[FloatArray, FloatArray]:
        """The Jacobian without heading columns, and each stop's residual against its own heading, (3n,)."""
        n = len(self.table)
        alpha, f_v, p = self._base(state)
        beta, g = self.beta(state), state.g0_mps2
        rt = state.rot_vs.inv().as_matrix()
        rot = rt @ skew(f_v)  # ∂(Rᵀ f)/∂δ = Rᵀ [f]×
        if not self.fit_yaw:
            rot = rot[:, :, :2]
        df_da = g * np.column_stack([np.cos(alpha) * np.cos(beta), -np.cos(alpha) * np.sin(beta), -np.sin(alpha)])
        da = np.zeros((n, 3, len(self.sites)))
        da[np.arange(n), :, self.site_index] = df_da @ rt.T
        blocks = [np.concatenate([rot, da], axis=2)]
        db = _heading_derivative(alpha, beta, g) @ rt.T
        for effect, values in zip(self.chain, self._values(state), strict=True):
            p, d_values, d_p = effect.apply(self.table, values, p, g)
            if d_p is not None:
                blocks = [d_p @ b for b in blocks]
                db = (d_p @ db[:, :, None])[:, :, 0]
            blocks.append(d_values)
        jac = -(self.whiten @ np.concatenate(blocks, axis=2)).reshape(3 * n, -1)  # matmul: 5× einsum here
        return jac, -np.einsum("nij,nj->ni", self.whiten, db).ravel()

    def heading_tangents(self, state: State) -> FloatArray:
        """Each stop's prediction's change per radian of its own heading, (n, 3), sensor frame: where an error in
        that heading moves the stop (g·sin α long, horizontal in the vehicle frame, through every effect)."""
        alpha, _, _ = self._base(state)
        d_base = _heading_derivative(alpha, self.beta(state), state.g0_mps2) @ state.rot_vs.inv().as_matrix().T
        return self.carry(state, d_base)

    def retract(self, state: State, step: np.ndarray) -> State:
        k = 3 if self.fit_yaw else 2
        delta = np.zeros(3)
        delta[:k] = step[:k]
        i = k
        rot = Rotation.from_rotvec(delta) * state.rot_vs
        m = len(self.sites)
        slope = state.slope_rad + step[i : i + m]
        i += m
        values = dict(state.values)
        for effect, v in zip(self.chain, self._values(state), strict=True):
            size = v.size
            values[effect.name], i = v + step[i : i + size], i + size
        beta = state.beta_rad + step[i:] if self.fit_beta else state.beta_rad
        return State(rot, slope, beta, state.g0_mps2, values)


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
    return State(rot, np.array([slope]), beta, g_mps2)


def adapt(state: State, table: StopTable, terms: tuple[str, ...], g_mps2: float) -> State:
    """A start for ``terms`` from a fit of other terms: effects not in ``terms`` dropped, slopes per site."""
    chain = registry.chain(terms)
    n_sites = len(site_index(table)[1]) if any(e.slope_per_site for e in chain) else 1
    slope = state.slope_rad
    if slope.size != n_sites:
        slope = np.full(n_sites, float(np.mean(slope)))
    values = {e.name: state.values.get(e.name, e.initial(table, g_mps2)) for e in chain}
    return replace(state, slope_rad=slope, g0_mps2=g_mps2, values=values)


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
        jacobian=jac,
        owned=model.owned,
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


def _heading_derivative(alpha: FloatArray, beta: FloatArray, g: float) -> FloatArray:
    """∂f_v/∂β per stop, shape (n, 3)."""
    tangent = np.column_stack([-np.sin(beta), -np.cos(beta), np.zeros(len(beta))])
    return np.asarray(g * np.sin(alpha)[:, None] * tangent, dtype=np.float64)


def parameter_values(state: State, names: tuple[str, ...]) -> FloatArray:
    """Parameter values in the order of ``names`` (δ as zero: the state is the reference)."""
    k = sum(n.startswith("rot_") for n in names)
    effects = [state.values[e.name] for e in registry.chain(tuple(state.values))]
    beta = state.beta_rad if names[-1].startswith("beta_") else np.zeros(0)
    return np.concatenate([np.zeros(k), state.slope_rad, *effects, beta])


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


def null_space(fisher: FloatArray, normalised: bool = False) -> FloatArray:
    """Directions the information matrix does not see (columns; empty when it is full rank).

    Judged on the information normalised to unit diagonal (units drop out); the directions are given
    in those normalised coordinates, or (default) back in parameter coordinates.
    """
    scale = np.sqrt(np.clip(np.diag(fisher), 1e-300, None))
    eig, vec = np.linalg.eigh(fisher / np.outer(scale, scale))
    null = vec[:, eig < NULL_TOL * eig.max()]
    return null if normalised or not null.size else null / scale[:, None]


def fisher_rank(fisher: FloatArray) -> int:
    """The rank of the information matrix, with the same threshold as :func:`null_space`."""
    return int(fisher.shape[0] - null_space(fisher, normalised=True).shape[1])


def inverse_information(fisher: FloatArray) -> FloatArray:
    """Inverse of the information matrix; the pseudo-inverse where it is singular."""
    scale = np.sqrt(np.clip(np.diag(fisher), 1e-300, None))
    normed = fisher / np.outer(scale, scale)
    inverse = np.linalg.pinv(normed, rcond=1e-12, hermitian=True) / np.outer(scale, scale)
    return np.asarray(inverse, dtype=np.float64)
