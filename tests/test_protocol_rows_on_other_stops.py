"""A protocol sheet on the log whose rows sit on their neighbours' stops (mountcal/stops/protocol_clock.py,
``misplaced``): a sheet a stop late or early is refused naming the offset that puts each row on its own stop,
through every command that takes a sheet and the library alike.

Before, such a sheet overlapped the log, so its clock was not questioned: each row took the still period of the
next (or the previous) one, its β a step off, and the yaw came out turned by the headings' step (30°), confident
(data/parking.mcap, its sheet 34 s late: yaw 37.0° for 7°; 34 s early: −23.0°; 26 s late: 37.0°).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from mountcal.calibration.pipeline import calibrate_log
from mountcal.cli import main
from mountcal.core.errors import InputError

REPO = Path(__file__).resolve().parents[1]
PARKING, PROTOCOL = REPO / "data" / "parking.mcap", REPO / "data" / "parking_protocol.csv"
PERIOD_S = 34.0  # data/parking.mcap: a stop every 34 s (22 s parked, 12 s driving)


def sheet(path: Path, shift_s: float) -> Path:
    """data/parking_protocol.csv with its times moved by ``shift_s``, written by pandas."""
    df = pd.read_csv(PROTOCOL)
    df[["t_start_s", "t_end_s"]] += shift_s
    df.to_csv(path, index=False, float_format="%.17g")
    return path


@pytest.mark.parametrize("shift_s", [PERIOD_S, -PERIOD_S, 26.0])
def test_a_sheet_whose_rows_sit_on_their_neighbours_stops_is_refused_naming_the_offset(
    shift_s: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    off = sheet(tmp_path / "off.csv", shift_s)
    out = tmp_path / "r.json"
    capsys.readouterr()
    assert main(["calibrate", str(PARKING), "--protocol", str(off), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert not out.exists() and "Traceback" not in err
    late = shift_s > 0
    assert f"found its rows {abs(shift_s):.0f} s {'late' if late else 'early'}" in err
    assert f"df[['t_start_s', 't_end_s']] {'-' if late else '+'}= {abs(shift_s):.0f}" in err
    stops = tmp_path / "stops.csv"
    assert main(["stops", str(PARKING), "--protocol", str(off), "-o", str(stops)]) == 2 and not stops.exists()
    with pytest.raises(InputError, match="on another still period than as written"):
        calibrate_log(PARKING, protocol=off, use="stops")


@pytest.mark.parametrize("shift_s", [0.0, 3.0, -3.0])
def test_a_sheet_on_its_own_stops_a_few_seconds_off_calibrates_as_before(shift_s: float, tmp_path: Path) -> None:
    cal = calibrate_log(PARKING, protocol=sheet(tmp_path / "near.csv", shift_s), use="stops").calibration
    assert cal.confident and cal.yaw_deg is not None
    assert abs(cal.yaw_deg - 7.0) < 1.0
