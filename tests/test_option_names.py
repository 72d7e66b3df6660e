"""Library messages name the Python parameter; the same messages from the CLI name its flag."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import pandas as pd
import pytest

from mountcal import cli
from mountcal.apply.rotate_log import output_format, rotate_log
from mountcal.calibration.options import Options, parse_model
from mountcal.calibration.pipeline import calibrate_log
from mountcal.core.errors import InputError
from mountcal.core.option_names import OPTIONS, as_flags, option
from mountcal.io.reader import LogOptions
from mountcal.outputs.exporters import Frames, export
from mountcal.outputs.report.html import render
from mountcal.sessions.plan import Noise
from mountcal.simulate.stops import simulate_preset
from mountcal.stops.detect import StopDetection
from mountcal.stops.headings import relax
from mountcal.stops.table import read_stop_table, write_stop_table


def _flags_of_every_command() -> set[str]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    assert isinstance(sub, dict) and set(sub) == set(cli.COMMANDS)
    return {flag for p in sub.values() for action in p._actions for flag in action.option_strings}


def test_every_flag_in_the_table_is_a_flag_of_the_parsers() -> None:
    flags = _flags_of_every_command()
    missing = {key: flag for key, (_, flag) in OPTIONS.items() if flag not in flags}
    assert not missing, f"no command has {missing}"


def test_every_python_spelling_in_the_table_is_a_parameter() -> None:
    from mountcal.fleet import FleetOptions

    owners = (StopDetection, Options, LogOptions, Frames, FleetOptions, Noise)
    classes = {c.__name__: {f.name for f in dataclasses.fields(c)} for c in owners}
    parameters = set().union(
        *(
            inspect.signature(f).parameters
            for f in (calibrate_log, read_stop_table, rotate_log, output_format, render, export)
        )
    )
    for key, (python, _) in OPTIONS.items():
        owner, _, name = python.rpartition(".")
        known = classes[owner] if owner else parameters
        assert name in known, f"{key}: {python} names no parameter"


def test_option_spells_the_value_for_each_reader() -> None:
    assert option("unit", "g") == "unit='g'" and option("level_only", True) == "level_only=True"
    with as_flags():
        assert option("unit", "g") == "--unit g" and option("level_only", True) == "--level-only"
        assert option("max_acc_std") == "--max-acc-std"
    assert option("max_acc_std") == "StopDetection.max_acc_std_mps2="  # the block is left: Python again
    assert "--" not in relax() and "StopDetection.min_duration_s=" in relax()


@pytest.fixture
def g_table(tmp_path: Path) -> Path:
    table, _ = simulate_preset("zhang2011", seed=21)
    path = tmp_path / "stops.csv"
    write_stop_table(table, path)
    df = pd.read_csv(path)
    df[["ax", "ay", "az"]] /= 9.80665  # a table in g, read as m/s²
    df.to_csv(path, index=False)
    return path


def test_a_library_error_names_the_parameter_and_no_flag(g_table: Path) -> None:
    with pytest.raises(InputError) as err:
        read_stop_table(g_table)
    assert "unit='g'" in str(err.value) and "--" not in str(err.value)
    with pytest.raises(InputError) as model_err:
        parse_model("rotation,slope,nonsense")
    assert str(model_err.value).startswith("Options.model=") and "--" not in str(model_err.value)


def test_the_same_error_through_the_cli_names_the_flag(g_table: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["calibrate", str(g_table)]) == 2
    err = capsys.readouterr().err
    assert "add --unit g" in err and "unit='g'" not in err
    assert cli.main(["calibrate", str(g_table), "--unit", "g", "--model", "rotation,slope,nonsense"]) == 2
    err = capsys.readouterr().err
    assert "--model" in err and "Options.model" not in err
    assert option("unit") == "unit="  # the CLI's rendering ends with its command
