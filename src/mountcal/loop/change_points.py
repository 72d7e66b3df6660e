"""Change points in stop order: the sensor's bias or its mounting steps once, at a stop nobody noted.

A restart or a knock changes the bias from one stop on; a bracket that slips turns the sensor. On a
circle of stops driven in heading order most of such a step looks like a constant and a 1β pattern,
which the bias and the tilt absorb; what is left is the step's sharp edge, and these tests look for it.

For each candidate split k of the stops in time order (row order without ``t_s``), the directions
"the stops from k on carry an extra bias b" (3) or "are turned by a small δθ" (3) are projected off
the fitted model's span as in :mod:`mountcal.loop.diagnose`: at a fixed k the explained part is exactly
χ²(rank), F with estimated noise. The split is unknown, so the statistic is the smallest p over the
splits. Its null is that of a minimum over correlated tests: simulated under the linearised model up
to ``SIMULATED_STOPS`` stops (``DRAWS`` residual sets, fixed seed), and bounded by Bonferroni (m·p_min)
where the simulation cannot resolve it or above that many stops. The bound is tight in the far tail,
where the splits' exceedances become nearly disjoint events.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from mountcal.core.conventions import G_N, FloatArray
from mountcal.core.findings import Finding
from mountcal.core.pvalues import chi2_logsf, f_logsf

MAX_SPLITS = 48  # candidate splits, evenly spaced in stop order above this many
MIN_SIDE = 2  # stops on each side of a split: one stop alone is the single-stop test's
SIMULATED_STOPS = 60
DRAWS = 1000

KINDS = (
    ("bias_step", "a bias step from one stop on (a restart, a knock)"),
    ("attitude_step", "the sensor turned from one stop on (a bracket that slipped, a remount)"),
)


def change_points(
    r: FloatArray,
    whiten: FloatArray,
    unwhiten: FloatArray,
    u: FloatArray,
    basis: FloatArray,
    order: np.ndarray,
    noise_known: bool,
    dof: int,
    rows: np.ndarray,
) -> list[Finding]:
    """Both step tests: ``r`` the whitened residual (3n), ``whiten`` (n, 3, 3) and its inverse ``unwhiten``,
    ``u`` the gravity direction in the sensor frame in g (n, 3), ``basis`` an orthonormal basis of the
    model's span, ``order`` the stops' time order, ``dof`` the fit's residual degrees of freedom, ``rows`` the
    stops' rows in the user's table (what a finding names)."""
    n = len(order)
    splits = _splits(n)
    null = None
    if splits.size and n <= SIMULATED_STOPS:  # residual sets under the linearised model, shared by both tests
        noise = np.random.default_rng(0).standard_normal((r.size, DRAWS))
        null = noise - basis @ (basis.T @ noise)  # ⟂ the span: Qᵀr vanishes
    out = []
    for (test, what), directions in zip(KINDS, (_bias_directions, _attitude_directions), strict=True):
        if splits.size == 0:
            why = f"no test: a step needs {MIN_SIDE} stops on each side"
            out.append(Finding(test, what, why, None, 3, None, None, why))
            continue
        e = directions(whiten, u)[order]
        out.append(_scan(test, what, r, e, basis, order, splits, noise_known, dof, null, unwhiten, rows))
    return out


def _bias_directions(whiten: FloatArray, u: FloatArray) -> FloatArray:
    return whiten


def _attitude_directions(whiten: FloatArray, u: FloatArray) -> FloatArray:
    # δθ × u = −[u]× δθ: column a is the reading's change for a turn about sensor axis a
    cross = np.zeros((len(u), 3, 3))
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = -u[:, 2], u[:, 1], -u[:, 0]
    cross -= cross.transpose(0, 2, 1)
    return np.asarray(-np.einsum("nij,njk->nik", whiten, cross), dtype=float)


def _splits(n: int) -> np.ndarray:
    """First stop (in time order) of the later side, for each candidate split."""
    k = np.arange(MIN_SIDE, n - MIN_SIDE + 1)
    if k.size > MAX_SPLITS:
        k = np.unique(np.round(np.linspace(k[0], k[-1], MAX_SPLITS)).astype(int))
    return k


def _suffix(x: FloatArray, splits: np.ndarray) -> FloatArray:
    """Σ over the stops from each split on, of ``x`` given per stop in time order."""
    return _from_each_on(np.add.reduceat(x[splits[0] :], splits - splits[0], axis=0))


def _from_each_on(seg: FloatArray) -> FloatArray:
    """Sums of the segments between consecutive splits → sums from each split to the end."""
    return np.flip(np.cumsum(np.flip(seg, axis=0), axis=0), axis=0)


@dataclass(frozen=True)
class _Projected:
    """The step directions of every split, made orthogonal to the model's span (normalised per column)."""

    vec: FloatArray  # eigenvectors of each split's Gram matrix outside the span, (m, 3, 3)
    lam: FloatArray  # its eigenvalues, 1 where dropped, (m, 3)
    keep: np.ndarray  # the eigen-directions outside the span, (m, 3)
    norms: FloatArray  # column norms of each split's directions, (m, 3)
    inside: FloatArray  # Qᵀ D_k, (m, p, 3)
    c_obs: FloatArray  # D_kᵀ r outside the span, (m, 3)

    def explained(self, c: FloatArray) -> FloatArray:
        """Δχ² of each split for D_kᵀ r given as ``c`` (m, 3, S)."""
        proj = np.einsum("mab,mas->mbs", self.vec, c / self.norms[:, :, None])
        return np.asarray(np.sum(np.where(self.keep[:, :, None], proj**2 / self.lam[:, :, None], 0.0), axis=1))


def _project(r: FloatArray, e: FloatArray, basis: FloatArray, order: np.ndarray, splits: np.ndarray) -> _Projected:
    n = len(order)
    q = basis.reshape(n, 3, -1)[order]
    gram = _suffix(np.einsum("nia,nib->nab", e, e), splits)
    bounds = np.append(splits, n)
    inside = _from_each_on(np.stack([np.einsum("nip,nia->pa", q[a:b], e[a:b]) for a, b in pairwise(bounds)]))
    norms = np.sqrt(np.einsum("maa->ma", gram))
    scale = norms[:, :, None] * norms[:, None, :]
    lam, vec = np.linalg.eigh((gram - np.einsum("mpa,mpb->mab", inside, inside)) / scale)
    keep = lam > 1e-8
    rs = r.reshape(n, 3)[order]
    c_obs = _suffix(np.einsum("nia,ni->na", e, rs), splits) - np.einsum("mpa,p->ma", inside, basis.T @ r)
    return _Projected(vec, np.where(keep, lam, 1.0), keep, norms, inside, c_obs)


def largest_bias_step(r: FloatArray, whiten: FloatArray, basis: FloatArray, order: np.ndarray) -> tuple[float, int]:
    """The most the residual ``r`` a bias step at one stop (in time order) explains beyond ``basis`` — its Δχ²
    and the row of the first stop after it; (0, −1) when the stops allow no split. No p-value: it is the
    alternative a term that follows time must beat, not a test."""
    splits = _splits(len(order))
    if splits.size == 0:
        return 0.0, -1
    proj = _project(r, whiten[order], basis, order, splits)
    stat = proj.explained(proj.c_obs[:, :, None])[:, 0]
    best = int(np.argmax(stat))
    return float(stat[best]), int(order[splits[best]])


def _scan(
    test: str,
    what: str,
    r: FloatArray,
    e: FloatArray,
    basis: FloatArray,
    order: np.ndarray,
    splits: np.ndarray,
    noise_known: bool,
    dof: int,
    null: FloatArray | None,
    unwhiten: FloatArray,
    rows: np.ndarray,
) -> Finding:
    n = len(order)
    proj = _project(r, e, basis, order, splits)
    k = proj.keep.sum(axis=1)
    ok = (k > 0) & (noise_known | (dof - k >= 1))
    if not np.any(ok):
        why = "no test: the fitted model already absorbs a step, or no degrees of freedom are left"
        return Finding(test, what, why, None, 3, None, None, why)
    explained = proj.explained
    total = np.array([[float(r @ r)]])

    def rank(stat: FloatArray, total: FloatArray) -> FloatArray:  # per split (m, S): larger is less likely
        if noise_known:
            return stat
        return np.asarray(stat / np.maximum(total - stat, 1e-300))  # F is monotone in it at a fixed rank

    def logp(stat: FloatArray, total: FloatArray) -> FloatArray:  # per split (m, S)
        kk = np.where(ok, k, 1)[:, None]
        if noise_known:
            out = chi2_logsf(stat, kk)
        else:
            rest_dof = np.maximum(dof - kk, 1)
            out = f_logsf(rank(stat, total) * rest_dof / kk, kk, rest_dof)
        return np.asarray(np.where(ok[:, None], out, 0.0))

    stat = explained(proj.c_obs[:, :, None])
    lp = logp(stat, total)[:, 0]
    best = int(np.argmin(lp))
    tested = int(np.sum(ok))
    log_p = min(float(lp[best]) + float(np.log(tested)), 0.0)  # Bonferroni
    if null is not None:
        # the smallest p is the largest statistic when every split keeps the same rank (the usual case): cheaper
        score = rank if np.unique(k[ok]).size == 1 else logp
        sign = 1.0 if score is rank else -1.0
        ok_col = ok[:, None]
        observed = sign * float(np.max(np.where(ok_col, sign * score(stat, total), -np.inf)))
        log_p = min(log_p, _simulated(null, order, e, splits, explained, score, ok_col, sign, observed))
    # Size as the other tests give it: the explained structure (the step's part outside the model's span, which
    # is all the residual can show) as an RMS per stop in m/s², back through the stop noise.
    vec, norms = proj.vec[best], proj.norms[best]
    coef = vec @ np.where(proj.keep[best], (vec.T @ (proj.c_obs[best] / norms)) / proj.lam[best], 0.0) / norms
    structure = -(basis @ (proj.inside[best] @ coef)).reshape(n, 3)
    structure[order[splits[best] :]] += np.einsum("nia,a->ni", e[splits[best] :], coef)
    fitted = np.einsum("nij,nj->ni", unwhiten, structure)
    size = f"{np.sqrt(np.mean(np.sum(fitted**2, axis=1))) * 1e3 / G_N:.3g} mg RMS"
    return Finding(
        test,
        what,
        f"{size}, from stop {int(rows[order[splits[best]]]) + 1} on",
        float(stat[best, 0]),
        int(k[best]),
        float(np.exp(log_p)),
        log_p / np.log(10),
    )


def _simulated(
    r0: FloatArray,
    order: np.ndarray,
    e: FloatArray,
    splits: np.ndarray,
    explained: Callable[[FloatArray], FloatArray],
    score: Callable[[FloatArray, FloatArray], FloatArray],
    ok: np.ndarray,
    sign: float,
    observed: float,
) -> float:
    """log P(the most extreme split's score beyond the observed one) under the linearised model, (k + 1)/(S + 1):
    ``sign`` is +1 for a score that grows with the evidence (a statistic), −1 for one that falls (log p)."""
    n = len(order)
    rs = r0.reshape(n, 3, DRAWS)[order]
    c = _suffix(np.einsum("nia,nis->nas", e, rs), splits)
    extreme = np.max(np.where(ok, sign * score(explained(c), np.sum(r0**2, axis=0)[None, :]), -np.inf), axis=0)
    return float(np.log((1 + np.sum(extreme >= sign * observed)) / (1 + DRAWS)))
