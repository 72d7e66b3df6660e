"""A number typed in another unit than its option's, caught by the option's range (mountcal.core.ranges).

- ``export --translation 350 0 120`` (the IMU's lever arm in mm, as a drawing gives it) wrote a URDF placing the
  IMU 350 m from base_link: a lever arm's range was ±1000 m. On a vehicle it is within ±50 m; beyond, the
  refusal says the unit is metres and what a value in mm or cm would be.
- ``simulate --noise-g 1`` (1 mg meant, as ``plan --noise`` takes mg) wrote a stop table whose stop means scatter
  by 1 g, said nowhere: its range was [0, 1] g. A stop mean's noise is within 0.1 g; beyond, the refusal names
  the value in g.
"""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from mountcal.cli import main


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    capsys.readouterr()
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    return capsys.readouterr().err


def test_a_lever_arm_in_millimetres_is_refused_naming_metres(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "imu.urdf"
    err = _refused(["export", str(result), "--to", "urdf", "--translation", "350", "0", "120", "-o", str(out)], capsys)
    assert not out.exists()
    assert "--translation" in err and "m" in err and "350 mm is 0.35 m" in err, err
    assert main(["export", str(result), "--to", "urdf", "--translation", "0.35", "0", "0.12", "-o", str(out)]) == 0
    assert re.search(r'xyz="0\.35 0 0\.12"', out.read_text(encoding="utf-8"))


def test_a_stop_noise_in_mg_given_as_g_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.csv"
    err = _refused(["simulate", "--noise-g", "1", "-o", str(out)], capsys)
    assert not out.exists()
    assert "--noise-g" in err and "1 mg is 0.001" in err, err
    assert main(["simulate", "-q", "--noise-g", "0.001", "-o", str(out)]) == 0
    assert len(pd.read_csv(out)) == 12
