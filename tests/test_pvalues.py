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


@pytest.mark.parametrize("dof", [1, 3, 17])
def test_chi2_threshold_equals_scipy_stats(dof: int) -> None:
    p = np.array([1e-12, 1e-6, 0.001, 0.05, 0.5, 0.99])
    np.testing.assert_allclose(pvalues.chi2_isf(p, dof), stats.chi2.isf(p, dof), rtol=1e-12, atol=0)


def test_no_module_of_mountcal_imports_scipy_stats() -> None:
    """Every module of the package imported (the fleet worker's whole calibration stack among them):
    scipy.stats stays out — its import alone costs ~0.3 s of every command and of every fleet worker
    server's start, and this module's functions give the same values."""
    import subprocess
    import sys

    code = (
        "import importlib, pkgutil, sys, mountcal\n"
        "names = [m.name for m in pkgutil.walk_packages(mountcal.__path__, 'mountcal.')]\n"
        "for name in names:\n"
        "    try:\n"
        "        importlib.import_module(name)\n"
        "    except ImportError as err:  # an optional extra not installed: its modules are not ours to weigh\n"
        "        if not (err.name or '').split('.')[0] in ('dask', 'distributed', 'matplotlib', 's3fs'):\n"
        "            raise\n"
        "print(len(names), 'scipy.stats' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    count, imported = done.stdout.split()
    assert int(count) > 100 and imported == "False", done.stdout + done.stderr
