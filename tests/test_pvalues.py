"""χ² and F tail probabilities from scipy.special equal scipy.stats' own."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from mountcal import pvalues

X = np.array([-1.0, 0.0, 1e-9, 0.5, 1.0, 3.0, 10.0, 50.0, 200.0, 800.0, 2000.0])


@pytest.mark.parametrize("dof", [1, 2, 3, 5, 17, 100])
def test_chi2_tails_equal_scipy_stats(dof: int) -> None:
    np.testing.assert_allclose(pvalues.chi2_sf(X, dof), stats.chi2.sf(X, dof), rtol=1e-13, atol=0)
    np.testing.assert_allclose(pvalues.chi2_logsf(X, dof), stats.chi2.logsf(X, dof), rtol=1e-13, atol=0)


@pytest.mark.parametrize("dfn", [1, 3, 17])
@pytest.mark.parametrize("dfd", [1, 4, 30, 1000])
def test_f_tails_equal_scipy_stats(dfn: int, dfd: int) -> None:
    np.testing.assert_allclose(pvalues.f_sf(X, dfn, dfd), stats.f.sf(X, dfn, dfd), rtol=1e-12, atol=0)
    np.testing.assert_allclose(pvalues.f_logsf(X, dfn, dfd), stats.f.logsf(X, dfn, dfd), rtol=1e-12, atol=0)


def test_scalars_stay_scalars() -> None:
    assert np.ndim(pvalues.chi2_logsf(3.0, 2)) == 0
    assert pvalues.chi2_logsf(1e5, 1) == -np.inf
