"""Samples mountcal already rotated, read back: the readers say so from the file's own metadata (a Parquet
file's ``mountcal.frame``, the chosen MCAP channel's ``frame``), rotating them again is refused — by the
command line and the library alike — and calibrating them says what the angles are relative to. A CSV,
which carries no metadata, says it in a column (tests/test_rotated_csv.py). Every file is written by
mountcal's own ``rotate``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from tests.conftest import Refused

from mountcal.apply.rotate import frame_to_vehicle
from mountcal.apply.rotate_log import rotate_log, to_frame
from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.core.result import Calibration
from mountcal.io.logs import iter_log, read_log
from mountcal.io.reader import LogOptions

DATA = Path(__file__).resolve().parents[1] / "data"
VEHICLE_TOPIC = "/imu/data/vehicle"


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The parking log, its calibration and its rotated copies (Parquet, MCAP), all by the command line."""
    folder = tmp_path_factory.mktemp("rotated")
    shutil.copy(DATA / "parking.mcap", folder / "parking.mcap")
    protocol = ["--protocol", str(DATA / "parking_protocol.csv")]
    assert main(["calibrate", str(folder / "parking.mcap"), *protocol, "-o", str(folder / "r.json"), "-q"]) == 0
    for name in ("veh.parquet", "veh.mcap"):
        args = ["rotate", str(folder / "parking.mcap"), "--calibration", str(folder / "r.json"), "-o"]
        assert main([*args, str(folder / name), "-q"]) == 0
    return folder


def test_rotating_a_rotated_parquet_is_refused(refused: Refused, made: Path) -> None:
    out = made / "twice.csv"
    err = refused(["rotate", str(made / "veh.parquet"), "--calibration", str(made / "r.json"), "-o", str(out)], out)
    assert f"{made / 'veh.parquet'}: expected samples in the sensor's frame" in err
    assert "already put in the vehicle frame" in err and f"from {made / 'parking.mcap'}" in err
    assert "apply the mounting twice" in err and "Rotate the original log." in err


@pytest.mark.parametrize(  # read as a stream; copied through; read through the message definition
    ("suffix", "field"), [(".csv", []), (".mcap", []), (".parquet", ["--field", "linear_acceleration"])]
)
def test_rotating_the_vehicle_topic_of_a_rotated_mcap_is_refused(
    refused: Refused, made: Path, suffix: str, field: list[str]
) -> None:
    out = made / f"twice{suffix}"
    argv = ["rotate", str(made / "veh.mcap"), "--topic", VEHICLE_TOPIC, *field, "--calibration", str(made / "r.json")]
    err = refused([*argv, "-o", str(out)], out)
    assert f"{made / 'veh.mcap'}: expected samples in the sensor's frame" in err
    assert f"from {made / 'parking.mcap'}" in err and "apply the mounting twice" in err


def test_the_library_refuses_too(made: Path) -> None:
    cal = Calibration.load(made / "r.json")
    with pytest.raises(InputError, match="already put in the vehicle frame"):
        rotate_log(made / "veh.parquet", cal, made / "lib.parquet")
    with pytest.raises(InputError, match="already put in the vehicle frame"):
        rotate_log(made / "veh.mcap", cal, made / "lib.mcap", options=LogOptions(topic=VEHICLE_TOPIC))
    assert not (made / "lib.parquet").exists() and not (made / "lib.mcap").exists()
    rotated = to_frame(read_log(made / "veh.parquet"))
    assert rotated.attrs["frame"] == "vehicle"
    with pytest.raises(InputError, match="mounting twice"):
        frame_to_vehicle(rotated, cal, gyro_columns=("gx", "gy", "gz"))
    once = frame_to_vehicle(to_frame(read_log(made / "parking.mcap")), cal)
    with pytest.raises(InputError, match="mounting twice"):
        frame_to_vehicle(once, cal)


def test_the_readers_say_the_frame_of_the_chosen_channel_from_the_metadata(made: Path) -> None:
    parquet = read_log(made / "veh.parquet")
    assert parquet.rotated is not None and parquet.rotated.frame == "vehicle"
    assert f"from {made / 'parking.mcap'}" in parquet.rotated.calibration and "mountcal.frame" in parquet.rotated.by
    chunks = list(iter_log(made / "veh.parquet", max_samples=5000))
    assert len(chunks) > 2 and all(c.rotated == parquet.rotated for c in chunks)
    vehicle = read_log(made / "veh.mcap", LogOptions(topic=VEHICLE_TOPIC))
    assert vehicle.rotated is not None and VEHICLE_TOPIC in vehicle.rotated.by
    # the same file's original topic is the sensor's: a channel's metadata, not "some channel in the file"
    assert read_log(made / "veh.mcap", LogOptions(topic="/imu/data")).rotated is None
    assert read_log(made / "parking.mcap").rotated is None
    renamed = made / "looks_like_a_log.parquet"  # the name says nothing either way
    shutil.copy(made / "veh.parquet", renamed)
    assert read_log(renamed).rotated == parquet.rotated


def test_two_imu_topics_name_the_one_mountcal_rotated(refused: Refused, made: Path) -> None:
    label = f"'{VEHICLE_TOPIC}' (mountcal rotate's vehicle-frame output)"
    with pytest.raises(InputError, match="exactly one sensor_msgs/msg/Imu topic") as err:
        read_log(made / "veh.mcap")
    assert label in str(err.value) and "'/imu/data', " in str(err.value)
    out = made / "which.mcap"  # the copy-through path chooses its topic itself
    assert label in refused(
        ["rotate", str(made / "veh.mcap"), "--calibration", str(made / "r.json"), "-o", str(out)], out
    )


@pytest.mark.parametrize(
    ("name", "topic", "by"),
    [("veh.parquet", None, "Parquet metadata"), ("veh.mcap", VEHICLE_TOPIC, f"MCAP channel '{VEHICLE_TOPIC}'")],
)
def test_calibrating_rotated_samples_measures_what_is_left_and_says_so(
    made: Path, name: str, topic: str | None, by: str
) -> None:
    out = made / f"check_{Path(name).suffix[1:]}.json"
    argv = ["calibrate", str(made / name), "--protocol", str(DATA / "parking_protocol.csv"), "-o", str(out), "-q"]
    assert main(argv + (["--topic", topic] if topic else [])) == 0
    doc = json.loads(out.read_text())
    mounted = json.loads((made / "r.json").read_text())["mounting"]
    assert abs(mounted["roll_deg"]) > 1 and abs(mounted["yaw_deg"]) > 1  # so ≈ 0 below is not the log's own
    for angle in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert abs(doc["mounting"][angle]) < min(0.15, 3 * doc["uncertainty"][angle]), (angle, doc["mounting"])
    frame = [c for c in doc["provenance"]["conventions"] if c["name"] == "frame"]
    assert len(frame) == 1 and frame[0]["value"].startswith("vehicle (mountcal rotate's output")
    assert frame[0]["how"] == "stated" and by in frame[0]["by"] and "parking.mcap" in frame[0]["value"]
    assert any("relative to that frame" in note for note in doc["notes"])


def test_a_sensor_frame_log_states_no_frame(made: Path) -> None:
    doc = json.loads((made / "r.json").read_text())
    assert "frame" not in [c["name"] for c in doc["provenance"]["conventions"]]
    assert not any("relative to that frame" in note for note in doc["notes"])


def test_the_stops_command_says_the_frame_of_its_stops(made: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = made / "stops.csv"
    capsys.readouterr()
    assert (
        main(["stops", str(made / "veh.parquet"), "--protocol", str(DATA / "parking_protocol.csv"), "-o", str(out)])
        == 0
    )
    err = capsys.readouterr().err
    assert "input frame: samples mountcal rotate already put in the vehicle frame" in err and out.exists()
