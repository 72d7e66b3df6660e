"""An output's suffix means its format, or the output is refused before anything is written
(issue 23, reproduction 5: ``rotate -o out.blf`` wrote Parquet under a BLF name, exit 0).

Each output option declares the suffixes of what it writes where its parser is built, in its path
declaration (``add_path(..., formats=...)``, :mod:`mountcal.cli.path_options`); the one check
(:func:`mountcal.core.output_suffix.check_output_suffix`) runs from that declaration before every
command, and the library's writers that choose a format by name apply it too.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from mountcal.apply.rotate_log import rotate_log
from mountcal.cli import COMMANDS, build_parser, main
from mountcal.cli.path_options import declared, label
from mountcal.core.errors import InputError
from mountcal.core.output_suffix import check_output_suffix
from mountcal.core.result import Calibration
from mountcal.stops.table import read_stop_table, write_stop_table

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("result") / "r.json"
    assert main(["calibrate", str(DATA / "zhang2011_stops.csv"), "-o", str(path), "-q"]) == 0
    return path


@pytest.mark.parametrize("name", ["out.blf", "out.mf4", "out.json", "out.txt"])
def test_rotate_refuses_an_output_named_for_a_format_it_does_not_write(
    name: str, result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / name
    assert main(["rotate", str(DATA / "parking.mcap"), "--calibration", str(result), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"a name ending in {out.suffix}" in err and "out.parquet" in err and "Traceback" not in err
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match=r"output=? .*Parquet \(\.parquet\)"):
        rotate_log(DATA / "parking.mcap", Calibration.load(result), out)


def test_rotate_writes_what_its_name_says_and_refuses_a_format_that_contradicts_it(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["rotate", str(DATA / "parking.mcap"), "--calibration", str(result), "-q"]
    assert main([*base, "-o", str(tmp_path / "v.csv"), "--format", "parquet"]) == 2
    assert "Drop --format to write csv" in capsys.readouterr().err
    assert main([*base, "-o", str(tmp_path / "v.csv")]) == 0
    assert (tmp_path / "v.csv").read_bytes()[:4] != b"PAR1"
    assert main([*base, "-o", str(tmp_path / "v"), "--format", "csv"]) == 0  # no suffix: the format asked for


def test_the_other_writers_refuse_a_name_of_another_format(result: Path, tmp_path: Path) -> None:
    table = read_stop_table(DATA / "zhang2011_stops.csv")
    with pytest.raises(InputError, match=r"\.mcap, which says MCAP"):
        write_stop_table(table, tmp_path / "s.mcap")
    with pytest.raises(InputError, match=r"\.csv, which says CSV"):
        Calibration.load(result).save(tmp_path / "r.csv")
    assert list(tmp_path.iterdir()) == []
    assert check_output_suffix("-o", "table", (".csv", ".parquet")) == ".csv"
    assert check_output_suffix("-o", "table.PQ", (".csv", ".parquet", ".pq")) == ".pq"


@pytest.mark.parametrize(
    ("args", "name"),
    [
        (["stops", str(DATA / "parking.mcap")], "s.json"),
        (["calibrate", str(DATA / "zhang2011_stops.csv")], "r.yaml"),
        (["calibrate", str(DATA / "zhang2011_stops.csv"), "-o", "r.json", "--report"], "r.pdf"),
        (["simulate"], "stops.blf"),
        (["plan", "--target", "roll=0.1"], "protocol.parquet"),
    ],
)
def test_every_output_option_is_checked_before_the_command_runs(
    args: list[str], name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    flag = [] if args[-1] == "--report" else ["-o"]
    assert main([*args, *flag, name]) == 2
    assert f"a name ending in {Path(name).suffix}" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# outputs whose names are not one format's: the command checks them itself
OWN_NAMES = {
    ("live", "-o"): "a prefix: PREFIX.blf, PREFIX.json, PREFIX_stops.csv, PREFIX_protocol.csv",
    ("fleet", "-o"): "must end in .parquet: run_fleet refuses any other name, a missing suffix too",
    ("simulate", "--log"): "each log is written in the format its own suffix names (.mcap, .blf, .mf4, ...)",
}


def test_every_output_declares_the_formats_it_writes() -> None:
    """Walks every command's path declarations: an output added later without its formats fails here."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    outputs = []
    for name in COMMANDS:
        for action in sub.choices[name]._actions:
            spec = declared(action)
            if spec is not None and spec.role == "output":
                outputs.append((name, label(action)))
                assert spec.formats or (name, label(action)) in OWN_NAMES, (name, label(action))
    assert len(outputs) >= 15 and set(OWN_NAMES) <= set(outputs)


def test_export_takes_the_suffixes_of_its_format(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["export", str(result), "--to", "yaml", "-o", str(tmp_path / "m.blf")]) == 2
    assert "a name ending in .blf" in capsys.readouterr().err and not (tmp_path / "m.blf").exists()
    assert main(["export", str(result), "--to", "json", "-o", str(tmp_path / "m.sh")]) == 2
    assert main(["export", str(result), "--to", "yaml", "-o", str(tmp_path / "m.yml")]) == 0
