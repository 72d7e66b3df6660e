"""docs/fleet.md's per-log table names every column of fleet.parquet, and says what its rotation σ hold.

A reader of fleet.parquet has only the docs: a column they do not list, or a σ they describe as the whole
1σ when it is a part of it, is read wrong. The rotation σ of a log are its statistical part (the logs of one
sensor are compared and averaged on it); the sensor's systematic part, common to its logs, is in
``rot_sys_sigma_*``; the two add in quadrature to the result's σ about the vehicle axes.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from mountcal.calibration.fit import calibrate
from mountcal.fleet import store
from mountcal.fleet.worker import calibration_record
from mountcal.simulate.stops import simulate_stops

DOC = Path(__file__).resolve().parents[1] / "docs" / "fleet.md"


def per_log_rows() -> dict[str, str]:
    """Each column docs/fleet.md's per-log table names (``a_{x,y}_b`` spelled out), with its row's meaning."""
    section = DOC.read_text(encoding="utf-8").split("## The per-log table", 1)[1].split("\n## ", 1)[0]
    rows: dict[str, str] = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 3 or not cells[0].startswith("`"):
            continue
        for token in re.findall(r"`([^`]+)`", cells[0]):
            braces = re.fullmatch(r"(.*)\{(.*)\}(.*)", token)
            names = [braces[1] + v + braces[3] for v in braces[2].split(",")] if braces else [token]
            rows |= dict.fromkeys(names, cells[-1])
    return rows


def test_every_column_of_the_per_log_table_is_documented() -> None:
    documented = per_log_rows()
    columns = [c[0] for c in store.LOG_COLUMNS]
    assert [c for c in columns if c not in documented] == []
    assert sorted(set(documented) - set(columns)) == []


def test_the_rotation_sigma_columns_are_documented_as_what_they_hold() -> None:
    truth = Rotation.from_euler("ZYX", [135.0, 10.0, -90.0], degrees=True)
    cal = calibrate(simulate_stops(rot_vs=truth, noise_g=0.003, seed=10)[0])
    rec = calibration_record(cal)
    stat = np.array([rec[f"rot_sigma_{a}_deg"] for a in "xyz"], dtype=float)
    sys = np.array([rec[f"rot_sys_sigma_{a}_deg"] for a in "xyz"], dtype=float)
    assert (sys > 10 * stat)[:2].all()  # this sensor's datasheet limits dominate its tilt σ
    np.testing.assert_allclose(np.hypot(stat, sys), cal.rotation_sigma_deg, rtol=1e-9)  # the result's: the total
    documented = per_log_rows()
    assert "statistical" in documented["rot_sigma_x_deg"]
    assert "systematic" in documented["rot_sys_sigma_x_deg"]
