"""The frame a ROS log names for its IMU (``header.frame_id``) is recorded by every ROS reader, stated in the
result's ``provenance.conventions`` (``sensor_frame``) and used by ``mountcal export`` as the child frame; a
``--child`` that differs is written as given and said; a log naming no frame gets ``imu_link``, said to be
mountcal's default; several frames on the IMU topic are said, with their counts, and never reduced to one."""

from __future__ import annotations

import json
import re
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2Writer
from tests.io.test_bags import _bag, _convert
from tests.io.test_mcap_log import IMU_MSGDEF, T0_NS, imu_msg

from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.core.result import Calibration, Convention
from mountcal.io.logs import iter_log, read_log
from mountcal.io.reader import LogOptions
from mountcal.io.samples import slices
from mountcal.io.writers import write_mcap
from mountcal.outputs.exporters import Frames, export

REPO = Path(__file__).resolve().parents[1]
PARKING = REPO / "data" / "parking.mcap"
PROTOCOL = REPO / "data" / "parking_protocol.csv"
REAL_MCAP = "robot_localization/test1_ros2_mcap/test1_ros2_mcap.mcap"
FRAMED = ("ros2-static-tf", "urdf", "tf2", "autoware")


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The parking demo's samples in an MCAP whose Imu messages name ``xsens_imu``, and its calibration."""
    folder = tmp_path_factory.mktemp("xsens")
    write_mcap(folder / "xsens.mcap", read_log(PARKING), frame_id="xsens_imu", start_time_s=0)
    code = main(["calibrate", str(folder / "xsens.mcap"), "--protocol", str(PROTOCOL), "-o", str(folder / "r.json")])
    assert code == 0
    return folder


def _sensor_frame(conventions: Any) -> list[Any]:
    return [c for c in conventions if (c["name"] if isinstance(c, dict) else c.name) == "sensor_frame"]


def _child_of(fmt: str, text: str) -> str:
    """The child frame an export names, parsed from each format's own syntax (not from its comments)."""
    if fmt == "ros2-static-tf":
        return re.findall(r"--child-frame-id (\S+)$", text, re.M)[0]
    if fmt == "urdf":
        return re.findall(r'<child link="([^"]+)"/>', text)[0]
    if fmt == "autoware":
        return re.findall(r"^  (\S+):$", text, re.M)[0]
    return re.findall(r"^// transform \S+ -> (\S+):", text, re.M)[0]  # tf2: only its comment names frames


def _export(folder: Path, fmt: str, capsys: pytest.CaptureFixture[str], *extra: str) -> tuple[str, str]:
    parent = ["--parent", "base_link"] if fmt == "autoware" else []  # the kit's parent needs its pose
    capsys.readouterr()
    assert main(["export", str(folder / "r.json"), "--to", fmt, *parent, *extra, "-o", "-"]) == 0
    got = capsys.readouterr()
    return got.out, got.err


def test_calibrating_an_mcap_states_its_imu_frame(made: Path) -> None:
    doc = json.loads((made / "r.json").read_text())
    assert _sensor_frame(doc["provenance"]["conventions"]) == [
        {
            "name": "sensor_frame",
            "value": "xsens_imu",
            "how": "stated",
            "by": "header.frame_id of /imu/data in xsens.mcap",
        }
    ]


@pytest.mark.parametrize("fmt", FRAMED)
def test_export_names_the_frame_the_data_were_in(made: Path, fmt: str, capsys: pytest.CaptureFixture[str]) -> None:
    out, err = _export(made, fmt, capsys)
    assert _child_of(fmt, out) == "xsens_imu"
    said = "child frame xsens_imu: the frame the calibration's data were in (stated by header.frame_id of /imu/data"
    assert said in err and said in out  # stderr, and the file's comment
    assert "warning" not in err
    if fmt == "ros2-static-tf":
        assert out.rstrip().endswith("--frame-id base_link --child-frame-id xsens_imu")


@pytest.mark.parametrize("fmt", FRAMED)
def test_another_child_is_written_and_said(made: Path, fmt: str, capsys: pytest.CaptureFixture[str]) -> None:
    out, err = _export(made, fmt, capsys, "--child", "imu_link")
    assert _child_of(fmt, out) == "imu_link"
    assert "xsens_imu" not in out.splitlines()[-1]
    warning = [line for line in err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "NOT the frame the calibration's data were in" in warning[0]
    assert "they were in frame xsens_imu (stated by header.frame_id of /imu/data in xsens.mcap)" in warning[0]
    comment = [line for line in out.splitlines() if "NOT the frame" in line]
    assert len(comment) == 1 and "xsens_imu" in comment[0] and "written for imu_link" in comment[0]


def test_the_same_child_given_is_no_warning(made: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, err = _export(made, "ros2-static-tf", capsys, "--child", "xsens_imu")
    assert _child_of("ros2-static-tf", out) == "xsens_imu" and "warning" not in err


def test_the_library_export_names_the_recorded_frame(made: Path) -> None:
    cal = Calibration.load(made / "r.json")
    assert _child_of("urdf", str(export(cal, "urdf"))) == "xsens_imu"
    assert _child_of("urdf", str(export(cal, "urdf", frames=Frames(parent="base_link")))) == "xsens_imu"
    renamed = str(export(cal, "urdf", frames=Frames(child="imu_link")))
    assert _child_of("urdf", renamed) == "imu_link" and "they were in frame xsens_imu" in renamed


def _without_frame(cal: Calibration, conventions: tuple[Convention, ...] = ()) -> Calibration:
    kept = tuple(c for c in cal.provenance.conventions if c.name != "sensor_frame")
    return replace(cal, provenance=replace(cal.provenance, conventions=(*kept, *conventions)))


def test_a_result_whose_log_named_no_frame_gets_mountcals_default(made: Path) -> None:
    cal = _without_frame(Calibration.load(made / "r.json"))
    out = str(export(cal, "ros2-static-tf"))
    assert _child_of("ros2-static-tf", out) == "imu_link"
    assert "# child frame imu_link: mountcal's default (the calibration's log named no frame" in out


def test_a_table_names_no_frame(tmp_path: Path) -> None:
    samples = read_log(PARKING)
    assert samples.frame_ids is not None
    path = tmp_path / "samples.csv"
    cols = np.column_stack([samples.t_s, samples.acc_s, samples.gyro_s])
    np.savetxt(path, cols[:2000], delimiter=",", header="t_s,ax,ay,az,gx,gy,gz", comments="")
    table = read_log(path)
    assert table.frame_ids is None and not _sensor_frame(table.conventions)


def test_several_frames_are_said_and_no_child_is_picked(made: Path, capsys: pytest.CaptureFixture[str]) -> None:
    several = Convention("sensor_frame", "several frames: a (10 messages), b (3 messages)", "stated", "header…")
    cal = _without_frame(Calibration.load(made / "r.json"), (several,))
    with pytest.raises(InputError, match=r"several frames: a \(10 messages\), b \(3 messages\)"):
        export(cal, "ros2-static-tf")
    out = str(export(cal, "ros2-static-tf", frames=Frames(child="a")))
    assert _child_of("ros2-static-tf", out) == "a" and "data were in several frames: a (10 messages)" in out
    cal.save(made / "several.json")
    assert main(["export", str(made / "several.json"), "--to", "urdf", "-o", "-"]) == 2
    assert "--child" in capsys.readouterr().err
    assert str(export(cal, "novatel"))  # a format naming no frames needs none


def test_a_frame_name_a_command_would_misread_is_not_written(made: Path) -> None:
    odd = Convention("sensor_frame", "imu; rm -rf ~", "stated", "header.frame_id of /imu in odd.mcap")
    cal = _without_frame(Calibration.load(made / "r.json"), (odd,))
    with pytest.raises(InputError, match=r"--child|Frames\.child"):
        export(cal, "ros2-static-tf")
    assert _child_of("ros2-static-tf", str(export(cal, "ros2-static-tf", frames=Frames(child="imu")))) == "imu"


# --------------------------------------------------------------------------- every reader counts the frame ids


def _mixed_mcap(path: Path, frames: list[str]) -> None:
    """Imu messages whose frame_id is ``frames[i]`` (CDR, small chunks: several per chunk and per length)."""
    with path.open("wb") as f:
        writer = Ros2Writer(f, chunk_size=4000)
        schema = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
        for i, frame in enumerate(frames):
            t_ns = T0_NS + i * 5_000_000
            message = imu_msg(t_ns, [0.1, 0.2, 9.8], [0.0, 0.0, 0.01], frame_id=frame)
            writer.write_message("/imu", schema, message, log_time=t_ns, publish_time=t_ns)
        writer.finish()


def test_the_cdr_reader_counts_every_frame_id(tmp_path: Path) -> None:
    # same-length names that differ (ab/ba), other lengths, an empty one, runs and single odd ones out
    frames = ["ab"] * 300 + ["ba"] * 7 + ["ab"] * 200 + [""] * 3 + ["imu_link"] * 90 + ["ab", "ba"] * 50
    _mixed_mcap(tmp_path / "mixed.mcap", frames)
    samples = read_log(tmp_path / "mixed.mcap")
    assert samples.frame_ids is not None and dict(samples.frame_ids.counts) == dict(Counter(frames))
    (named,) = _sensor_frame(samples.conventions)
    assert (
        named.value
        == "several frames: ab (550 messages), imu_link (90 messages), ba (57 messages), (empty) (3 messages)"
    )
    streamed: Counter[str] = Counter()
    for chunk in iter_log(tmp_path / "mixed.mcap", max_samples=64):
        streamed.update(dict(chunk.frame_ids.counts) if chunk.frame_ids else {})
    assert streamed == Counter(frames)


def test_one_frame_in_every_chunk_of_the_stream(made: Path) -> None:
    chunks = list(iter_log(made / "xsens.mcap", max_samples=5000))
    assert len(chunks) > 2
    assert {name for c in chunks for name, _ in (c.frame_ids.counts if c.frame_ids else ())} == {"xsens_imu"}
    assert sum(n for c in chunks for _, n in (c.frame_ids.counts if c.frame_ids else ())) == sum(map(len, chunks))


def test_a_ros1_bag_counts_frame_ids_of_varying_length(tmp_path: Path) -> None:
    msgs = _bag(tmp_path / "imu.bag", n=900, chunk_bytes=20_000)  # frame ids "", "imu", "imuimu" in turn
    samples = read_log(tmp_path / "imu.bag")
    assert samples.frame_ids is not None
    assert dict(samples.frame_ids.counts) == dict(Counter(m.header.frame_id for m in msgs))
    (named,) = _sensor_frame(samples.conventions)
    assert named.value.startswith("several frames: ") and "imuimu (300 messages)" in named.value


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_ros2_bag_folder_states_its_imu_frame(made: Path, tmp_path: Path, storage: str) -> None:
    folder = _convert(made / "xsens.mcap", tmp_path / f"bag_{storage}", storage)
    (named,) = _sensor_frame(read_log(folder).conventions)
    assert named.value == "xsens_imu" and named.by == f"header.frame_id of /imu/data in bag_{storage}"


def test_splits_naming_two_frames_calibrate_with_both_said(made: Path, capsys: pytest.CaptureFixture[str]) -> None:
    samples = read_log(PARKING)
    first, second = slices(samples, len(samples) // 2 + 1)
    write_mcap(made / "a.mcap", first, frame_id="xsens_imu", start_time_s=0)
    write_mcap(made / "b.mcap", second, frame_id="gps_imu", start_time_s=0)
    args = [str(made / "a.mcap"), str(made / "b.mcap"), "--protocol", str(PROTOCOL)]
    assert main(["calibrate", *args, "-o", str(made / "two.json")]) == 0
    doc = json.loads((made / "two.json").read_text())
    (named,) = _sensor_frame(doc["provenance"]["conventions"])
    assert named["value"] == f"several frames: xsens_imu ({len(first)} messages), gps_imu ({len(second)} messages)"
    assert named["by"] == "header.frame_id of /imu/data in a.mcap + b.mcap"
    assert any("the IMU messages name several frames" in note for note in doc["notes"])
    capsys.readouterr()
    assert main(["export", str(made / "two.json"), "--to", "ros2-static-tf", "-o", "-"]) == 2
    assert "xsens_imu" in capsys.readouterr().err


def test_a_log_mountcal_rotated_records_its_frame_not_a_sensor_frame(made: Path, tmp_path: Path) -> None:
    out = tmp_path / "vehicle.mcap"
    assert main(["rotate", str(made / "xsens.mcap"), "--calibration", str(made / "r.json"), "-o", str(out), "-q"]) == 0
    samples = read_log(out, LogOptions(topic="/imu/data/vehicle"))  # the original topic stays beside it
    assert samples.rotated is not None and not _sensor_frame(samples.conventions)
    assert [c.name for c in samples.conventions if c.name == "frame"] == ["frame"]


@pytest.mark.real_data
def test_the_real_ros2_recording_states_the_frame_its_imu_messages_carry(real_data: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = real_data / REAL_MCAP
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        carried = Counter(m.header.frame_id for *_, m in reader.iter_decoded_messages(topics=["/imu/data"]))
    assert len(carried) == 1 and sum(carried.values()) == 11865
    samples = read_log(path)
    assert samples.frame_ids is not None and dict(samples.frame_ids.counts) == dict(carried)
    (named,) = _sensor_frame(samples.conventions)
    assert named.value == next(iter(carried)) and named.how == "stated"


def test_a_json_encoded_mcap_counts_its_frame_ids(tmp_path: Path) -> None:
    from mcap.writer import Writer as McapWriter

    frames = ["imu_link_ned"] * 40 + ["xsens_imu"] * 3 + ["imu_link_ned"] * 17
    with (tmp_path / "json.mcap").open("wb") as f:
        writer = McapWriter(f, chunk_size=2000)
        writer.start()
        channel = writer.register_channel(
            "/imu", "json", writer.register_schema("sensor_msgs/msg/Imu", "jsonschema", b"{}")
        )
        for i, frame in enumerate(frames):
            t_ns = T0_NS + i * 5_000_000
            data = json.dumps(imu_msg(t_ns, [0.1, 0.2, 9.8], [0.0, 0.0, 0.01], frame_id=frame)).encode()
            writer.add_message(channel, log_time=t_ns, data=data, publish_time=t_ns)
        writer.finish()
    samples = read_log(tmp_path / "json.mcap")
    assert samples.frame_ids is not None and samples.frame_ids.counts == (("imu_link_ned", 57), ("xsens_imu", 3))


@pytest.mark.real_data
def test_the_real_ros1_bag_states_the_same_frame_as_its_ros2_recording(real_data: Path) -> None:
    bag = read_log(real_data / "robot_localization" / "test1.bag")
    mcap = read_log(real_data / REAL_MCAP)
    assert bag.frame_ids is not None and mcap.frame_ids is not None
    assert bag.frame_ids.counts == mcap.frame_ids.counts and sum(n for _, n in bag.frame_ids.counts) == 11865
    assert _sensor_frame(bag.conventions)[0].value == _sensor_frame(mcap.conventions)[0].value


MAPS = ("y,x,-z", "-x,-y,z", "z,x,y")  # proper signed permutations: the same sensor, its axes named otherwise


@pytest.fixture(scope="module")
def mapped(made: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The framed log calibrated with each axis map (the calibration's angles are then on the mapped axes)."""
    out = {}
    for axes in MAPS:
        folder = tmp_path_factory.mktemp("mapped")
        argv = ["calibrate", str(made / "xsens.mcap"), "--protocol", str(PROTOCOL), "--axes", axes]
        assert main([*argv, "-o", str(folder / "r.json"), "-q"]) == 0
        out[axes] = folder
    return out


def _numbers(fmt: str, text: str) -> np.ndarray:
    """The numbers an export writes outside its comments."""
    comment = {"urdf": "<!--", "tf2": "//"}.get(fmt, "#")
    lines = [line for line in text.splitlines() if not line.lstrip().startswith(comment)]
    return np.array([float(x) for x in re.findall(r"-?\d+\.\d+(?:e[-+]?\d+)?", "\n".join(lines))])


@pytest.mark.parametrize("fmt", FRAMED)
def test_an_axis_map_does_not_change_the_transform_for_the_frame_the_data_were_in(
    made: Path, mapped: dict[str, Path], fmt: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The transform is for the recorded frame's axes, as its messages carry them: however the calibration
    named the sensor's axes (--axes), the same data give the same transform."""
    plain, _ = _export(made, fmt, capsys)
    for axes, folder in mapped.items():
        doc = json.loads((folder / "r.json").read_text(encoding="utf-8"))
        assert abs(doc["mounting"]["roll_deg"] - 5.0) > 1.0 or axes == "z,x,y"  # the angles do change
        text, err = _export(folder, fmt, capsys)
        assert _child_of(fmt, text) == "xsens_imu"
        assert f"--axes {axes} is composed in" in err and f"{axes} is composed in" in text  # XML comments hold no "--"
        np.testing.assert_allclose(_numbers(fmt, text), _numbers(fmt, plain), atol=1e-8, err_msg=axes)


def test_a_left_handed_log_made_right_handed_by_a_reflection_has_no_transform_for_its_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    samples = read_log(PARKING)
    assert samples.gyro_s is not None
    flip = np.array([1.0, -1.0, 1.0])  # the driver publishes y reversed: not a REP 103 frame
    mirrored = replace(samples, acc_s=samples.acc_s * flip, gyro_s=samples.gyro_s * flip)
    write_mcap(tmp_path / "left.mcap", mirrored, frame_id="imu_left", start_time_s=0)
    result = tmp_path / "r.json"
    argv = ["calibrate", str(tmp_path / "left.mcap"), "--protocol", str(PROTOCOL), "--axes", "x,-y,z"]
    assert main([*argv, "-o", str(result), "-q"]) == 0
    for fmt in FRAMED:
        out = tmp_path / f"t.{fmt}"
        parent = ["--parent", "base_link"] if fmt == "autoware" else []
        capsys.readouterr()
        assert main(["export", str(result), "--to", fmt, *parent, "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert "a reflection" in err and "imu_left" in err and "--child" in err and not out.exists()
        # the frame of the mapped axes, named by the user, gets the calibration's own rotation
        text, err = _export(tmp_path, fmt, capsys, "--child", "imu_mapped")
        assert _child_of(fmt, text) == "imu_mapped" and "NOT the frame" in err


@pytest.mark.parametrize("fmt", ["novatel", "ublox", "json", "yaml"])
def test_a_format_naming_no_frame_states_the_axis_map_its_rotation_is_on(
    mapped: dict[str, Path], made: Path, fmt: str, capsys: pytest.CaptureFixture[str]
) -> None:
    for axes, folder in mapped.items():
        text, _ = _export(folder, fmt, capsys)
        assert f"sensor frame = the log's axes after the calibration's axis map {axes}" in text
    plain, _ = _export(made, fmt, capsys)
    assert "axis map" not in plain
