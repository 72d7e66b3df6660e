"""The result is typed end to end (#24): no ``Any`` and no ``dict[str, Any]`` anywhere in the dataclasses a
:class:`~mountcal.core.result.Calibration` holds; a result file of format version 2 still loads, its driving fit and
combination as the typed records; the report takes the Calibration."""

from __future__ import annotations

import ast
import dataclasses
import json
import re
import types
from dataclasses import replace
from pathlib import Path
from typing import Any, Union, get_args, get_origin, get_type_hints

import pytest

from mountcal.core.angles import ANGLE_NAMES, AngleValues
from mountcal.core.driving_document import Combination, DrivingDocument, TiltCheck
from mountcal.core.errors import InputError
from mountcal.core.result import FORMAT_VERSION, Angles, Calibration, Declined
from mountcal.core.result_file import schema

DATA = Path(__file__).parent / "data"

# Fields that are not (yet) typed records, each with the reason. Nothing of the driving half is here.
ALLOWED: dict[str, str] = {}


def _walk(tp: Any, where: str, seen: set[type], found: list[str]) -> None:
    if tp is Any:
        found.append(where)
        return
    origin, args = get_origin(tp), get_args(tp)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if tp in seen:
            return
        seen.add(tp)
        for name, hint in get_type_hints(tp).items():
            _walk(hint, f"{tp.__name__}.{name}", seen, found)
        return
    if origin in (Union, types.UnionType, tuple, dict, list):
        for a in args:
            if a is not Ellipsis:
                _walk(a, where, seen, found)


def test_the_result_holds_no_any_and_no_untyped_dict() -> None:
    found: list[str] = []
    _walk(Calibration, "Calibration", set(), found)
    assert sorted(set(found)) == sorted(ALLOWED), (
        f"untyped fields in the result: {sorted(set(found) - set(ALLOWED))}; "
        f"allowed but now typed (drop from ALLOWED): {sorted(set(ALLOWED) - set(found))}"
    )
    hints = get_type_hints(Calibration)
    fit = get_type_hints(hints["fit"])
    assert fit["driving"] == DrivingDocument | None and fit["combination"] == Combination | None


@pytest.mark.parametrize("name", ["result_v2_stops_and_driving.json", "result_v2_driving.json"])
def test_a_version_2_result_file_loads_with_its_driving_fit_typed(name: str, tmp_path: Path) -> None:
    """Files written by mountcal before the driving half was typed (stored as written): same layout, same version."""
    doc = json.loads((DATA / name).read_text(encoding="utf-8"))
    assert doc["format_version"] == 2 == FORMAT_VERSION  # the layout did not change: no new version
    cal = Calibration.load(DATA / name)
    driving = cal.fit.driving
    assert isinstance(driving, DrivingDocument) and driving.segments > 10 and driving.consistency is not None
    assert driving.yaw_deg == pytest.approx(doc["fit"]["driving"]["yaw_deg"])
    assert driving.gates.min_speed_mps == doc["fit"]["driving"]["gates"]["min_speed_mps"]
    if name == "result_v2_stops_and_driving.json":
        c = cal.fit.combination
        assert isinstance(c, Combination) and c.used == doc["fit"]["combination"]["used"]
        assert isinstance(c.tilt_check, TiltCheck) and c.yaw_deg == pytest.approx(cal.yaw_deg)
    # and what this version writes from it reads back the same
    out = tmp_path / "again.json"
    cal.save(out)
    assert Calibration.load(out).fit == cal.fit


def test_a_version_2_driving_fit_without_the_later_keys_still_loads(tmp_path: Path) -> None:
    """Early v2 files lack the residual tests, the model-error σ and the horizontal-axes gate: they default."""
    doc = json.loads((DATA / "result_v2_driving.json").read_text(encoding="utf-8"))
    driving = doc["fit"]["driving"]
    del driving["consistency"], driving["sigma"]["yaw_model_error_deg"], driving["gates"]["horizontal_axes_sigma_deg"]
    old = tmp_path / "early_v2.json"
    old.write_text(json.dumps(doc), encoding="utf-8")
    fit = Calibration.load(old).fit.driving
    assert fit is not None and fit.consistency is None and fit.gates.horizontal_axes_sigma_deg is None


@pytest.mark.invalid_results
def test_a_driving_fit_with_a_key_no_version_wrote_is_refused_naming_it(tmp_path: Path) -> None:
    doc = json.loads((DATA / "result_v2_driving.json").read_text(encoding="utf-8"))
    doc["fit"]["driving"]["made_up"] = 1.0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(InputError, match=r"fit\.driving has unknown keys made_up"):
        Calibration.load(bad)


def test_the_published_schema_describes_the_driving_fit_and_the_combination() -> None:
    defs = schema()["$defs"]
    assert {"DrivingDocument", "Combination", "TiltCheck", "DrivingSigma", "DrivingGates"} <= set(defs)
    driving = defs["FitQuality"]["properties"]["driving"]
    assert driving == {"anyOf": [{"$ref": "#/$defs/DrivingDocument"}, {"type": "null"}]}
    assert defs["DrivingDocument"]["additionalProperties"] is False


def test_declined_effects_are_typed_from_the_loop_on() -> None:
    from mountcal.calibration.fit import calibrate
    from mountcal.loop.steps import Loop

    assert get_type_hints(Loop)["declined"] == list[Declined]
    from mountcal.simulate.stops import simulate_stops

    cal = calibrate(simulate_stops(seed=5, slope_deg=12.0)[0])
    assert all(isinstance(d, Declined) for d in cal.model_selection.declined)


def test_a_yaw_or_slope_is_never_a_number_without_its_sigma() -> None:
    ok = Angles(1.0, 0.1, 2.0, 0.1, None, None, "relative headings", 5.0, 0.2)
    assert not ok.yaw_determined
    with pytest.raises(ValueError, match="without its σ"):
        Angles(1.0, 0.1, 2.0, 0.1, 30.0, None, None, 5.0, 0.2)
    with pytest.raises(ValueError, match="undetermined"):
        Angles(1.0, 0.1, 2.0, 0.1, None, 0.3, "why", 5.0, 0.2)
    with pytest.raises(ValueError, match="slope"):
        Angles(1.0, 0.1, 2.0, 0.1, None, None, "why", 5.0, None)


def test_a_result_whose_yaw_has_no_sigma_is_refused() -> None:
    from mountcal.calibration.fit import calibrate
    from mountcal.simulate.stops import simulate_stops

    doc = calibrate(simulate_stops(seed=5, slope_deg=12.0)[0]).to_dict()  # uphill headings: yaw determined
    step = doc["model_steps"][0]["angles"]
    assert step["yaw_deg"] is not None
    step["yaw_sigma_deg"] = None
    with pytest.raises(InputError, match="without its σ"):
        Calibration.from_dict(doc)


def test_the_report_takes_the_calibration_never_a_dict() -> None:
    pytest.importorskip("matplotlib")
    from mountcal.outputs.report import render

    cal = Calibration.load(DATA / "result_v2_stops_and_driving.json")
    assert "stops + driving" in render(cal)
    with pytest.raises(TypeError, match="takes a Calibration"):
        render(cal.to_dict())  # type: ignore[arg-type]


def test_the_driving_gates_record_every_driving_option() -> None:
    from mountcal.core.driving_document import DrivingGates
    from mountcal.estimate.driving_options import DrivingOptions

    assert [f.name for f in dataclasses.fields(DrivingGates)] == [f.name for f in dataclasses.fields(DrivingOptions)]


# --- one spelling of the angles' flat columns (#24) -------------------------------------------------------------

SRC = Path(__file__).parent.parent / "src" / "mountcal"
# the flat names of the angles ± σ as strings (a dict's keys, a table's columns); "slope_deg" alone is also the
# site's slope a simulation or a plan is given, so it is not listed: the σ and the others give a new spelling away
FLAT_NAME = re.compile(
    r"^((roll|pitch|yaw)_deg|(roll|pitch|yaw|slope)_sigma_deg|sigma_(roll|pitch|yaw|slope)|yaw_reason)$"
)
# modules that may spell them, each with the reason: the formats' own converters, and values that are no angles ± σ
SPELLED: dict[str, str] = {
    "core/angles.py": "the type itself: Angles.columns / from_columns / column_names, the one spelling",
    "core/result.py": "the v2 result file (its mounting/uncertainty fields): Calibration.to_dict / from_dict",
    "core/result_file.py": "the v2 result file's checks (types, ranges) before it is read",
    "simulate/stops.py": "a simulation's true mounting: no σ (a true value has none)",
    "simulate/session.py": "a simulated session's true mounting, as its truth file holds it: no σ",
    "cli/simulate.py": "the options of a simulation's true mounting: no σ",
}
# dicts keyed by the angles' names that are not angles ± σ
NAMED: dict[str, str] = {
    "core/angles.py": "the type's own accessors",
    "outputs/report/html.py": "the meaning of each angle (text), for the report's table",
    "outputs/exporters/ublox.py": "the u-blox keys' own Euler angles (another convention, a device format)",
    "sessions/live.py": "the default target of `mountcal live` (the option's spelling: roll=σ,pitch=σ,yaw=σ)",
}


def _spellings(tree: ast.AST) -> list[str]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and FLAT_NAME.match(node.value):
            found.append(f"{node.value!r} (line {node.lineno})")
        # f"{name}_deg", f"{name}_sigma_deg": the flat names built from the angle's name
        if isinstance(node, ast.JoinedStr) and len(node.values) >= 2 and isinstance(node.values[0], ast.FormattedValue):
            rest = node.values[1]
            if isinstance(rest, ast.Constant) and rest.value in ("_deg", "_sigma_deg"):
                found.append(f"f'{{…}}{rest.value}' (line {node.lineno})")
    return found


def _named_dicts(tree: ast.AST) -> list[str]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            keys = {k.value for k in node.keys if isinstance(k, ast.Constant) and isinstance(k.value, str)}
            if {"roll", "pitch"} <= {k.lower() for k in keys}:
                found.append(f"a dict keyed {sorted(keys)} (line {node.lineno})")
    return found


def test_the_angles_flat_names_are_spelled_only_by_the_type_and_the_formats() -> None:
    """A new dict of the angles ± σ, or a new table or message writing them column by column, fails here: pass an
    Angles (or AngleValues), and write a format's columns with Angles.columns / from_columns."""
    spelled, named = {}, {}
    for path in sorted(SRC.rglob("*.py")):
        where = path.relative_to(SRC).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if where not in SPELLED and (found := _spellings(tree)):
            spelled[where] = found
        if where not in NAMED and (found := _named_dicts(tree)):
            named[where] = found
    assert not spelled, f"the angles' flat names spelled outside the type and the formats: {spelled}"
    assert not named, f"dicts of the angles by name (use Angles / AngleValues): {named}"
    stale = [m for m in (*SPELLED, *NAMED) if not (SRC / m).exists()]
    assert not stale, f"allowed modules that no longer exist: {stale}"


def test_the_scan_finds_a_dict_spelling() -> None:
    """The scan above would see the spellings it forbids."""
    tree = ast.parse('d = {"roll_sigma_deg": 1.0}\nname = "yaw"\nk = f"{name}_sigma_deg"\ne = {"roll": 1, "pitch": 2}')
    assert len(_spellings(tree)) == 2 and len(_named_dicts(tree)) == 1


def test_the_columns_of_the_angles_round_trip() -> None:
    full = Angles(1.5, 0.1, -2.0, 0.2, 30.0, 0.5, None, 4.0, 0.05)
    cols = full.columns()
    assert tuple(cols) == Angles.column_names()
    assert cols["roll_sigma_deg"] == 0.1 and cols["yaw_reason"] is None and cols["slope_sigma_deg"] == 0.05
    assert Angles.from_columns(cols) == full
    no_yaw = Angles(1.5, 0.1, -2.0, 0.2, None, None, "level ground", None, None)
    assert Angles.from_columns(no_yaw.columns()) == no_yaw
    drive = no_yaw.columns(slope=False)  # the fleet's consensus tables and live's events have no slope
    assert "slope_deg" not in drive and Angles.from_columns(drive) == no_yaw
    assert tuple(no_yaw.columns(slope=False, reason=False)) == Angles.column_names(slope=False, reason=False)
    # a table's missing cells are NaN: read as None
    nan = float("nan")
    row = {**no_yaw.columns(), "yaw_deg": nan, "yaw_sigma_deg": nan, "slope_deg": nan, "slope_sigma_deg": nan}
    assert Angles.from_columns(row) == no_yaw


def test_columns_the_type_refuses_are_refused_when_read() -> None:
    good = Angles(1.0, 0.1, 2.0, 0.1, 30.0, 0.5, None, 4.0, 0.2).columns()
    with pytest.raises(ValueError, match="without its σ"):
        Angles.from_columns({**good, "yaw_sigma_deg": float("nan")})
    with pytest.raises(ValueError, match="slope"):
        Angles.from_columns({**good, "slope_sigma_deg": None})
    with pytest.raises(ValueError, match="without roll or pitch"):
        Angles.from_columns({k: v for k, v in good.items() if k != "roll_deg"})


def test_a_calibration_takes_its_angles_as_one_value() -> None:
    cal = Calibration.load(DATA / "result_v2_driving.json")
    moved = replace(cal.angles, roll_deg=cal.roll_deg + 1.0, roll_sigma_deg=0.25)
    again = cal.with_angles(moved)
    assert again.angles == moved and again.roll_deg == cal.roll_deg + 1.0 and again.rot_vs is cal.rot_vs
    assert again.angles.widened(2.0).roll_sigma_deg == 0.5 and again.angles.widened(2.0).roll_deg == again.roll_deg
    with pytest.raises(ValueError, match="roll or pitch without its σ"):
        Calibration.angle_fields(replace(moved, roll_sigma_deg=None))


def test_the_formats_read_their_angles_with_the_type() -> None:
    """The v2 file's driving fit, its systematic parts, and the fleet tables' columns all go through the type."""
    from mountcal.core.result import Systematic
    from mountcal.fleet import store

    doc = json.loads((DATA / "result_v2_driving.json").read_text(encoding="utf-8"))
    cal = Calibration.load(DATA / "result_v2_driving.json")
    assert cal.fit.driving is not None
    drive = cal.fit.driving.angles
    assert drive.roll_deg == doc["fit"]["driving"]["roll_deg"] and drive.slope_deg is None
    assert drive.roll_sigma_deg == doc["fit"]["driving"]["sigma"]["roll_deg"]
    part = Systematic.part(AngleValues(0.1, 0.2, None, 0.3), (0.4, 0.5, None))
    assert part == {
        "roll_deg": 0.1,
        "pitch_deg": 0.2,
        "yaw_deg": None,
        "slope_deg": 0.3,
        "rotation_x_deg": 0.4,
        "rotation_y_deg": 0.5,
        "rotation_z_deg": None,
    }
    assert Systematic.angles_of(part) == AngleValues(0.1, 0.2, None, 0.3)
    assert Systematic.rotation_of(part) == (0.4, 0.5, None)
    for columns, slope in ((store.LOG_COLUMNS, True), (store.MOUNTING_COLUMNS, False), (store.VEHICLE_COLUMNS, False)):
        names = [c[0] for c in columns]
        first = names.index("roll_deg")
        assert tuple(names[first : first + len(Angles.column_names(slope=slope))]) == Angles.column_names(slope=slope)


def test_one_value_per_angle_by_name() -> None:
    v = AngleValues(0.1, 0.2, None, 0.4)
    assert v["roll"] == v["roll_deg"] == 0.1 and v["yaw"] is None and v.get("bias") is None
    with pytest.raises(KeyError):
        v["bias_deg"]
    assert v.named() == {"roll": 0.1, "pitch": 0.2, "yaw": None, "slope": 0.4}
    assert v.times(2.0) == AngleValues(0.2, 0.4, None, 0.8)
    a = Angles(1.0, 0.1, 2.0, 0.2, None, None, "why", 3.0, 0.3)
    assert a.values == AngleValues(1.0, 2.0, None, 3.0) and a.sigmas == AngleValues(0.1, 0.2, None, 0.3)
    assert [a.value(n) for n in ANGLE_NAMES] == [1.0, 2.0, None, 3.0]
