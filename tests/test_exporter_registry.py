"""An export format is one file, found by the registry (:mod:`mountcal.outputs.exporters`): dropped into the
package, or in another package declaring it in the entry-point group ``mountcal.exporters``. Either way it is
a ``--to`` choice, its suffix is accepted by ``-o`` (and another format's refused), and it writes — with no
other edit. The plugin is installed the way pip leaves a package: a module and a ``*.dist-info`` folder
(METADATA, entry_points.txt) on the path, as in tests/io/test_reader_plugin.py."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from mountcal.calibration.fit import calibrate
from mountcal.cli import build_parser, main
from mountcal.cli.path_options import command_parser
from mountcal.core.conventions import angles_from_rot_vs
from mountcal.core.result import Calibration
from mountcal.outputs import exporters
from mountcal.simulate.stops import simulate_stops

SRC = Path(__file__).resolve().parents[1] / "src"

# The one new file: roll, pitch, yaw in degrees on one line.
ANGLES = '''
"""roll pitch yaw in degrees, one line."""

from mountcal.outputs.exporters.common import Exporter, ExportOptions


def write(cal, options: ExportOptions) -> str:
    from mountcal.core.conventions import angles_from_rot_vs

    roll, pitch, yaw = angles_from_rot_vs(options.mounting(cal).rot_vs)
    return f"{roll:.12f} {pitch:.12f} {yaw:.12f}\\n"


EXPORTER = Exporter("angles", (".angles", ".txt"), "roll pitch yaw in radians, one line", write)
EXPORTERS = (EXPORTER,)
'''


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Calibration]:
    table, _ = simulate_stops(5.0, 6.0, 7.0, seed=3)
    cal = calibrate(table)
    path = tmp_path_factory.mktemp("registry") / "r.json"
    cal.save(path)
    return path, Calibration.load(path)


def _angles(text: str) -> list[float]:
    return [float(v) for v in text.split()]


def _to_choices() -> tuple[str, ...]:
    to = next(a for a in command_parser(build_parser(), "export")._actions if a.dest == "to")
    assert to.choices is not None
    return tuple(to.choices)


def _run(*args: str | Path) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


# ------------------------------------------------------------------ a file dropped into the package


@contextlib.contextmanager
def dropped_into_the_package(folder: Path) -> Iterator[None]:
    """``folder/angles.py`` as a module of mountcal.outputs.exporters, for the duration (the package's
    ``__path__`` extended: what a file written into src/mountcal/outputs/exporters/ does)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "angles.py").write_text(ANGLES, encoding="utf-8")
    exporters.__path__.append(str(folder))
    exporters.builtin.cache_clear()
    try:
        yield
    finally:
        exporters.__path__.remove(str(folder))
        sys.modules.pop(f"{exporters.__name__}.angles", None)
        exporters.builtin.cache_clear()


def test_a_file_in_the_package_is_a_format_with_no_other_edit(tmp_path: Path, result: tuple[Path, Calibration]) -> None:
    path, cal = result
    assert "angles" not in exporters.names()
    with dropped_into_the_package(tmp_path / "pkg"):
        assert "angles" in _to_choices()
        help_text = command_parser(build_parser(), "export").format_help()
        assert "\n  angles " in help_text and "roll pitch yaw in radians, one line\n" in help_text
        assert "| `angles` | roll pitch yaw in radians, one line | `.angles`, `.txt` |" in exporters.markdown_table()
        out = tmp_path / "mount.angles"
        code, _, err = _run("export", path, "--to", "angles", "-o", out)
        assert code == 0, err
        assert _angles(out.read_text()) == pytest.approx(angles_from_rot_vs(cal.rot_vs), abs=1e-11)
        code, _, err = _run("export", path, "--to", "angles", "-o", tmp_path / "mount.json")
        assert code == 2 and "mount.angles" in err and not (tmp_path / "mount.json").exists()
    assert "angles" not in exporters.names() and "angles" not in _to_choices()


def test_the_registry_lists_the_built_in_formats_without_numerical_libraries() -> None:
    code = (
        "import sys; from mountcal.outputs import exporters; exporters.builtin(); exporters.markdown_table()\n"
        "print(sorted(m for m in ('numpy', 'scipy', 'pandas') if m in sys.modules))"
    )
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


# ------------------------------------------------------------------ a plugin, through the entry point


def install(folder: Path, module: str, source: str, entries: str) -> dict[str, str]:
    """``module.py`` and its distribution's metadata in ``folder``; the environment that sees them."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{module}.py").write_text(source, encoding="utf-8")
    info = folder / f"{module}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 1.0\n", encoding="utf-8")
    (info / "entry_points.txt").write_text(f"[mountcal.exporters]\n{entries}\n", encoding="utf-8")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), str(folder)])}


def mountcal(env: dict[str, str], *args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mountcal", *map(str, args)], env=env, capture_output=True, text=True, timeout=600
    )


PLUGIN = (
    ANGLES
    + """

def crash(cal, options):
    print("a plugin printing")
    raise RuntimeError("the plugin's own bug")


CRASHING = Exporter("crashing", (".crash",), "a writer that raises", crash)
"""
)


def test_a_plugin_s_format_is_chosen_accepted_and_written(tmp_path: Path, result: tuple[Path, Calibration]) -> None:
    path, cal = result
    env = install(
        tmp_path / "site",
        "mc_angles",
        PLUGIN,
        "angles = mc_angles:EXPORTER\ncrashing = mc_angles:CRASHING\njson = mc_angles:EXPORTER\n"
        "missing = mc_nowhere:EXPORTER",
    )
    listed = subprocess.run(
        [sys.executable, "-c", "from mountcal.outputs import exporters; print(' '.join(exporters.names()))"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    assert listed[-3:] == ["angles", "crashing", "missing"] and listed.count("json") == 1  # a built-in stays

    done = mountcal(env, "export", path, "--to", "nope")  # argparse's choices name the plugin's format
    assert done.returncode == 2 and "'angles'" in done.stderr

    out = tmp_path / "mount.angles"
    done = mountcal(env, "export", path, "--to", "angles", "-o", out)
    assert done.returncode == 0, done.stderr
    assert _angles(out.read_text()) == pytest.approx(angles_from_rot_vs(cal.rot_vs), abs=1e-11)
    done = mountcal(env, "export", path, "--to", "angles", "-o", "-")  # to stdout
    assert done.returncode == 0 and _angles(done.stdout) == pytest.approx(_angles(out.read_text()), abs=0)

    done = mountcal(env, "export", path, "--to", "angles", "-o", tmp_path / "mount.yaml")  # another format's name
    assert done.returncode == 2 and "mount.angles" in done.stderr and not (tmp_path / "mount.yaml").exists()

    done = mountcal(env, "export", path, "--to", "json", "-o", "-")  # the built-in, not the plugin claiming its name
    assert done.returncode == 0 and '"format": "mountcal.rotation"' in done.stdout

    done = mountcal(env, "export", path, "--to", "crashing", "-o", "-")  # its bug and print: named, stdout clean
    assert done.returncode == 2 and done.stdout == ""
    assert "plugin 'crashing'" in done.stderr and "the plugin's own bug" in done.stderr
    assert "a plugin printing" in done.stderr

    done = mountcal(env, "export", path, "--to", "missing", "-o", "-")  # fails to load: refused by name
    assert done.returncode == 2 and "plugin 'missing'" in done.stderr and "mc_nowhere" in done.stderr
