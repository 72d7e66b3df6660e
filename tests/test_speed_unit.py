"""A speed logged in km/h, mph or knots and read as m/s: the drive's speed scale names the unit, the angles stay."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mountcal.apply.rotate_log import to_frame
from mountcal.cli import main
from mountcal.estimate.speed_unit import MPS_PER, unit_of_scale
from mountcal.simulate.drive import simulate_drive


def test_a_unit_s_factor_is_named_and_a_tyre_s_few_per_cent_is_not() -> None:
    for unit, factor in MPS_PER.items():
        assert unit_of_scale(factor, 0.001) == unit
        assert unit_of_scale(1.0 / factor, 0.004) == f"m/s as {unit}"
        assert unit_of_scale(factor, 0.2 * factor) is None  # too uncertain to tell
    for scale in (0.97, 1.0, 1.03, 0.6, 0.75, 2.5):
        assert unit_of_scale(scale, 0.001) is None


def _drive_result(tmp_path: Path, speed_scale: float) -> dict:  # type: ignore[type-arg]
    drive = simulate_drive(4.0, -3.0, 25.0, duration_s=900.0, speed_scale=speed_scale, seed=6)
    log, out = tmp_path / f"drive_{speed_scale:.3f}.parquet", tmp_path / f"r_{speed_scale:.3f}.json"
    to_frame(drive.to_samples()).to_parquet(log, index=False)
    assert main(["calibrate", str(log), "--use", "driving", "-o", str(out), "-q"]) == 0
    return json.loads(out.read_text(encoding="utf-8"))  # type: ignore[no-any-return]


@pytest.mark.parametrize("unit", list(MPS_PER))
def test_a_drive_whose_speed_is_in_another_unit_names_it_and_gives_the_same_angles(unit: str, tmp_path: Path) -> None:
    true = _drive_result(tmp_path, 1.0)
    slipped = _drive_result(tmp_path, 1.0 / MPS_PER[unit])  # the logged numbers are the speed in that unit
    notes = [n for n in slipped["notes"] if "d(speed)/dt" in n]
    assert len(notes) == 1 and f"a speed logged in {unit} and read as m/s" in notes[0]
    assert f"speed=COLUMN:{unit}" in notes[0]
    assert not any(unit in n for n in true["notes"] if "d(speed)/dt" in n)
    for angle in ("roll_deg", "pitch_deg", "yaw_deg"):  # the direction of the speed's change is what the fit uses
        sigma = true["uncertainty"][angle]
        assert abs(slipped["mounting"][angle] - true["mounting"][angle]) < max(0.5 * sigma, 0.05), angle


def test_a_tyre_s_scale_error_is_no_unit(tmp_path: Path) -> None:
    doc = _drive_result(tmp_path, 1.04)
    notes = [n for n in doc["notes"] if "d(speed)/dt" in n]
    assert all("tyre radius" in n and "read as m/s" not in n for n in notes)
    assert np.isfinite(doc["mounting"]["yaw_deg"])
