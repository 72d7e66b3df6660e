"""Tampered and corrupted calibration files (issue 12, item 6), the stop table of `report --stops`,
and text from files shown in a terminal (item 8).

The published JSON Schema is checked with the ``jsonschema`` library (a reference implementation
that shares nothing with mountcal's own validator) on results written by the real `calibrate`.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pandas as pd
import pytest

from mountcal.cli import main
from mountcal.core.budget import setting
from mountcal.core.errors import InputError
from mountcal.core.result import FORMAT_VERSION, Calibration, schema_defs
from mountcal.core.result_file import check_document, read_json, schema
from mountcal.core.terminal import safe

Doc = dict[str, Any]


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Stop tables and the results `mountcal calibrate` writes for them (models with and without bias,
    paper method, relative headings, yaw undetermined)."""
    d = tmp_path_factory.mktemp("tamper")
    out: dict[str, Path] = {}
    assert main(["simulate", "-o", str(d / "s.csv"), "--seed", "7"]) == 0
    assert main(["simulate", "-o", str(d / "other.csv"), "--seed", "8"]) == 0
    assert main(["simulate", "-o", str(d / "b.csv"), "--seed", "9", "--bias-mg", "20", "-10", "5"]) == 0
    for name, args in {
        "auto": ["s.csv"],
        "bias": ["b.csv", "--model", "rotation,slope,bias"],
        "paper": ["s.csv", "--method", "paper"],
        "relative": ["s.csv", "--headings", "relative"],
        "none": ["s.csv", "--headings", "none"],
    }.items():
        out[name] = d / f"{name}.json"
        assert main(["calibrate", str(d / args[0]), *args[1:], "-o", str(out[name])]) == 0
    out["stops"], out["other"], out["dir"] = d / "s.csv", d / "other.csv", d
    return out


def test_every_result_calibrate_writes_matches_the_published_schema_and_the_loader(made: dict[str, Path]) -> None:
    for name in ("auto", "bias", "paper", "relative", "none"):
        doc = json.loads(made[name].read_text())
        jsonschema.validate(doc, schema())
        check_document(doc, name)  # no exception
        Calibration.load(made[name])


def _set(path: str, value: Any) -> Callable[[Doc], None]:
    def change(doc: Doc) -> None:
        *parents, last = path.split(".")
        for key in parents:
            doc = doc[int(key)] if isinstance(doc, list) else doc[key]
        if isinstance(doc, list):
            doc[int(last)] = value
        else:
            doc[last] = value

    return change


# Tampering a schema can see; mountcal's loader and the jsonschema library must both refuse it.
SCHEMA_VISIBLE = {
    "string roll": _set("mounting.roll_deg", "5"),
    "pitch beyond 90": _set("mounting.pitch_deg", 91.0),
    "huge bias": _set("bias_mps2", [1e308, 0.0, 0.0]),
    "two-element bias": _set("bias_mps2", [0.1, 0.2]),
    "negative sigma": _set("uncertainty.roll_deg", -0.1),
    "negative bias sigma": _set("uncertainty.bias_mps2.1", -0.01),
    "negative sigma about z": _set("uncertainty.rotation_about_vehicle_xyz_deg.2", -1.0),
    "gravity of the moon": _set("gravity.value_mps2", 1.62),
    "yaw without sigma": _set("uncertainty.yaw_deg", None),
    "yaw dropped but still determined": _set("mounting.yaw_deg", None),
    "quaternion of 3": _set("rotation.quaternion_xyzw", [0.0, 0.0, 1.0]),
    "residual row of 2": _set("stops.residual_s_mps2.0", [0.0, 0.0]),
    "boolean angle": _set("mounting.roll_deg", True),
    # the typed parts: their schema and their loader are both derived from the dataclasses
    "condition number as text": _set("observability.condition_number", "x"),
    "chi2 as text": _set("fit.chi2", "12.5"),
    "unknown key in the fit": _set("fit.chi_squared", 12.5),
    "dof as a float": _set("fit.dof", 3.5),
    "headings nobody defined": _set("fit.headings", "downhill"),
    "step without its angles": _set("model_steps.0.angles", None),
    "effect value as a number": _set("effects.0.value", 0.1),
    "declined effect without a reason": _set("model_selection.declined", [{"effect": "scale"}]),
    "fingerprint of 2 sums": _set("provenance.stops_fingerprint.acc_sum_mps2", [0.0, 9.8]),
    "finding without its test": _set("diagnostics.0", {"what": "x", "size": "y"}),
}
LOADER_ONLY = {"condition number below 1": _set("observability.condition_number", 0.5)}  # the schema leaves it open


def test_a_huge_but_finite_sigma_is_what_calibrate_may_write_and_loads_back(tmp_path: Path) -> None:
    """Three stops without headings at an odd orientation: σ of hundreds of degrees, not confident —
    honest, and a file both validators accept (the fuzzer found the loader refusing it)."""
    table = pd.DataFrame(
        {
            "beta_deg": [0.0, 120.0, 240.0],
            "ax": [-2.9, -2.2, -3.6],
            "ay": [8.1, 8.9, 8.6],
            "az": [-4.7, -3.9, -3.1],
        }
    )
    table.to_csv(tmp_path / "s.csv", index=False)
    assert main(["calibrate", str(tmp_path / "s.csv"), "--headings", "none", "-o", str(tmp_path / "r.json")]) == 0
    doc = json.loads((tmp_path / "r.json").read_text())
    doc["uncertainty"]["roll_deg"] = doc["uncertainty"]["rotation_about_vehicle_xyz_deg"][1] = 483.65
    jsonschema.validate(doc, schema())
    assert not Calibration.from_dict(doc, "huge.json").confident


@pytest.mark.parametrize("tamper", list(SCHEMA_VISIBLE), ids=list(SCHEMA_VISIBLE))
def test_schema_visible_tampering_is_refused_by_both_validators(made: dict[str, Path], tamper: str) -> None:
    doc = json.loads(made["bias"].read_text())
    SCHEMA_VISIBLE[tamper](doc)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(doc, schema())
    with pytest.raises(InputError, match="re-create it with `mountcal calibrate`"):
        Calibration.from_dict(doc, "tampered.json")


def test_a_field_the_report_formats_is_checked_too(made: dict[str, Path]) -> None:
    for change in LOADER_ONLY.values():
        doc = json.loads(made["auto"].read_text())
        change(doc)
        jsonschema.validate(doc, schema())
        with pytest.raises(InputError, match="condition_number"):
            Calibration.from_dict(doc, "tampered.json")


def test_the_published_schema_follows_the_result_types() -> None:
    """The typed parts of the schema are generated from the dataclasses: a field added, removed or
    retyped without regenerating (``python -m mountcal.core.result``) fails here."""
    published, derived = schema(), schema_defs()
    assert published["$defs"] == derived["$defs"]
    for name, part in derived["properties"].items():
        assert published["properties"][name] == part, name
    assert set(derived["properties"]) >= {"fit", "observability", "model_selection", "provenance", "model_steps"}


def test_a_result_round_trips_through_its_json_unchanged(made: dict[str, Path]) -> None:
    for name in ("auto", "bias", "paper", "none"):
        cal = Calibration.load(made[name])
        again = Calibration.from_dict(json.loads(json.dumps(cal.to_dict())))
        before, after = cal.to_dict(), again.to_dict()
        assert np.allclose(before.pop("rotation")["matrix_vs"], after.pop("rotation")["matrix_vs"], atol=1e-15)
        assert after == before
        assert again.fit == cal.fit and again.model_steps == cal.model_steps and again.provenance == cal.provenance


def test_a_format_1_file_is_refused_saying_which_version_and_what_to_do(made: dict[str, Path]) -> None:
    doc = json.loads(made["auto"].read_text())
    doc["format_version"] = 1
    with pytest.raises(InputError, match="format_version 1") as err:
        Calibration.from_dict(doc, "old.json")
    assert "Re-run `mountcal calibrate`" in str(err.value) and f"format_version {FORMAT_VERSION}" in str(err.value)


def test_the_schema_check_of_every_test_finds_an_invalid_result(
    made: dict[str, Path], tmp_path: Path, check_results: Callable[[list[Path]], list[str]]
) -> None:
    """The autouse fixture (tests/conftest.py) runs this check after every test: it must see a bad
    result anywhere under the folder, and pass a good one."""
    good = json.loads(made["bias"].read_text())
    (tmp_path / "deep" / "er").mkdir(parents=True)
    (tmp_path / "deep" / "er" / "good.json").write_text(json.dumps(good))
    (tmp_path / "other.json").write_text(json.dumps({"format": "something else"}))
    assert check_results([tmp_path]) == []
    bad = json.loads(json.dumps(good))
    bad["fit"]["chi2"] = "12.5"
    (tmp_path / "deep" / "bad.json").write_text(json.dumps(bad))
    problems = check_results([tmp_path])
    assert len(problems) == 1 and "bad.json" in problems[0] and "fit/chi2" in problems[0]
    (tmp_path / "deep" / "bad.json").unlink()  # leave only valid results for the fixture itself


def test_a_test_that_writes_an_invalid_result_fails(made: dict[str, Path], pytester: pytest.Pytester) -> None:
    """The autouse fixture end to end: in a session with this conftest, a test that writes an invalid
    result errors at teardown, one that writes a valid one passes, and the marker opts out."""
    good = made["bias"].read_text()
    bad = json.loads(good)
    bad["fit"]["dof"] = "many"
    pytester.makeconftest((Path(__file__).parent / "conftest.py").read_text())
    pytester.makepyfile(
        test_inner=f"""
import pytest

def test_valid(tmp_path):
    (tmp_path / "r.json").write_text({good!r})

def test_invalid(tmp_path):
    (tmp_path / "r.json").write_text({json.dumps(bad)!r})

@pytest.mark.invalid_results
def test_invalid_on_purpose(tmp_path):
    (tmp_path / "r.json").write_text({json.dumps(bad)!r})
"""
    )
    outcome = pytester.runpytest_inprocess("-p", "no:cacheprovider")
    outcome.assert_outcomes(passed=3, errors=1)
    outcome.stdout.fnmatch_lines(["*results not valid against the published schema*", "*fit/dof*"])


def _rotated_quaternion(doc: Doc) -> None:
    q = np.array(doc["rotation"]["quaternion_xyzw"])
    q = np.array([q[0] + 0.05, q[1], q[2], q[3]])  # about 6° away from the stored angles
    doc["rotation"]["quaternion_xyzw"] = (q / np.linalg.norm(q)).tolist()
    doc["rotation"].pop("matrix_vs")


def test_a_quaternion_that_contradicts_the_angles_is_refused(made: dict[str, Path]) -> None:
    for name in ("auto", "none"):  # yaw determined: the whole rotation; undetermined: the tilt
        doc = json.loads(made[name].read_text())
        _rotated_quaternion(doc)
        jsonschema.validate(doc, schema())  # beyond what JSON Schema can state
        with pytest.raises(InputError, match="away from the rotation of mounting roll/pitch/yaw"):
            Calibration.from_dict(doc, name)


def test_a_tiny_change_of_angle_within_the_tolerance_is_accepted_and_beyond_it_refused(made: dict[str, Path]) -> None:
    doc = json.loads(made["auto"].read_text())
    near, far = copy.deepcopy(doc), copy.deepcopy(doc)
    near["mounting"]["roll_deg"] += 1e-8
    far["mounting"]["roll_deg"] += 1e-4
    Calibration.from_dict(near, "near")
    with pytest.raises(InputError):
        Calibration.from_dict(far, "far")


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _tampered(path: str, value: Any, literal: str | None = None) -> Callable[[str], str]:
    """The document with ``path`` set to ``value`` (or to the raw JSON text ``literal``)."""

    def edit(text: str) -> str:
        doc = json.loads(text)
        _set(path, "@@" if literal else value)(doc)
        out = json.dumps(doc)  # Python writes NaN as the literal NaN, as a careless tool would
        return out.replace('"@@"', literal) if literal else out

    return edit


TEXT_TAMPERING = {
    "nan-bias": _tampered("bias_mps2.0", float("nan")),
    "nan-roll": _tampered("mounting.roll_deg", float("nan")),
    "infinite-bias": _tampered("bias_mps2.1", None, literal="Infinity"),
    "overflowing-roll": _tampered("mounting.roll_deg", None, literal="1e400"),
    "huge-bias": _tampered("bias_mps2.0", 1e308),
    "string-roll": _tampered("mounting.roll_deg", "5.0"),
    "two-element-bias": _tampered("bias_mps2", [0.1, 0.2]),
}


@pytest.mark.parametrize("tamper", list(TEXT_TAMPERING), ids=list(TEXT_TAMPERING))
@pytest.mark.parametrize("command", ["rotate", "report"])
def test_rotate_and_report_refuse_a_tampered_file_and_write_nothing(
    made: dict[str, Path], tamper: str, command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = _write(made["dir"] / f"bad_{tamper}.json", TEXT_TAMPERING[tamper](made["bias"].read_text()))
    out = made["dir"] / ("rotated.parquet" if command == "rotate" else "bad.html")
    args = (
        ["rotate", str(made["stops"]), "--calibration", str(bad), "-o", str(out)]
        if command == "rotate"
        else ["report", str(bad), "-o", str(out)]
    )
    code, _, err = run(args, capsys)
    assert code == 2 and "Traceback" not in err
    assert str(bad) in err and not out.exists()


def test_a_200000_deep_array_is_refused_without_recursion(
    made: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    deep = _write(made["dir"] / "deep.json", "[" * 200_000 + "]" * 200_000)
    code, _, err = run(["report", str(deep), "-o", str(made["dir"] / "deep.html")], capsys)
    assert code == 2 and f"nested at most {setting('depth')} levels" in err and "200000 levels" in err
    brackets_in_strings = _write(made["dir"] / "strings.json", json.dumps({"a": "[" * 1000, "format": "x"}))
    with pytest.raises(InputError, match="format"):  # depth 1: parsed, then refused as no calibration
        Calibration.load(brackets_in_strings)
    assert read_json(brackets_in_strings)["a"] == "[" * 1000


def test_an_untouched_result_still_rotates(made: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    out = made["dir"] / "ok.csv"
    rows = ["--columns", "time=t_s,ax=ax,ay=ay,az=az"]  # a stop table's rows rotated as samples: said so
    argv = ["rotate", str(made["stops"]), *rows, "--calibration", str(made["bias"]), "-o", str(out)]
    code, _, err = run(argv, capsys)
    assert code == 0, err
    assert np.isfinite(pd.read_csv(out).select_dtypes("number").to_numpy()).all()


# ------------------------------------------------------------------ report --stops


def test_report_stops_refuses_another_table_of_the_same_length(
    made: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert len(pd.read_csv(made["stops"])) == len(pd.read_csv(made["other"]))
    html = made["dir"] / "r.html"
    code, _, err = run(["report", str(made["auto"]), "--stops", str(made["other"]), "-o", str(html)], capsys)
    assert code == 2 and "a different table" in err and not html.exists()
    shuffled = made["dir"] / "shuffled.csv"
    pd.read_csv(made["stops"]).iloc[::-1].to_csv(shuffled, index=False)  # same stops, other order
    code, _, err = run(["report", str(made["auto"]), "--stops", str(shuffled), "-o", str(html)], capsys)
    assert code == 2 and "a different table" in err


def test_report_stops_accepts_the_same_stops_in_another_format(
    made: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    as_parquet = made["dir"] / "s.parquet"
    pd.read_csv(made["stops"]).to_parquet(as_parquet)
    html = made["dir"] / "same.html"
    code, out, err = run(["report", str(made["auto"]), "--stops", str(as_parquet), "-o", str(html)], capsys)
    assert code == 0, err
    assert "pass --stops" not in out and html.exists()


# ------------------------------------------------------------------ terminal output


def test_control_and_bidi_characters_are_shown_escaped() -> None:
    assert safe("imu\x1b]0;owned\x07/acc\u202egnp.exe") == "imu\\x1b]0;owned\\x07/acc\\u202egnp.exe"
    assert safe("a\nb", keep="\n") == "a\nb" and safe("a\nb") == "a\\x0ab"
    assert safe("Beschleunigung α ±") == "Beschleunigung α ±"  # printable text is untouched


def test_inspect_escapes_names_from_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from mcap.writer import Writer

    topic = "/imu\x1b[2J\u202etxt.exe"
    path = tmp_path / "hostile.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        schema_id = w.register_schema("evil\x1b[31m", "jsonschema", b"{}")
        channel = w.register_channel(topic, "json", schema_id)
        for i in range(3):
            w.add_message(channel, log_time=i * 10**9, publish_time=i * 10**9, data=b"{}")
        w.finish()
    code, out, err = run(["inspect", str(path)], capsys)
    assert code == 0, err
    assert out == ""  # the listing is the command's summary, on stderr
    assert "\x1b" not in err and "\u202e" not in err
    assert "/imu\\x1b[2J\\u202etxt.exe" in err


def test_huge_stop_values_get_no_unit_advice(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = tmp_path / "huge.csv"
    assert main(["simulate", "-o", str(table)]) == 0
    df = pd.read_csv(table)
    df.loc[2, ["ax", "ay"]] = 1e308
    df.to_csv(table, index=False)
    capsys.readouterr()
    for unit in (["--unit", "g"], []):
        code, _, err = run(["calibrate", str(table), *unit], capsys)
        assert code == 2 and "no static reading in either unit" in err
    code, _, err = run(["calibrate", str(table)], capsys)
    assert "add --unit g" not in err
