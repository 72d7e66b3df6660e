"""Numbers checked at the edge (issue 27, reproduction 5 and item 7's CAN stamps and ids).

Every float read from a file or an option is finite and inside the physical range of its
quantity (:mod:`mountcal.core.ranges`, one table stated in docs/reliability.md), or refused naming
it; nothing downstream writes ``inf`` or ``NaN``. The option ranges are a mechanism: a test walks
every parser, so a new numeric option cannot skip them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
from pathlib import Path

import can
import numpy as np
import pandas as pd
import pytest

from mountcal.calibration.fit import calibrate
from mountcal.cli import build_parser, main
from mountcal.core import ranges
from mountcal.core.errors import NotEnoughInformation
from mountcal.stops.table import read_stop_table

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
STOPS = DATA / "zhang2011_stops.csv"
DBC = DATA / "imu_mm5_10.dbc"


def _commands() -> list[tuple[str, argparse.ArgumentParser]]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices.items())


def test_every_numeric_option_is_declared_with_its_range() -> None:
    """No option parses a bare float or int: each names a quantity of the one table (a new option
    that does not fails here)."""
    checked = 0
    for command, parser in _commands():
        for action in parser._actions:
            flag = "/".join(action.option_strings) or action.dest
            assert action.type not in (float, int), f"{command} {flag}: declare it with mountcal.core.ranges.Number"
            quantities = ranges.option_quantities(action)
            if quantities is None:
                continue
            assert all(q in ranges.QUANTITIES for q in quantities), (command, flag)
            if len(quantities) > 1:
                assert action.nargs == len(quantities), (command, flag)
            checked += 1
    assert checked >= 60  # every command's numbers (calibrate alone has 14)


def test_the_table_in_the_docs_is_the_code_s() -> None:
    """docs/reliability.md states the ranges; this regenerates its table from mountcal.core.ranges."""
    docs = (REPO / "docs" / "reliability.md").read_text(encoding="utf-8")
    table = ranges.markdown(build_parser())
    assert table in docs, "regenerate the table: python -m mountcal.cli.ranges_table (then paste it)\n" + table


def test_every_quantity_is_used() -> None:
    assert "(library only)" not in ranges.markdown(build_parser())


# --------------------------------------------------------------------------- options


OPTIONS_OUT_OF_RANGE = [
    ["calibrate", str(STOPS), "--slope-reference", "5", "1e308"],
    ["calibrate", str(STOPS), "--slope-reference", "95", "1"],
    ["calibrate", str(STOPS), "--max-yaw-sigma", "nan"],
    ["plan", "--target", "roll=1", "--noise", "1", "--stop-s", "nan"],
    ["plan", "--target", "roll=1", "--noise", "1", "--rate-hz", "-1"],
    ["plan", "--target", "roll=1", "--noise", "1", "--max-stops", "1000000"],
    ["simulate", "-o", "x.csv", "--seed", "-1"],
    ["simulate", "-o", "x.csv", "--seed", "99999999999999999999"],
    ["simulate", "-o", "x.csv", "--noise-g", "nan"],
    ["simulate", "-o", "x.csv", "--slope", "90"],
    ["simulate", "-o", "x.csv", "--roll", "1e308"],
    ["simulate", "--log", "x.mcap", "--rate-hz", "0"],
    ["simulate", "--log", "x.mcap", "--rate-hz", "1e9"],
    ["simulate", "--log", "x.mcap", "--stop-s", "-5"],
    ["simulate", "--log", "x.mcap", "--drive-s", "1e300"],
    ["simulate", "--log", "x.mcap", "--start-time", "1e300"],
    ["simulate", "--log", "x.mcap", "--start-time", "-1"],
    ["simulate", "--log", "x.mcap", "--fix", "95", "0", "0"],
    ["simulate", "--log", "x.mcap", "--fix", "0", "0", "nan"],
    ["simulate", "--log", "x.mcap", "--acc-lsb", "inf"],
    ["rotate", str(STOPS), "--calibration", "r.json", "-o", "o.parquet", "--chunk", "0"],
    ["fleet", str(DATA), "-o", "f.csv", "--workers", "0"],
    ["export", "r.json", "--to", "urdf", "--translation", "0", "0", "1e308", "-o", "-"],
    ["stops", str(STOPS), "-o", "s.csv", "--trim-s", "-1"],
]


@pytest.mark.parametrize("args", OPTIONS_OUT_OF_RANGE, ids=lambda a: " ".join(a[:1] + a[-2:]))
def test_an_option_outside_its_range_is_refused_by_the_parser(
    args: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`--slope-reference 5 1e308` was a traceback, `plan --noise 5e-324` said "not reachable,
    because .", `--stop-s nan` planned "roll nan°", and simulate crashed on rates, durations,
    times, noise and seeds outside their range."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(args)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and re.search(r"argument [-\w/]+: expected .* in [\[(]", err), err
    assert list(tmp_path.iterdir()) == []


# options that take a unit (`--gravity 1g`, `--noise 5mg`): text for argparse, the number checked when read
UNIT_OPTIONS_OUT_OF_RANGE = [
    ["calibrate", str(STOPS), "--gravity", "inf"],
    ["calibrate", str(STOPS), "--gravity", "1e308g"],
    ["triad", str(STOPS), "-o", "t.json", "--gravity", "nan"],
    ["plan", "--target", "roll=1", "--noise", "5e-324"],
    ["plan", "--target", "roll=1", "--noise", "5e-324mg"],
    ["plan", "--target", "roll=1", "--noise", "1e308g"],
]


@pytest.mark.parametrize("args", UNIT_OPTIONS_OUT_OF_RANGE, ids=lambda a: " ".join(a[:1] + a[-2:]))
def test_an_option_with_a_unit_outside_its_range_is_refused(
    args: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A unit can carry a number out of any range: `plan --noise 1e308g` was an infinite noise."""
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"error: {args[-2]}: expected" in err and "nan" not in err.replace(args[-1], ""), err
    assert list(tmp_path.iterdir()) == []


def test_the_options_with_a_unit_are_declared_with_the_range_they_are_checked_against() -> None:
    from mountcal.io.input_conventions import GRAVITY, NOISE

    declared = {
        (command, action.option_strings[-1]): ranges.option_quantities(action)
        for command, parser in _commands()
        for action in parser._actions
        if action.option_strings and action.option_strings[-1] in ("--gravity", "--noise")
    }
    assert declared == {
        ("calibrate", "--gravity"): (GRAVITY.limit,),
        ("triad", "--gravity"): (GRAVITY.limit,),
        ("plan", "--noise"): (NOISE.limit,),
    }


def test_plan_targets_are_in_range(capsys: pytest.CaptureFixture[str]) -> None:
    for target in ("roll=nan", "roll=1e308", "roll=-1"):
        assert main(["plan", "--target", target, "--noise", "1"]) == 2
        assert "the target" in capsys.readouterr().err


# --------------------------------------------------------------------------- files


STOP_TABLE_EXTREMES = [
    ("sx", 1e-170),
    ("sx", 1e170),
    ("n", 1e308),
    ("n", 0.5),
    ("sx_mean", 1e-300),
    ("sx_mean", 1e308),
    ("temperature_c", 1e308),
    ("temperature_c", -1e308),
    ("alt_m", 1e308),
    ("alt_m", -1e308),
    ("t_s", 1e308),
    ("duration_s", 1e308),
    ("lon_deg", 1e308),
    ("heading_deg", -1e308),
    ("beta_deg", 1e308),
]


@pytest.mark.parametrize(("column", "value"), STOP_TABLE_EXTREMES)
def test_stop_table_values_at_the_edge_of_float_are_refused_by_name(
    column: str, value: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Stop tables with sx ≤ 1e-160 or ≥ 1e160, and n, sx_mean, temperature_c, alt_m near ±1e308
    gave 51 tracebacks."""
    df = pd.read_csv(STOPS).assign(n=100.0)
    if column == "sx_mean":
        df = df.assign(sx_mean=0.001, sy_mean=0.001, sz_mean=0.001)
    df[column] = df[column].astype(float) if column in df else np.arange(len(df), dtype=float)
    df.loc[0, column] = value
    path = tmp_path / "edge.csv"
    df.to_csv(path, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert column in err and "row 1" in err and "in [" in err, err
    assert not out.exists()


def test_stop_table_values_inside_the_ranges_give_finite_results(tmp_path: Path) -> None:
    """At the ends of the ranges nothing overflows: a finite result, or a refusal."""
    df = pd.read_csv(STOPS).assign(sx=1e-9, sy=1000.0, sz=0.01, n=1e12, temperature_c=200.0, alt_m=100_000.0)
    df.loc[::2, "temperature_c"] = -100.0
    path = tmp_path / "edge.csv"
    df.to_csv(path, index=False)
    out = tmp_path / "r.json"
    for model in ("auto", "rotation,slope,bias,temperature"):
        code = main(["calibrate", str(path), "-o", str(out), "--model", model, "-q"])
        assert code in (0, 3, 4)
        if code == 0:
            json.loads(out.read_text(), parse_constant=_no_constant)


def _no_constant(name: str) -> float:
    raise AssertionError(f"{name} written")


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("result") / "r.json"
    assert main(["calibrate", str(STOPS), "-o", str(path), "-q"]) == 0
    return path


@pytest.mark.invalid_results
@pytest.mark.parametrize("sigma", [1e300, 3601.0])
def test_a_result_with_a_huge_sigma_is_refused_by_every_reader(
    sigma: float, result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A result with σ = 1e300 loaded; then `export --to json` crashed, `--to yaml` wrote
    Infinity, and `report` crashed in matplotlib."""
    doc = json.loads(result.read_text())
    doc["uncertainty"] |= {"roll_deg": sigma, "pitch_deg": sigma, "rotation_about_vehicle_xyz_deg": [sigma] * 3}
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    for args in (
        ["export", str(bad), "--to", "json", "-o", "-"],
        ["export", str(bad), "--to", "yaml", "-o", str(tmp_path / "m.yaml")],
        ["export", str(bad), "--to", "novatel", "-o", "-"],
        ["report", str(bad), "-o", str(tmp_path / "r.html")],
        ["rotate", str(DATA / "parking.mcap"), "--calibration", str(bad), "-o", str(tmp_path / "o.parquet")],
    ):
        assert main(args) == 2, args
        out = capsys.readouterr()
        assert "uncertainty.roll_deg" in out.err and "[0, 3600]" in out.err and out.out == "", out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


def test_a_sigma_at_the_end_of_its_range_exports_finite_numbers(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = json.loads(result.read_text())
    doc["uncertainty"] |= {"roll_deg": 3600.0, "pitch_deg": 3600.0, "rotation_about_vehicle_xyz_deg": [3600.0] * 3}
    edge = tmp_path / "edge.json"
    edge.write_text(json.dumps(doc))
    for to in ("json", "yaml", "urdf", "ros2-static-tf", "ublox", "autoware"):
        out = tmp_path / f"m.{to}"
        parent = ["--parent", "base_link"] if to == "autoware" else []
        assert main(["export", str(edge), "--to", to, "-o", str(out), "--accept-unconfident", *parent]) == 0, to
        assert not re.search(r"\b(nan|inf|Infinity|NaN)\b", out.read_text()), to
    assert main(["report", str(edge), "-o", str(tmp_path / "r.html")]) == 0


def test_calibrate_never_writes_a_result_its_loader_refuses(tmp_path: Path) -> None:
    cal = calibrate(read_stop_table(STOPS))
    undetermined = dataclasses.replace(cal, roll_sigma_deg=5000.0)
    with pytest.raises(NotEnoughInformation, match=r"uncertainty.roll_deg = 5000"):
        undetermined.save(tmp_path / "r.json")
    assert list(tmp_path.iterdir()) == []


def test_imucal_matrices_at_the_edge_of_float_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """imucal matrices at 1e308 were a traceback (the polar decomposition overflowed)."""
    faces = tmp_path / "faces.csv"
    rows = [[s * 9.80665 if i == a else 0.0 for i in range(3)] for a in range(3) for s in (1, -1)]
    pd.DataFrame(rows, columns=["ax", "ay", "az"]).assign(sx=0.01, sy=0.01, sz=0.01, n=100).to_csv(faces, index=False)
    for key, value in (("K_a", [[1e308, 0, 0], [0, 1, 0], [0, 0, 1]]), ("b_a", [0, 0, -1e308])):
        doc = {"cal_type": "Ferraris", "acc_unit": "m/s^2", "K_a": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}
        doc |= {"R_a": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "b_a": [0, 0, 0], key: value}
        imucal = tmp_path / "imucal.json"
        imucal.write_text(json.dumps(doc))
        assert main(["triad", str(faces), "--imucal", str(imucal), "-o", str(tmp_path / "t.json")]) == 2
        err = capsys.readouterr().err
        assert key in err and "in [" in err, err
    assert not (tmp_path / "t.json").exists()


def test_a_sensor_spec_with_a_non_finite_toml_number_is_refused(tmp_path: Path) -> None:
    spec = tmp_path / "spec.toml"
    for text in ("scale = nan", "bias_mg = inf", "heading_deg = 1e3"):
        spec.write_text(text)
        assert main(["calibrate", str(STOPS), "--sensor-spec", str(spec)]) == 2


# --------------------------------------------------------------------------- CAN logs


def _can_logs(tmp_path: Path) -> dict[str, Path]:
    """A candump log and a CAN CSV written by python-can (the IMU's frames of data/imu_mm5_10.dbc)."""
    messages = [
        can.Message(timestamp=1.0 + k * 0.01, arbitration_id=ident, is_extended_id=False, data=bytes(8), channel=0)
        for k in range(20)
        for ident in (0x070, 0x080, 0x576)
    ]
    paths = {"log": tmp_path / "a.log", "csv": tmp_path / "a.csv"}
    with can.CanutilsLogWriter(str(paths["log"]), channel="can0") as log, can.CSVWriter(str(paths["csv"])) as csv:
        for msg in messages:
            log.on_message_received(msg)
            csv.on_message_received(msg)
    return paths


@pytest.mark.parametrize(
    ("fmt", "old", "new", "named"),
    [
        ("log", "(1.000000)", "(nan)", "time stamps"),
        ("log", "(1.010000)", "(1e300)", "time stamps"),
        ("csv", "\n1.0,", "\nnan,", "time stamps"),
        ("csv", "\n1.01,0x70,", "\n1.01,-0x70,", "arbitration ids"),
        ("csv", "\n1.01,0x70,", "\n1.01,0x7FFFFFFFFFFF,", "arbitration ids"),
    ],
)
def test_text_can_logs_with_impossible_stamps_or_ids_are_refused(
    fmt: str, old: str, new: str, named: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """candump and CAN CSV logs with NaN stamps or id -0x70 were tracebacks."""
    path = _can_logs(tmp_path)[fmt]
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    for args in (
        ["inspect", str(path), "--dbc", str(DBC)],
        ["stops", str(path), "--dbc", str(DBC), "-o", str(tmp_path / "s.csv")],
    ):
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert named in err and str(path) in err and "in [" in err, err
    assert not (tmp_path / "s.csv").exists()


def test_the_truth_of_a_simulation_is_finite_json_at_the_ends_of_the_ranges(tmp_path: Path) -> None:
    """simulate wrote NaN literals into a truth JSON."""
    truth = tmp_path / "t.json"
    logs = [str(tmp_path / f"s.{fmt}") for fmt in ("mcap", "blf", "mf4")]
    args = ["--slope", "89.99", "--roll", "360", "--rate-hz", "1", "--stop-s", "1", "--drive-s", "1"]
    args += ["--fix", "90", "360", "100000", "--seed", str(2**32 - 1), "--dbc", str(DBC)]
    for start in ("86400", "2e9"):  # the ends of the start time: MF4 and ROS 2 stamps hold them
        assert main(["simulate", "--log", *logs, "--truth", str(truth), *args, "--start-time", start, "-q"]) == 0
        doc = json.loads(truth.read_text(), parse_constant=_no_constant)
        assert all(math.isfinite(v) for v in doc["beta_deg"])
    assert main(["simulate", "--log", str(tmp_path / "big.mcap"), "--rate-hz", "10000", "--stop-s", "3600"]) == 2
    assert not (tmp_path / "big.mcap").exists()
