"""Frame names written into the formats that name frames: read back by the consumer's own parser as given.

A frame name is written into a shell command (``static_transform_publisher``), XML (URDF) and YAML (Autoware).
A name that any of them would read as something else — a comment, a second argument, a mapping, a broken
attribute — makes a corrupt output; such a name, given with ``--child`` or ``--parent``, is refused (exit 2,
nothing written), as one taken from the log is. A plain name that YAML reads as another type (``on``, ``null``,
``1``: a boolean, nothing, a number) is quoted in the YAML, so that Autoware's parser gets the string.
"""

from __future__ import annotations

import shlex
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

from mountcal.calibration.fit import calibrate
from mountcal.cli import main
from mountcal.simulate.stops import simulate_stops

FRAMED = ("ros2-static-tf", "urdf", "tf2", "autoware")
MISREAD = ("#imu", "imu link", 'imu"1', "imu: x", "<imu>", "--imu", "imu&gyro", "imu\nx", "")


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> Path:
    table, _ = simulate_stops(5.0, 6.0, 7.0, seed=3)
    path = tmp_path_factory.mktemp("names") / "r.json"
    calibrate(table).save(path)
    return path


@pytest.mark.parametrize("fmt", FRAMED)
@pytest.mark.parametrize("name", MISREAD)
@pytest.mark.parametrize("which", ["--child", "--parent"])
def test_a_name_the_format_would_misread_is_refused_and_nothing_written(
    result: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str, name: str, which: str
) -> None:
    out = tmp_path / "out.txt"
    extra = ["--parent", "base_link"] if fmt == "autoware" and which == "--child" else []
    assert main(["export", str(result), "--to", fmt, *extra, f"{which}={name}", "-o", str(out)]) == 2
    assert not out.exists()
    err = capsys.readouterr().err
    assert which in err and "Traceback" not in err


@pytest.mark.parametrize("name", ["on", "null", "yes", "true", "1", "0x10", "imu_link", "tamagawa/imu_link"])
def test_every_plain_name_reads_back_as_the_same_string(
    result: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    assert main(["export", str(result), "--to", "autoware", "--parent", "base_link", "--child", name, "-o", "-"]) == 0
    entry = yaml.safe_load(capsys.readouterr().out)["base_link"]
    assert list(entry) == [name] and set(entry[name]) == {"x", "y", "z", "roll", "pitch", "yaw"}
    assert main(["export", str(result), "--to", "ros2-static-tf", "--child", name, "-o", "-"]) == 0
    command = capsys.readouterr().out.splitlines()[-1]
    assert shlex.split(command)[-2:] == ["--child-frame-id", name]
    assert main(["export", str(result), "--to", "urdf", "--child", name, "-o", "-"]) == 0
    text = capsys.readouterr().out
    joint = ET.fromstring(text[text.index("<joint") :])
    assert joint.find("child").get("link") == name  # type: ignore[union-attr]
