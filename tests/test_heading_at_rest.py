"""A heading channel that is a course over ground: empty at rest (an iPhone's bearing of −1, an empty RMC field)
or held at one value. Read at rest it gave no headings (yaw lost, the log said to have no heading channel) or one
heading for every stop (refused as parked at one heading); the course before each stop, carried to it by the
gyro, gives the stops their headings, and the answer says so."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.cli import main
from mountcal.core.conventions import angles_from_rot_vs
from mountcal.simulate.stops import simulate_parking_log

MOUNT = (-4.0, 7.0, 123.0)


def _log(path: Path, at_rest: float | None, speed: bool = True, seed: int = 3) -> tuple[Path, float]:
    """A parking session on a 9° slope as a sample table, its heading channel ``at_rest`` (NaN: empty) while
    parked (None: the true heading), and the true yaw."""
    park = simulate_parking_log(*MOUNT, slope_deg=9.0, seed=seed)
    heading = park.heading_deg.copy()
    if at_rest is not None:
        heading[park.speed_mps < 0.2] = at_rest
    frame = pd.DataFrame(
        {
            "t_s": park.t_s,
            **{f"a{k}": park.acc_s[:, i] for i, k in enumerate("xyz")},
            **{f"g{k}": park.gyro_s[:, i] for i, k in enumerate("xyz")},
            "heading_deg": heading,
            **({"speed_mps": park.speed_mps} if speed else {}),
        }
    )
    frame.to_parquet(path, index=False)
    return path, float(np.degrees(angles_from_rot_vs(park.truth.rot_vs))[2])


def _calibrate(log: Path, out: Path) -> dict:  # type: ignore[type-arg]
    assert main(["calibrate", str(log), "--uphill-azimuth-deg", "30", "-o", str(out)]) == 0
    return json.loads(out.read_text(encoding="utf-8"))  # type: ignore[no-any-return]


def _convention(doc: dict, name: str) -> dict | None:  # type: ignore[type-arg]
    return next((c for c in doc["provenance"]["conventions"] if c["name"] == name), None)


@pytest.mark.parametrize(("at_rest", "speed"), [(np.nan, True), (0.0, True), (0.0, False), (217.0, True)])
def test_a_course_over_ground_gives_the_stops_their_headings(tmp_path: Path, at_rest: float, speed: bool) -> None:
    log, yaw = _log(tmp_path / "log.parquet", at_rest, speed)
    doc = _calibrate(log, tmp_path / "r.json")
    read = _convention(doc, "heading_at_stops")
    assert read is not None and read["how"] == "inferred" and read["value"] == "course before the stop"
    assert "empty at 12 of 12 stops" in read["by"] if np.isnan(at_rest) else f"one value ({at_rest:.1f}°)" in read["by"]
    assert "1 stop(s) without a course before them set aside" in read["by"]  # the log begins at the first stop
    m, u = doc["mounting"], doc["uncertainty"]
    assert abs(m["yaw_deg"] - yaw) < 3.0 * u["yaw_deg"] + 0.3
    assert abs(m["roll_deg"] - MOUNT[0]) < 3.0 * u["roll_deg"] and abs(m["pitch_deg"] - MOUNT[1]) < 3.0 * u["pitch_deg"]


def test_a_heading_channel_that_moves_with_the_vehicle_at_rest_is_read_at_rest(tmp_path: Path) -> None:
    log, yaw = _log(tmp_path / "log.parquet", None)
    doc = _calibrate(log, tmp_path / "r.json")
    assert _convention(doc, "heading_at_stops") is None
    assert abs(doc["mounting"]["yaw_deg"] - yaw) < 3.0 * doc["uncertainty"]["yaw_deg"]


def test_a_heading_channel_empty_everywhere_says_so_and_which_option_went_unused(tmp_path: Path) -> None:
    """Not "no heading channel in the log": the channel is there, it gives nothing to read."""
    log, _ = _log(tmp_path / "log.parquet", np.nan)
    frame = pd.read_parquet(log)
    frame.loc[frame.index[::2], "heading_deg"] = np.nan  # while moving too: no course to take either
    frame.loc[frame["speed_mps"] >= 0.2, "heading_deg"] = np.nan
    frame.loc[frame.index[:5], "heading_deg"] = 10.0  # one value somewhere, so the column is read
    frame.to_parquet(log, index=False)
    doc = _calibrate(log, tmp_path / "r.json")
    ref = _convention(doc, "heading_reference")
    assert ref is not None and ref["value"] == "none"
    assert "heading channel at rest is empty" in ref["by"] and "--uphill-azimuth-deg 30 left unused" in ref["by"]
    assert "no heading channel in the log" not in ref["by"]
    assert doc["mounting"]["yaw_deg"] is None
