"""The result is typed end to end (#24): no ``Any`` and no ``dict[str, Any]`` anywhere in the dataclasses a
:class:`~mountcal.core.result.Calibration` holds; a result file of format version 2 still loads, its driving fit and
combination as the typed records; the report takes the Calibration."""

from __future__ import annotations

import dataclasses
import json
import types
from pathlib import Path
from typing import Any, Union, get_args, get_origin, get_type_hints

import pytest

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
