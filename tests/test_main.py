"""The console script: a local fleet starts its worker server before the heavy imports."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from mountcal.__main__ import _local_fleet

DATA = Path(__file__).resolve().parents[1] / "data"


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


def test_an_export_stays_the_export_when_its_home_is_imported() -> None:
    """`mountcal.calibrate` is the function after its module mountcal.calibration.fit is imported."""
    code = (
        "import mountcal.calibration.fit, mountcal; from mountcal import calibrate; import types; "
        "print(callable(mountcal.calibrate) and calibrate is mountcal.calibration.fit.calibrate "
        "and not isinstance(calibrate, types.ModuleType))"
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


COMMANDS = ("calibrate", "stops", "inspect", "rotate", "report", "fleet", "simulate", "plan", "live", "export", "triad")


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_imports_no_numerical_library(command: str | None) -> None:
    """`mountcal --help` and `mountcal CMD --help` build the parser without numpy, pandas or scipy."""
    args = [] if command is None else [command]
    code = (
        "import sys, contextlib, io\n"
        "from mountcal.__main__ import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):\n"
        f"    main({args!r} + ['--help'])\n"
        "heavy = sorted(m for m in ('numpy', 'pandas', 'scipy', 'pyarrow', 'matplotlib') if m in sys.modules)\n"
        "print(','.join(heavy)); print('usage: mountcal' in out.getvalue())"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.splitlines() == ["", "True"], done.stdout + done.stderr


def test_the_fleet_command_itself_imports_no_fit(tmp_path: Path) -> None:
    """`mountcal fleet` lists, hashes, stores and analyses; its workers fit. The command process
    imports neither the fit nor the estimators (≈ 0.3 s of start-up, serial before the first log goes out)."""
    import shutil

    logs = tmp_path / "v01"
    logs.mkdir()
    shutil.copy(DATA / "parking.mcap", logs / "a.mcap")
    out = tmp_path / "fleet.parquet"
    code = (
        "import sys\n"
        "from mountcal.__main__ import main\n"
        f"code = main(['fleet', {str(tmp_path)!r}, '-o', {str(out)!r}, '-q', '--workers', '1'])\n"
        "fit = ('mountcal.calibration.pipeline', 'mountcal.calibration.fit', 'mountcal.estimate.full',"
        " 'scipy.optimize')\n"
        "fit = sorted(m for m in fit if m in sys.modules)\n"
        "print(code, ','.join(fit))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.stdout.split() == ["0"], done.stdout + done.stderr
    assert out.exists()


def test_every_command_has_the_common_options_and_the_cli_knows_them_all() -> None:
    from mountcal.cli import COMMANDS as known
    from mountcal.cli import build_parser

    assert set(known) == set(COMMANDS)
    parser = build_parser()
    for command in COMMANDS:
        args = parser.parse_args([command, "-q", "-v", "-v", "--progress", *_required(command)])
        assert (args.quiet, args.verbose, args.progress) == (1, 2, True)


def test_the_help_documents_the_exit_codes() -> None:
    from mountcal.cli import build_parser
    from mountcal.cli.options import EXIT_CODES

    text = build_parser().format_help()
    for code in EXIT_CODES:
        assert f"\n  {code:<4} " in text


def test_the_export_formats_of_the_parser_are_the_registry_s() -> None:
    from mountcal.cli import build_parser
    from mountcal.cli.path_options import command_parser
    from mountcal.outputs import exporters

    to = next(a for a in command_parser(build_parser(), "export")._actions if a.dest == "to")
    assert to.choices is not None and tuple(to.choices) == exporters.names() and len(exporters.names()) >= 10


def _required(command: str) -> list[str]:
    return {
        "calibrate": ["s.csv"],
        "stops": ["l.mcap", "-o", "s.csv"],
        "inspect": ["l.mcap"],
        "rotate": ["l.mcap", "--calibration", "r.json", "-o", "o.parquet"],
        "report": ["r.json"],
        "fleet": ["logs", "-o", "f.parquet"],
        "plan": ["--target", "roll=0.1"],
        "live": ["--interface", "virtual", "--channel", "0", "--dbc", "b.dbc"],
        "export": ["r.json", "--to", "json", "-o", "-"],
        "triad": ["s.csv", "-o", "t.json"],
    }.get(command, [])


def test_the_process_entry_point_skips_the_exit_collections_and_an_in_process_call_does_not() -> None:
    """The console script's process ends right after ``main()``: its objects are frozen, so CPython's
    collections at exit skip them. A caller running ``main(argv)`` in its own process keeps its collector."""
    probe = (
        "import gc, sys; from mountcal.__main__ import main; "
        "main(['inspect', 'no-such.csv']); inside = gc.get_freeze_count(); "
        "sys.argv = ['mountcal', 'inspect', 'no-such.csv']; main(); print(inside, gc.get_freeze_count() > 0)"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.split()[-2:] == ["0", "True"], done.stdout
