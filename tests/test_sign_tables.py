"""A Sensor Logger recording's acceleration sign kept across the stop table (column ``acceleration_sign``) and
the triad: a stop table of an iOS recording calibrates as the recording does — the app's default turned round
where the stops' headings show it mirrored, not confident where nothing confirms it — and a triad fitted on a
default sign says so and refuses stops read with the other sign."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.conftest import Refused
from tests.test_sensor_logger import G_N, _assert_truth, _check, _protocol, _sign, record, session

from mountcal.cli import main
from mountcal.estimate.triad import load
from mountcal.simulate.stops import ParkingLog

__all__ = ["session"]  # the recording's fixture, shared with tests/test_sensor_logger.py

SETTING = "Standardise Units & Frames"


def _table(folder: Path, out: Path, *args: str) -> Path:
    assert main(["stops", str(folder), "-o", str(out), *args]) == 0
    return out


def _calibrated(table: Path, *args: str) -> dict:  # type: ignore[type-arg]
    out = table.with_suffix(".json")
    assert main(["calibrate", str(table), "-o", str(out), *args]) == 0
    return dict(json.loads(out.read_text()))


def _column(table: Path) -> str:
    frame = pd.read_parquet(table) if table.suffix == ".parquet" else pd.read_csv(table)
    values = set(frame["acceleration_sign"])
    assert len(values) == 1
    return str(values.pop())


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_an_ios_table_with_headings_is_turned_round_inferred_and_said(
    session: ParkingLog, tmp_path: Path, suffix: str
) -> None:
    """The setting on, no AccelerometerUncalibrated.csv: the table keeps the app's default (negated), its stops go
    round mirrored, and calibrating the table turns them round once — the right mounting, the sign inferred."""
    folder = record(tmp_path / "ios", session, "iOS", standardised=True)
    table = _table(folder, tmp_path / f"t{suffix}", "--protocol", str(_protocol(session, tmp_path / "p.csv")))
    assert _column(table).startswith("negated (") and "; default: the app's default" in _column(table)
    doc = _calibrated(table)
    sign = _sign(doc)
    assert (sign["how"], sign["value"].split()[0]) == ("inferred", "as")
    assert f"{SETTING}' was on" in sign["by"]
    assert _check(doc, "handedness_stops")["passed"] is True and _check(doc, "acceleration_sign")["passed"] is True
    assert any("means were turned round" in n for n in doc["notes"])
    _assert_truth(doc, session)
    assert doc["confident"]


def test_an_ios_table_without_headings_or_drive_is_not_confident_and_without_the_column_as_before(
    session: ParkingLog, tmp_path: Path
) -> None:
    """No headings, no drive: nothing can confirm the default, so the table's result is not confident, as the
    recording's is (with the setting on it is upside down). The same table without the column states no sign."""
    folder = record(tmp_path / "ios", session, "iOS", standardised=True, motion=False)
    table = _table(folder, tmp_path / "t.csv")
    doc = _calibrated(table)
    assert _sign(doc)["how"] == "default" and "column acceleration_sign" in _sign(doc)["by"]
    check = _check(doc, "acceleration_sign")
    assert check["passed"] is False and "AccelerometerUncalibrated" in check["reason"]
    assert not doc["confident"]
    bare = tmp_path / "bare.csv"
    pd.read_csv(table).drop(columns="acceleration_sign").to_csv(bare, index=False)
    before = _calibrated(bare)
    assert all(c["name"] != "acceleration_sign" for c in (*before["checks"], *before["provenance"]["conventions"]))
    assert before["confident"]


def test_an_android_table_states_its_sign(session: ParkingLog, tmp_path: Path) -> None:
    table = _table(record(tmp_path / "android", session, "Android"), tmp_path / "t.csv")
    assert _column(table).startswith("as logged (") and "; stated: " in _column(table)
    doc = _calibrated(table)
    assert _sign(doc)["how"] == "stated" and _check(doc, "acceleration_sign")["passed"] is True
    assert doc["confident"]


def test_a_sign_column_is_read_as_written_or_refused(session: ParkingLog, tmp_path: Path, refused: Refused) -> None:
    """A bare sign is stated by the column; anything that is no sign is refused naming the column."""
    table = _table(record(tmp_path / "android", session, "Android"), tmp_path / "t.csv")
    frame = pd.read_csv(table)
    frame.assign(acceleration_sign="negated").to_csv(tmp_path / "bare.csv", index=False)
    assert _sign(_calibrated(tmp_path / "bare.csv")) == {
        "name": "acceleration_sign",
        "value": f"negated (logged as the inertial force: iOS with '{SETTING}' off)",
        "how": "stated",
        "by": f"{tmp_path / 'bare.csv'}: column acceleration_sign",
    }
    frame.assign(acceleration_sign="upside down").to_csv(tmp_path / "bad.csv", index=False)
    err = refused(["calibrate", str(tmp_path / "bad.csv"), "-o", str(tmp_path / "bad.json")], tmp_path / "bad.json")
    assert "column acceleration_sign" in err and "'upside down'" in err


def test_a_triad_on_a_default_sign_says_so_and_refuses_stops_read_the_other_way(
    session: ParkingLog, tmp_path: Path, refused: Refused, capsys: pytest.CaptureFixture[str]
) -> None:
    """The sphere fit sees magnitudes only: a session negated in all three axes fits with the same scale and the
    bias negated (no negative determinant to detect). A triad fitted on the app's default sign says the bias rests
    on it; calibrating with it stops that the handedness check turned round (the setting was on) is refused."""
    rng = np.random.default_rng(7)
    up = rng.normal(size=(30, 3))
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    bias, matrix = np.array([0.2, -0.15, 0.3]), np.eye(3) + np.diag([0.02, -0.01, 0.015])
    true = (G_N * up) @ matrix.T + bias + rng.normal(scale=2e-3, size=up.shape)
    vehicle = _table(
        record(tmp_path / "ios", session, "iOS", standardised=True),
        tmp_path / "vehicle.csv",
        "--protocol",
        str(_protocol(session, tmp_path / "p.csv")),
    )
    triads = {}
    for name, sign, said in (("logged", 1.0, "as logged"), ("default", -1.0, _column(vehicle))):
        session_table = pd.DataFrame(sign * true, columns=["ax", "ay", "az"]).assign(sx=2e-3, sy=2e-3, sz=2e-3)
        session_table.assign(acceleration_sign=said).to_csv(tmp_path / f"{name}.csv", index=False)
        capsys.readouterr()
        assert main(["triad", str(tmp_path / f"{name}.csv"), "-o", str(tmp_path / f"{name}.json")]) == 0
        triads[name] = (load(tmp_path / f"{name}.json"), capsys.readouterr().err)
    (logged, _), (default, said) = triads["logged"], triads["default"]
    np.testing.assert_allclose(default.scale_e, logged.scale_e, atol=1e-9)
    np.testing.assert_allclose(default.bias_mps2, -logged.bias_mps2, atol=1e-9)
    sign = next(c for c in default.conventions if c.name == "acceleration_sign")
    assert sign.how == "default" and "the bias's sign rests on it" in said
    err = refused(
        ["calibrate", str(vehicle), "--triad", str(tmp_path / "default.json"), "-o", str(tmp_path / "v.json")],
        tmp_path / "v.json",
    )
    assert "triad" in err and SETTING in err and "acceleration_sign" in err
    # a triad whose sign is stated applies to those stops, turned round as without it
    assert _sign(_calibrated(vehicle, "--triad", str(tmp_path / "logged.json")))["how"] == "inferred"
