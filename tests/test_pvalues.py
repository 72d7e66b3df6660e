"""χ² and F tail probabilities from scipy.special equal scipy.stats' own."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import special, stats

from mountcal.core import pvalues

X = np.array([-1.0, 0.0, 1e-9, 0.5, 1.0, 3.0, 10.0, 50.0, 200.0, 800.0, 2000.0])


@pytest.mark.parametrize("dof", [1, 2, 3, 5, 17, 100])
def test_chi2_tails_equal_scipy_stats(dof: int) -> None:
    np.testing.assert_allclose(pvalues.chi2_sf(X, dof), stats.chi2.sf(X, dof), rtol=1e-13, atol=0)
    ref = stats.chi2.logsf(X, dof)
    ours = pvalues.chi2_logsf(X, dof)
    finite = np.isfinite(ref)
    np.testing.assert_allclose(ours[finite], ref[finite], rtol=1e-13, atol=0)
    assert np.all(np.isfinite(ours)) and np.all(ours[~finite] < np.log(1e-300))


@pytest.mark.parametrize("dfn", [1, 3, 17])
@pytest.mark.parametrize("dfd", [1, 4, 30, 1000])
def test_f_tails_equal_scipy_stats(dfn: int, dfd: int) -> None:
    np.testing.assert_allclose(pvalues.f_sf(X, dfn, dfd), stats.f.sf(X, dfn, dfd), rtol=1e-12, atol=0)
    ref = stats.f.logsf(X, dfn, dfd)
    ours = pvalues.f_logsf(X, dfn, dfd)
    finite = np.isfinite(ref)
    np.testing.assert_allclose(ours[finite], ref[finite], rtol=1e-12, atol=0)
    assert np.all(np.isfinite(ours)) and np.all(ours[~finite] < np.log(1e-300))


def test_scalars_stay_scalars() -> None:
    assert np.ndim(pvalues.chi2_logsf(3.0, 2)) == 0
    assert np.ndim(pvalues.chi2_logsf(1e5, 1)) == 0


@pytest.mark.parametrize(("a", "x"), [(0.5, 50.0), (1.5, 30.0), (3.0, 100.0), (150.0, 400.0), (500.0, 900.0)])
def test_underflow_branch_of_chi2_equals_scipy_where_scipy_is_finite(a: float, x: float) -> None:
    """The continued fraction used where the tail underflows, checked where it does not."""
    assert pvalues._log_upper_gamma(a, x) == pytest.approx(np.log(special.gammaincc(a, x)), rel=1e-10)


@pytest.mark.parametrize(("a", "b", "z"), [(5.0, 1.5, 1e-3), (0.5, 2.0, 1e-6), (50.0, 3.0, 0.01), (200.0, 0.5, 0.2)])
def test_underflow_branch_of_f_equals_scipy_where_scipy_is_finite(a: float, b: float, z: float) -> None:
    assert pvalues._log_beta_lower(a, b, z) == pytest.approx(np.log(special.betainc(a, b, z)), rel=1e-10)


def test_an_underflowed_tail_is_finite_and_follows_the_asymptote() -> None:
    """log Q(1/2, x/2) ≈ −x/2 − ½ log(πx/2) for large x (χ²(1) tail): finite, never −inf."""
    x = 1e5
    assert pvalues.chi2_logsf(x, 1) == pytest.approx(-x / 2 - 0.5 * np.log(np.pi * x / 2), rel=1e-8)
    assert np.isfinite(pvalues.f_logsf(1e300, 3, 2000))
