"""A model choice's steps: each model the loop fitted (:class:`Step`) and the whole sequence with the candidates
turned down and the final residual analysis (:class:`Loop`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.core.findings import Finding
from mountcal.core.pvalues import unexplained
from mountcal.core.result import Declined
from mountcal.estimate import full
from mountcal.stops.table import StopTable


@dataclass(frozen=True)
class Step:
    """One model of the loop: its terms, the stops it leaves out, its fit and why it was taken."""

    added: str
    reason: str
    terms: tuple[str, ...]
    excluded: tuple[int, ...]
    table: StopTable
    fit: full.Fit
    loo_rms_mps2: float | None = None


@dataclass(frozen=True)
class Loop:
    """The sequence of models, the candidates turned down, and the final residual analysis."""

    steps: list[Step]
    declined: list[Declined]
    findings: list[Finding]
    doubts: list[str] = field(default_factory=list)  # why the chosen model may be the wrong explanation

    @property
    def final(self) -> Step:
        return self.steps[-1]

    @property
    def unexplained(self) -> list[Finding]:
        """The findings the family's test rejects (Holm at :data:`mountcal.core.pvalues.FAMILY_ALPHA`)."""
        return unexplained(self.findings)


def neg2loglik(table: StopTable, fit: full.Fit) -> float:
    """−2 log-likelihood of a fit of ``table`` (up to a constant): χ² and the stops' covariances' log-determinants,
    what a noise model (a road tilt, the headings' scatter) trades against each other."""
    return fit.chi2 + float(np.sum(np.linalg.slogdet(table.cov_s)[1]))  # type: ignore[arg-type]


def held_neg2loglik(resid: FloatArray, cov: FloatArray) -> float:
    """The same for the residual ``resid`` (n, 3) of a mean model held fixed, under the stop covariances ``cov``."""
    chi2 = np.einsum("ni,ni->", resid, np.linalg.solve(cov, resid[..., None])[..., 0])
    return float(chi2 + np.sum(np.linalg.slogdet(cov)[1]))


__all__ = ["Loop", "Step", "held_neg2loglik", "neg2loglik"]
