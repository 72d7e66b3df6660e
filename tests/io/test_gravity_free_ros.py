"""A ROS Imu whose linear_acceleration has gravity removed (a driver's "free acceleration") reads, but is refused
for calibration and rotation with that reason, in every reader (mountcal.io.samples.marked_gravity_free, applied
where every log is read).

Before: `calibrate` refused its stops as "no static reading in either unit (huge, overflowing or near-zero)", and
`rotate` as "acc_s: expected specific force in m/s² ... Convert g to m/s² (× 9.80665) first" — neither the file
nor the true reason.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.convert.converter import convert

from mountcal.cli import main
from mountcal.io.logs import read_log
from mountcal.io.samples import Samples
from mountcal.io.writers import write_mcap


@pytest.fixture(scope="module")
def free(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A still IMU for 60 s at 100 Hz whose acceleration had gravity removed: noise about zero."""
    folder = tmp_path_factory.mktemp("free")
    rng = np.random.default_rng(4)
    t = np.arange(6000) / 100.0
    samples = Samples(t, rng.normal(0.0, 0.03, (t.size, 3)), rng.normal(0.0, 0.002, (t.size, 3)))
    paths = {"mcap": folder / "free.mcap", "db3": folder / "free_db3"}
    write_mcap(paths["mcap"], samples, with_temperature=False, with_odometry=False)
    convert([paths["mcap"]], paths["db3"], "sqlite3", 9, None, "file", None, None, [], [], [], [])
    return paths


@pytest.mark.parametrize("kind", ["mcap", "db3"])
def test_a_gravity_free_imu_reads_and_is_refused_for_calibration_and_rotation(
    free: dict[str, Path], kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert "median magnitude" in read_log(free[kind]).gravity_free
    assert main(["inspect", str(free[kind])]) == 0
    capsys.readouterr()
    assert main(["stops", str(free[kind]), "-o", str(tmp_path / "s.csv")]) == 2
    err = capsys.readouterr().err
    assert str(free[kind]) in err and "without gravity" in err and "Traceback" not in err
    calibration = Path(__file__).parents[2] / "data" / "parking.mcap"
    result = tmp_path / "r.json"
    assert main(["calibrate", str(calibration), "--protocol", str(calibration.with_name("parking_protocol.csv")),
                 "-o", str(result), "-q"]) == 0  # fmt: skip
    out = tmp_path / "v.parquet"
    assert main(["rotate", str(free[kind]), "--calibration", str(result), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(free[kind]) in err and "without gravity" in err and "Convert g" not in err
    assert not out.exists()
