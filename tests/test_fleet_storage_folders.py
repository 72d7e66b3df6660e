"""Logs that are folders (a Sensor Logger recording, a ROS 2 bag, a comma2k19 segment) in object storage: a
prefix that is one log is one log, as the folder is locally, served by a real S3-compatible server (moto's
standalone server on 127.0.0.1, as tests/test_fleet_canedge.py serves its fleet).

The fleet is written by the real writers: Sensor Logger recordings as tests/test_sensor_logger.py writes them,
ROS 2 bags by rosbags' converter from data/parking.mcap, and data/parking.mcap itself as a plain log. Before,
each object was judged alone: a recording's six CSVs were six logs of the vehicle "rec_a" (five failed, and
TotalAcceleration.csv was calibrated alone as a bare table), a bag's storage file a log of the vehicle named by
the bag, and a comma2k19 segment's objects (no suffix) were dropped without a word.
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from tests.io.test_bags import _convert
from tests.s3_server import comparable, s3_server
from tests.test_sensor_logger import record

from mountcal.core.errors import InputError
from mountcal.fleet import FleetOptions, FleetResult, collect_jobs, run_fleet
from mountcal.fleet.storage import RemoteObject, list_objects, local_folder
from mountcal.fleet.storage_logs import NO_FILE_PATH, NOT_LOGS, storage_logs
from mountcal.io.folder import Listing
from mountcal.io.reader import LogOptions
from mountcal.io.registry import is_log, is_log_folder
from mountcal.simulate.stops import simulate_parking_log

REPO = Path(__file__).resolve().parents[1]
PARKING = REPO / "data" / "parking.mcap"
BUCKET = "s3://folders/LOG"
FOLDER_LOGS = ("v01/rec_a", "v01/rec_b", "v02/bag_db3", "v02/bag_mcap")  # each one log, as locally
PLAIN = "v03/plain.mcap"
SEGMENT = "rav4_2018-08-02--08-34-47_seg40"


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two recordings (Android, iOS) of one vehicle, two ROS 2 bags (MCAP and SQLite storage) of another, a
    plain MCAP of a third, and a README no reader takes."""
    root = tmp_path_factory.mktemp("storage-folders") / "LOG"
    log = simulate_parking_log(5.0, 6.0, 7.0, beta_deg=(0, 60, 120, 180, 240, 300), stop_s=20.0, drive_s=15.0,
                               rate_hz=50.0, seed=4)  # fmt: skip
    record(root / "v01" / "rec_a", log, "Android")
    record(root / "v01" / "rec_b", log, "iOS")
    (root / "v02").mkdir()
    _convert(PARKING, root / "v02" / "bag_mcap", "mcap")
    _convert(PARKING, root / "v02" / "bag_db3", "sqlite3")
    (root / "v03").mkdir()
    shutil.copy(PARKING, root / PLAIN)
    (root / "README.txt").write_text("the fleet's logs\n", encoding="utf-8")
    return root


@pytest.fixture(scope="module")
def s3(fleet: Path) -> Iterator[Any]:
    """moto's standalone S3 server on 127.0.0.1 with the fleet uploaded to s3://folders/LOG; the s3fs filesystem."""
    with s3_server(fleet, "folders") as (_, fs):
        yield fs


def run(inputs: list[str], output: Path) -> FleetResult:
    discarded: dict[str, int] = {}
    jobs = collect_jobs(inputs, discarded=discarded)
    return run_fleet(jobs, output, FleetOptions(workers=1, progress=False), set_aside=discarded)


@pytest.fixture(scope="module")
def local_run(fleet: Path, tmp_path_factory: pytest.TempPathFactory) -> FleetResult:
    return run([str(fleet)], tmp_path_factory.mktemp("local") / "fleet.parquet")


@pytest.fixture(scope="module")
def s3_run(s3: Any, tmp_path_factory: pytest.TempPathFactory) -> FleetResult:
    return run([BUCKET], tmp_path_factory.mktemp("s3") / "fleet.parquet")


def test_the_fleet_from_the_bucket_gives_the_local_table_a_prefix_that_is_one_log_one_row(
    fleet: Path, local_run: FleetResult, s3_run: FleetResult
) -> None:
    local, remote = local_run.logs, s3_run.logs
    assert list(local["log"]) == [str(fleet / p) for p in (*FOLDER_LOGS, PLAIN)]  # the local rule, as it was
    assert list(remote["log"]) == [f"{BUCKET}/{p}" for p in (*FOLDER_LOGS, PLAIN)]  # the prefixes' URLs
    assert list(remote["vehicle_id"]) == ["v01", "v01", "v02", "v02", "v03"]  # the parent folder, as locally
    assert (remote["status"] == "ok").all(), remote[["log", "error"]]
    for column in ("roll_deg", "pitch_deg", "yaw_deg", "roll_sigma_deg", "pitch_sigma_deg"):
        assert list(remote[column].fillna(-999.0)) == list(local[column].fillna(-999.0)), column
    pd.testing.assert_frame_equal(comparable(remote, BUCKET), comparable(local, str(fleet)), check_exact=True)
    pd.testing.assert_frame_equal(
        comparable(s3_run.vehicles.drop(columns=["remounts", "mountings"]), BUCKET),
        comparable(local_run.vehicles.drop(columns=["remounts", "mountings"]), str(fleet)),
        check_exact=True,
    )
    assert not remote["content_hash"].isin(local["content_hash"]).any()  # keyed by the objects' stamps
    # no object of a log folder is a log of its own; the README no reader takes is counted, not dropped unseen
    assert not any(log.startswith(f"{BUCKET}/{folder}/") for log in remote["log"] for folder in FOLDER_LOGS)
    assert s3_run.discarded[NOT_LOGS] == 1 and NOT_LOGS not in local_run.discarded
    assert (remote["n_splits"] == 1).all()


def test_a_resumed_run_against_the_bucket_recalculates_nothing_and_a_changed_folder_only_its_log(
    s3: Any, s3_run: FleetResult, tmp_path: Path
) -> None:
    again = run([BUCKET], s3_run.output)
    assert again.computed == 0 and again.reused == len(s3_run.logs) == 5
    assert list(again.logs["content_hash"]) == list(s3_run.logs["content_hash"])

    output = tmp_path / "fleet.parquet"  # a copy of the finished run, to change the bucket under it
    shutil.copytree(s3_run.parts, output.with_name(s3_run.parts.name))
    s3.pipe("folders/LOG/v02/bag_db3/notes.txt", b"one more object in the bag's folder\n")
    try:
        changed = run([BUCKET], output)
    finally:
        s3.rm("folders/LOG/v02/bag_db3/notes.txt")
    assert changed.computed == 1 and changed.reused == 4  # the folder's objects are its key
    redone = changed.logs.set_index("log").loc[f"{BUCKET}/v02/bag_db3"]
    before = s3_run.logs.set_index("log").loc[f"{BUCKET}/v02/bag_db3"]
    assert redone["content_hash"] != before["content_hash"] and redone["roll_deg"] == before["roll_deg"]
    assert changed.discarded[NOT_LOGS] == 1  # the README: notes.txt is part of the bag's folder, not set aside


def test_a_url_naming_a_log_folder_is_that_one_log(s3: Any) -> None:
    for url in (f"{BUCKET}/v01/rec_a", f"{BUCKET}/v01/rec_a/"):
        (job,) = collect_jobs([url])
        assert job.log == f"{BUCKET}/v01/rec_a" and job.vehicle_id == "v01" and job.job.paths == (job.log,)
        assert len(job.folder_objects) == 6 and job.stamps[0] is not None and job.stamps[0].startswith("objects=6 ")


def test_the_worker_fetches_a_prefix_into_one_folder_with_its_paths_and_leaves_nothing(s3: Any, fleet: Path) -> None:
    bag = fleet / "v02" / "bag_mcap"
    s3.put(str(bag), "folders/FETCH/v02/bag_mcap", recursive=True)  # a copy: the fleet's bucket stays as listed
    try:
        found, _ = storage_logs(
            list_objects("s3://folders/FETCH", {}), LogOptions(), lambda p: is_log(Path(p), LogOptions())
        )
        (log,) = found
        assert log.path == "s3://folders/FETCH/v02/bag_mcap"
        assert sorted(o.relative for o in log.objects) == ["bag_mcap.mcap", "metadata.yaml"]
        with local_folder(log.path, log.objects, {}) as folder:
            local = Path(folder)
            assert local.name == "bag_mcap" and is_log(local, LogOptions())
            assert sorted(p.name for p in local.iterdir()) == ["bag_mcap.mcap", "metadata.yaml"]
            for name in ("bag_mcap.mcap", "metadata.yaml"):
                assert (local / name).read_bytes() == (bag / name).read_bytes()
        assert not local.parent.parent.exists()  # the scratch folder went with the block

        s3.pipe("folders/FETCH/v02/bag_mcap/metadata.yaml", (bag / "metadata.yaml").read_bytes() + b"\n")
        with pytest.raises(InputError, match="changed during the run"), local_folder(log.path, log.objects, {}):
            pass
        outside = RemoteObject("s3://folders/FETCH/v02/x.csv", 1, "etag=x", "../x.csv")
        with pytest.raises(InputError, match="Rename it"), local_folder(log.path, (outside,), {}):
            pass
    finally:
        s3.rm("folders/FETCH", recursive=True)


def test_a_listed_folder_is_judged_by_the_rule_that_judges_it_on_disk(fleet: Path) -> None:
    names = [p.relative_to(fleet).as_posix() for p in fleet.rglob("*") if p.is_file()]
    listing = Listing(names)
    folders = {p.relative_to(fleet).as_posix() for p in fleet.rglob("*") if p.is_dir()}
    judged = {f: is_log_folder(listing.folder(f), LogOptions()) for f in folders}
    assert judged == {f: is_log(fleet / f, LogOptions()) for f in folders}
    assert {f for f, one in judged.items() if one} == set(FOLDER_LOGS)


def test_objects_of_a_log_folder_that_no_file_can_be_are_counted_and_never_logs_of_their_own() -> None:
    stamp = "etag=e size=1 mtime=t"
    keys = ["v01/rec/Metadata.csv", "v01/rec/Gravity.csv", "v01/rec//Accelerometer.csv", "v01/rec/../x.csv"]
    keys += ["v01/loose.mcap", "v01/notes.txt", "rec2/Metadata.csv"]
    objects = [RemoteObject(f"s3://b/LOG/{k}", 1, stamp, k) for k in keys]
    found, set_aside = storage_logs(objects, LogOptions(), lambda p: is_log(Path(p), LogOptions()))
    # a walk's order; rec2 holds no sensor's CSV: no recording, and its Metadata.csv a table, as on disk
    assert [f.path for f in found] == [
        "s3://b/LOG/rec2/Metadata.csv",
        "s3://b/LOG/v01/rec",
        "s3://b/LOG/v01/loose.mcap",
    ]
    assert sorted(o.relative for o in found[1].objects) == ["Gravity.csv", "Metadata.csv"]
    assert found[1].stamp is not None and found[1].stamp.startswith("objects=2 ")
    assert set_aside == {NO_FILE_PATH: 2, NOT_LOGS: 1}  # the notes no reader takes


@pytest.mark.real_data
def test_a_real_comma2k19_segment_in_the_bucket_is_one_log_as_on_disk(real_data: Path, s3: Any, tmp_path: Path) -> None:
    segment = real_data / "comma2k19" / SEGMENT
    logs = tmp_path / "REAL" / "rav4"
    logs.mkdir(parents=True)
    (logs / "seg40").symlink_to(segment, target_is_directory=True)
    local = run([str(tmp_path / "REAL")], tmp_path / "local.parquet")
    s3.put(str(segment), "folders/REAL/rav4/seg40", recursive=True)
    try:
        remote = run(["s3://folders/REAL"], tmp_path / "s3.parquet")
    finally:
        s3.rm("folders/REAL", recursive=True)
    assert list(remote.logs["log"]) == ["s3://folders/REAL/rav4/seg40"] and list(remote.logs["vehicle_id"]) == ["rav4"]
    assert remote.discarded.get(NOT_LOGS, 0) == 0  # every object is part of the segment (before: all dropped)
    pd.testing.assert_frame_equal(
        comparable(remote.logs, "s3://folders/REAL"), comparable(local.logs, str(tmp_path / "REAL")), check_exact=True
    )


def test_an_endpoint_changed_between_two_runs_in_one_process_is_the_one_reached(tmp_path: Path) -> None:
    """A notebook points AWS_ENDPOINT_URL at another server between two runs: fsspec keys its filesystems by
    their arguments, not by the environment, and reached the first server still (here stopped: a connection
    error; were it running, its bucket would have been listed in place of the one asked for)."""
    import os

    server_module = pytest.importorskip("moto.server")
    pytest.importorskip("s3fs")
    keys = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1"}
    saved = {k: os.environ.get(k) for k in (*keys, "AWS_ENDPOINT_URL")}
    first = server_module.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    second = server_module.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    try:
        os.environ.update(keys)
        first.start()
        host, port = first.get_host_and_port()
        os.environ["AWS_ENDPOINT_URL"] = f"http://{host}:{port}"
        import s3fs

        writer = s3fs.S3FileSystem(skip_instance_cache=True)
        writer.mkdir("endpoints")
        writer.pipe("endpoints/LOG/v01/a.mcap", PARKING.read_bytes())
        assert [o.url for o in list_objects("s3://endpoints/LOG", {})] == ["s3://endpoints/LOG/v01/a.mcap"]
        first.stop()
        second.start()  # moto keeps one store per process: the second server holds the same bucket
        host, port = second.get_host_and_port()
        os.environ["AWS_ENDPOINT_URL"] = f"http://{host}:{port}"
        assert [o.url for o in list_objects("s3://endpoints/LOG", {})] == ["s3://endpoints/LOG/v01/a.mcap"]
    finally:
        with contextlib.suppress(Exception):  # not started when the first part failed
            second.stop()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
