"""The samples' frame and axis map, carried wherever they go after mountcal rotate or --axes.

A triad calibration describes the sensor's own axes: fitting one on samples mountcal rotate put in the
vehicle frame, or applying one to them, is refused (a triad of the vehicle's axes corrects the wrong
axes, silently). A stop table of such samples says its frame in a ``frame`` column, so the refusal and
the calibration's note survive the table. A triad states the axis map of its session, and applying it
to stops read with another map is refused. A calibration of rotated samples measures the rotation left
over: applying it to a log, or exporting it as the sensor's mounting, is refused.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from tests.conftest import Refused

from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.conventions import G_N
from mountcal.core.errors import InputError
from mountcal.estimate.triad import Triad, load
from mountcal.stops.table import read_stop_table

DATA = Path(__file__).resolve().parents[1] / "data"
LOG, SHEET = DATA / "parking.mcap", DATA / "parking_protocol.csv"


@pytest.fixture(scope="module")
def rotated(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The sample log, its calibration, the log rotated by it (Parquet) and the stop tables of both."""
    d = tmp_path_factory.mktemp("rotated")
    paths = {k: d / n for k, n in [("cal", "r.json"), ("veh", "veh.parquet"), ("stops", "s.csv"), ("raw", "raw.csv")]}
    assert main(["calibrate", str(LOG), "--protocol", str(SHEET), "-o", str(paths["cal"]), "-q"]) == 0
    assert main(["rotate", str(LOG), "--calibration", str(paths["cal"]), "-o", str(paths["veh"]), "-q"]) == 0
    assert main(["stops", str(paths["veh"]), "--protocol", str(SHEET), "-o", str(paths["stops"]), "-q"]) == 0
    assert main(["stops", str(LOG), "--protocol", str(SHEET), "-o", str(paths["raw"]), "-q"]) == 0
    return paths


def _triad_file(path: Path, axes: str | None = None) -> Path:
    """A small triad as `mountcal triad` writes it, its session read with ``axes``."""
    how = "default" if axes is None else "stated"
    by = "the axes as logged" if axes is None else "--axes"
    conventions = ({"name": "axes", "value": axes or "x,y,z", "how": how, "by": by},)
    triad = Triad(
        np.array([0.02, -0.01, 0.03]), np.array([1e-3, -2e-3, 5e-4, 1e-4, 0, -1e-4]), np.eye(9) * 1e-8, "test"
    )
    doc = {**triad.to_dict(), "conventions": list(conventions)}
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def test_a_triad_of_rotated_samples_is_refused_from_the_log_and_from_its_stop_table(
    refused: Refused, rotated: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "t.json"
    for source in (rotated["veh"], rotated["stops"]):
        err = refused(["triad", str(source), "-o", str(out)], out)
        assert str(source) in err and "vehicle frame" in err and "sensor's own axes" in err
        assert "Fit the triad on the original log" in err


def test_the_stop_table_of_rotated_samples_says_its_frame_and_calibrates_as_the_log_does(
    rotated: dict[str, Path], tmp_path: Path
) -> None:
    frames = {str(v) for v in read_csv_column(rotated["stops"], "frame")}
    assert len(frames) == 1 and frames.pop().startswith("vehicle (mountcal rotate's output; calibration from ")
    assert "frame" not in read_csv_header(rotated["raw"])  # a sensor-frame log's table has no such column
    docs = {}
    for name, argv in (
        ("log", [str(rotated["veh"]), "--protocol", str(SHEET)]),
        ("table", [str(rotated["stops"])]),
    ):
        assert main(["calibrate", *argv, "-o", str(tmp_path / f"{name}.json"), "-q"]) == 0
        docs[name] = json.loads((tmp_path / f"{name}.json").read_text(encoding="utf-8"))
    frame = {k: next(c for c in d["provenance"]["conventions"] if c["name"] == "frame") for k, d in docs.items()}
    assert frame["log"]["value"] == frame["table"]["value"]  # the calibration applied, said by both
    for doc in docs.values():
        assert sum("already in mountcal's vehicle frame" in n for n in doc["notes"]) == 1
        assert abs(doc["mounting"]["roll_deg"]) < 0.2 and abs(doc["mounting"]["pitch_deg"]) < 0.2  # what is left over
    for angle in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert docs["table"]["mounting"][angle] == pytest.approx(docs["log"]["mounting"][angle], abs=1e-6)


def test_a_frame_column_that_is_not_a_frame_mountcal_knows_is_refused(tmp_path: Path) -> None:
    table = tmp_path / "s.csv"
    lines = DATA.joinpath("zhang2011_stops.csv").read_text(encoding="utf-8").splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    rows = [lines[header] + ",frame"] + [line + ",imu_link" for line in lines[header + 1 :] if line.strip()]
    table.write_text("\n".join(rows) + "\n", encoding="utf-8")
    with pytest.raises(InputError, match="column frame"):
        read_stop_table(table)
    table.write_text("\n".join(r.replace(",imu_link", ",sensor") for r in rows) + "\n", encoding="utf-8")
    assert not any(c.name == "frame" for c in read_stop_table(table).conventions)  # the sensor's own axes


def test_applying_a_triad_to_rotated_stops_is_refused_by_the_command_and_the_library(
    refused: Refused, rotated: dict[str, Path], tmp_path: Path
) -> None:
    triad = _triad_file(tmp_path / "t.json")
    out = tmp_path / "r.json"
    for argv in ([str(rotated["veh"]), "--protocol", str(SHEET)], [str(rotated["stops"])]):
        err = refused(["calibrate", *argv, "--triad", str(triad), "-o", str(out)], out)
        assert "vehicle frame" in err and "--triad" in err
    with pytest.raises(InputError, match="sensor's own axes"):
        calibrate(read_stop_table(rotated["stops"]), Options(triad=load(triad)))
    # the same triad on the log it was made for (the sensor's frame) is applied
    assert main(["calibrate", str(LOG), "--protocol", str(SHEET), "--triad", str(triad), "-o", str(out), "-q"]) == 0


def test_a_calibration_of_rotated_samples_is_neither_applied_nor_exported(
    refused: Refused, rotated: dict[str, Path], tmp_path: Path
) -> None:
    from mountcal.apply.rotate import acc_to_vehicle, frame_to_vehicle
    from mountcal.core.result import Calibration
    from mountcal.outputs.exporters import builtin

    leftover = tmp_path / "leftover.json"
    assert main(["calibrate", str(rotated["stops"]), "-o", str(leftover), "-q"]) == 0
    out = tmp_path / "veh2.parquet"
    for extra in ([], ["--level-only"]):
        err = refused(["rotate", str(LOG), "--calibration", str(leftover), "-o", str(out), *extra], out)
        assert "rotation left over" in err and "calibration from" in err
    cal = Calibration.load(leftover)
    with pytest.raises(InputError, match="rotation left over"):
        acc_to_vehicle(np.zeros((2, 3)), cal)
    import pandas as pd

    with pytest.raises(InputError, match="rotation left over"):
        frame_to_vehicle(pd.DataFrame({"ax": [0.0], "ay": [0.0], "az": [G_N]}), cal)
    formats = builtin()
    assert len(formats) >= 10
    for name, exporter in formats.items():
        target = tmp_path / f"x{exporter.suffixes[0] if exporter.suffixes else '.out'}"
        err = refused(["export", str(leftover), "--to", name, "-o", str(target)], target)
        assert "rotation left over" in err, name
    # the calibration the rotation applied exports as ever
    assert main(["export", str(rotated["cal"]), "--to", "json", "-o", str(tmp_path / "ok.json"), "-q"]) == 0


def _session(path: Path, n: int = 40, seed: int = 3) -> Path:
    """A multi-position session's stop table: gravity along n directions of a sensor with bias and scale."""
    rng = np.random.default_rng(seed)
    up = Rotation.random(n, random_state=seed).apply([0.0, 0.0, G_N])
    matrix = np.eye(3) + np.diag([4e-3, -3e-3, 2e-3])
    acc = up @ matrix.T + np.array([0.05, -0.04, 0.08]) + rng.normal(0, 2e-4, (n, 3))
    cols = "ax,ay,az,sx,sy,sz,n"
    rows = [",".join(f"{v:.9g}" for v in (*a, 0.01, 0.01, 0.01, 2500)) for a in acc]
    path.write_text(cols + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(("made_with", "applied_with"), [("y,x,-z", None), (None, "y,x,-z"), ("y,x,-z", "-y,x,z")])
def test_a_triad_states_its_session_axes_and_other_axes_are_refused(
    refused: Refused,
    made_with: str | None,
    applied_with: str | None,
    tmp_path: Path,
) -> None:
    session, triad = _session(tmp_path / "session.csv"), tmp_path / "t.json"
    given = [] if made_with is None else ["--axes", made_with]
    assert main(["triad", str(session), "-o", str(triad), *given, "-q"]) == 0
    axes = [c for c in json.loads(triad.read_text(encoding="utf-8"))["conventions"] if c["name"] == "axes"]
    assert [c["value"].split(" ")[0] for c in axes] == [made_with or "x,y,z"]
    out = tmp_path / "r.json"
    applied = [] if applied_with is None else ["--axes", applied_with]
    err = refused(
        ["calibrate", str(LOG), "--protocol", str(SHEET), "--triad", str(triad), *applied, "-o", str(out)], out
    )
    assert "the triad calibration was made with" in err
    assert (f"--axes {made_with}" if made_with else "no --axes") in err
    # the map it was made with is accepted
    assert (
        main(["calibrate", str(LOG), "--protocol", str(SHEET), "--triad", str(triad), *given, "-o", str(out), "-q"])
        == 0
    )


def test_a_triad_file_with_conventions_that_do_not_parse_is_refused_naming_it(tmp_path: Path) -> None:
    path = _triad_file(tmp_path / "t.json")
    doc = json.loads(path.read_text(encoding="utf-8"))
    for bad in ([{"name": "axes", "value": "x,y,w", "how": "stated", "by": "--axes"}], [{"name": "axes"}], "x,y,z"):
        path.write_text(json.dumps({**doc, "conventions": bad}), encoding="utf-8")
        with pytest.raises(InputError, match=str(path)):
            load(path)
    del doc["conventions"]  # a triad written without them (by hand, or by another tool's converter) still loads
    path.write_text(json.dumps(doc), encoding="utf-8")
    assert load(path).conventions == ()


def read_csv_column(path: Path, column: str) -> list[str]:
    import pandas as pd

    return pd.read_csv(path, comment="#")[column].astype(str).tolist()


def read_csv_header(path: Path) -> list[str]:
    return next(line for line in path.read_text(encoding="utf-8").splitlines() if not line.startswith("#")).split(",")


def test_mountcal_s_own_answers_given_as_input_are_refused_saying_what_they_are(
    refused: Refused, rotated: dict[str, Path], tmp_path: Path
) -> None:
    """A fleet table, a calibration result, a triad JSON: recognised by their content, not their name."""
    fleet_dir = tmp_path / "fleet"
    (fleet_dir / "v01").mkdir(parents=True)
    shutil.copy(LOG, fleet_dir / "v01" / "s1.mcap")
    shutil.copy(SHEET, fleet_dir / "v01" / "s1.protocol.csv")
    table = tmp_path / "fleet.parquet"
    assert main(["fleet", str(fleet_dir), "-o", str(table), "-q", "--workers", "1"]) == 0
    triad = _triad_file(tmp_path / "t.json")
    out = tmp_path / "r.json"
    for given, said in ((table, "mountcal fleet wrote"), (rotated["cal"], "mountcal.calibration JSON"),
                        (triad, "mountcal.estimate.triad JSON")):  # fmt: skip
        for command in ("calibrate", "triad"):
            err = refused([command, str(given), "-o", str(out)], out)
            assert f"{given}: expected a log or a stop table, found a" in err and said in err, (command, given)
