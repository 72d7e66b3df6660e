"""The console script: a local fleet starts its worker server before the heavy imports."""

from __future__ import annotations

import subprocess
import sys

import pytest

from mountcal.__main__ import _local_fleet


@pytest.mark.parametrize(
    ("args", "early"),
    [
        (["fleet", "logs/", "-o", "f.parquet"], True),
        (["fleet", "logs/", "-o", "f.parquet", "--workers", "2"], True),
        (["fleet", "logs/", "-o", "f.parquet", "--scheduler", "tcp://h:8786"], False),
        (["fleet", "logs/", "-o", "f.parquet", "--scheduler=tcp://h:8786"], False),
        (["fleet", "--help"], False),
        (["calibrate", "stops.csv"], False),
        ([], False),
    ],
)
def test_only_a_local_fleet_starts_workers_early(args: list[str], early: bool) -> None:
    assert _local_fleet(args) is early


def test_importing_mountcal_is_light() -> None:
    """`import mountcal` and the fleet engines import none of numpy, scipy, pandas (names load on use)."""
    code = (
        "import sys, mountcal, mountcal.fleet.engines; "
        "heavy = sorted(m for m in ('numpy', 'scipy', 'pandas', 'pyarrow') if m in sys.modules); "
        "print(','.join(heavy)); mountcal.calibrate; print('numpy' in sys.modules)"
    )
    lines = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert lines.splitlines() == ["", "True"]  # nothing heavy until a name is used; then it loads


def test_python_dash_m_mountcal_runs_the_cli() -> None:
    done = subprocess.run([sys.executable, "-m", "mountcal", "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "calibrate" in done.stdout and "fleet" in done.stdout


def test_an_export_named_like_its_submodule_stays_the_export() -> None:
    """`mountcal.calibrate` is the function even after the submodule mountcal.calibrate is imported."""
    code = (
        "import mountcal.calibrate, mountcal; from mountcal import calibrate; "
        "import types; print(callable(mountcal.calibrate) and not isinstance(calibrate, types.ModuleType))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"


def test_unknown_names_are_attribute_errors() -> None:
    import mountcal

    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        mountcal.nope  # noqa: B018
    assert {"calibrate", "Calibration", "read_log"} <= set(dir(mountcal))


def test_version_is_the_installed_distributions() -> None:
    """`mountcal --version` and `mountcal.__version__` say the same version, the distribution's when installed."""
    import importlib.metadata

    import mountcal

    done = subprocess.run([sys.executable, "-m", "mountcal", "--version"], capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == f"mountcal {mountcal.__version__}"
    try:
        assert mountcal.__version__ == importlib.metadata.version("mountcal")
    except importlib.metadata.PackageNotFoundError:  # a source tree on the path, not installed
        assert mountcal.__version__ == "unknown"
