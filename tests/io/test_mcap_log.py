"""The vectorized MCAP reader against the per-message ROS 2 decoder, on logs from the real writers."""

from __future__ import annotations

import hashlib
import json
import math
import re
import struct
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer

from mountcal.core.errors import InputError
from mountcal.io.mcap.inspect import inspect_mcap
from mountcal.io.mcap.read import iter_mcap, read_mcap

# --------------------------------------------------------------------------- message definitions

_SEP = "=" * 80
_HEADER = f"""{_SEP}
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
{_SEP}
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
_VECTOR3 = f"""{_SEP}
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"""
_QUATERNION = f"""{_SEP}
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w
"""
IMU_MSGDEF = (
    """std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
"""
    + _HEADER
    + _QUATERNION
    + _VECTOR3
)
TEMPERATURE_MSGDEF = "std_msgs/Header header\nfloat64 temperature\nfloat64 variance\n" + _HEADER
NAVSATFIX_MSGDEF = (
    """uint8 COVARIANCE_TYPE_UNKNOWN=0
std_msgs/Header header
sensor_msgs/NavSatStatus status
float64 latitude
float64 longitude
float64 altitude
float64[9] position_covariance
uint8 position_covariance_type
"""
    + _HEADER
    + f"""{_SEP}
MSG: sensor_msgs/NavSatStatus
int8 STATUS_NO_FIX=-1
int8 STATUS_FIX=0
uint16 SERVICE_GPS=1
int8 status
uint16 service
"""
)
ODOMETRY_MSGDEF = (
    """std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist
"""
    + _HEADER
    + f"""{_SEP}
MSG: geometry_msgs/PoseWithCovariance
geometry_msgs/Pose pose
float64[36] covariance
{_SEP}
MSG: geometry_msgs/Pose
geometry_msgs/Point position
geometry_msgs/Quaternion orientation
{_SEP}
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
"""
    + _QUATERNION
    + f"""{_SEP}
MSG: geometry_msgs/TwistWithCovariance
geometry_msgs/Twist twist
float64[36] covariance
{_SEP}
MSG: geometry_msgs/Twist
geometry_msgs/Vector3 linear
geometry_msgs/Vector3 angular
"""
    + _VECTOR3
)

T0_NS = 1_700_000_000 * 10**9
DT_NS = 5_000_000  # 200 Hz


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}


def _xyz(v: Sequence[float]) -> dict[str, float]:
    return {"x": v[0], "y": v[1], "z": v[2]}


def imu_msg(t_ns: int, acc: Sequence[float], gyro: Sequence[float], frame_id: str = "imu_link") -> dict[str, Any]:
    cov = [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01]
    return {
        "header": {"stamp": _stamp(t_ns), "frame_id": frame_id},
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        "orientation_covariance": cov,
        "angular_velocity": _xyz(gyro),
        "angular_velocity_covariance": cov,
        "linear_acceleration": _xyz(acc),
        "linear_acceleration_covariance": cov,
    }


def _yaw_quaternion(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def write_log(
    path: Path,
    *,
    n: int = 400,
    chunk_size: int = 4096,
    compression: CompressionType = CompressionType.ZSTD,
    frame_ids: Sequence[str] = ("imu_link",),
    imu_topics: Sequence[str] = ("/imu/data",),
    aux: bool = True,
    seed: int = 0,
) -> Path:
    """A drive-like log from the real ROS 2 writer: IMU at 200 Hz, temperature, fix and odometry."""
    rng = np.random.default_rng(seed)
    with open(path, "wb") as f, Ros2Writer(f, chunk_size=chunk_size, compression=compression) as writer:
        imu = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
        temp = writer.register_msgdef("sensor_msgs/msg/Temperature", TEMPERATURE_MSGDEF)
        fix = writer.register_msgdef("sensor_msgs/msg/NavSatFix", NAVSATFIX_MSGDEF)
        odom = writer.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY_MSGDEF)
        for i in range(n):
            t_ns = T0_NS + i * DT_NS
            for k, topic in enumerate(imu_topics):
                acc = rng.normal([0.3, -0.2, 9.8], 0.05) + k
                gyro = rng.normal(0.0, 0.01, 3)
                frame_id = frame_ids[i % len(frame_ids)]
                writer.write_message(topic, imu, imu_msg(t_ns, acc, gyro, frame_id), log_time=t_ns + 1_000_000)
            if aux and i % 10 == 3:
                msg = {"header": {"stamp": _stamp(t_ns), "frame_id": "board"}, "temperature": 25.0 + i / 100}
                writer.write_message("/imu/temperature", temp, msg, log_time=t_ns + 2_000_000)
            if aux and i % 20 == 7:
                msg = {
                    "header": {"stamp": _stamp(t_ns), "frame_id": "gps"},
                    "status": {"status": -1 if i == 7 else 0, "service": 1},
                    "latitude": 48.1 + i * 1e-6,
                    "longitude": 11.5 - i * 1e-6,
                    "altitude": 520.0 + rng.normal(),
                    "position_covariance": [1.0] * 9,
                    "position_covariance_type": 2,
                }
                writer.write_message("/gps/fix", fix, msg, log_time=t_ns + 3_000_000)
            if aux and i % 5 == 1:
                msg = {
                    "header": {"stamp": _stamp(t_ns), "frame_id": "odom"},
                    "child_frame_id": "base_link" + "_x" * (i % 3),
                    "pose": {"pose": {"position": _xyz(rng.normal(size=3)), "orientation": _yaw_quaternion(i / 50)}},
                    "twist": {"twist": {"linear": _xyz([5.0 + i / 100, 0.1, 0.0]), "angular": _xyz([0, 0, 0.02])}},
                }
                writer.write_message("/odom", odom, msg, log_time=t_ns + 4_000_000)
    return path


def rewrite(src: Path, dst: Path, **writer_options: Any) -> Path:
    """Copy every message of ``src`` into ``dst`` with the plain MCAP writer and other options."""
    with open(src, "rb") as f:
        messages = list(make_reader(f).iter_messages(log_time_order=False))
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    with open(dst, "wb") as out:
        writer = McapWriter(out, **writer_options)
        writer.start(profile="ros2", library="mountcal-tests")
        for schema, channel, message in messages:
            assert schema is not None
            if schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channel_ids:
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_ids[schema.id]
                )
            writer.add_message(
                channel_ids[channel.id], message.log_time, message.data, message.publish_time, message.sequence
            )
        writer.finish()
    return dst


# --------------------------------------------------------------------------- the per-message reference


def _seconds(stamp: Any, log_ns: int) -> float:
    """The reader's documented time rule, message by message."""
    if stamp.sec == 0 and stamp.nanosec == 0:
        return log_ns // 10**9 + (log_ns % 10**9) * 1e-9
    return stamp.sec + stamp.nanosec * 1e-9


def decoded(path: Path, topic: str) -> Iterator[tuple[float, Any]]:
    """(time in s, decoded message) of every message on ``topic``, by mcap_ros2's decoder."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, message, msg in reader.iter_decoded_messages(topics=[topic], log_time_order=False):
            yield _seconds(msg.header.stamp, message.log_time), msg


def _sorted_rows(rows: list[tuple[float, ...]]) -> np.ndarray:
    table = np.array(rows, dtype=np.float64).reshape(len(rows), -1)
    return table[np.argsort(table[:, 0], kind="stable")]


def reference_imu(path: Path, topic: str = "/imu/data") -> np.ndarray:
    """(n, 7) rows of t, acc, gyro: finite ones, sorted by time."""
    rows = []
    for t, m in decoded(path, topic):
        a, g = m.linear_acceleration, m.angular_velocity
        rows.append((t, a.x, a.y, a.z, g.x, g.y, g.z))
    table = _sorted_rows(rows)
    return table[np.isfinite(table).all(axis=1)]


def assert_matches_reference(path: Path, topic: str = "/imu/data", **kwargs: Any) -> None:
    samples = read_mcap(path, topic=topic, **kwargs)
    ref = reference_imu(path, topic)
    assert len(samples) == ref.shape[0] > 0
    np.testing.assert_allclose(samples.t_s, ref[:, 0], rtol=1e-9, atol=0)
    np.testing.assert_allclose(samples.acc_s, ref[:, 1:4], rtol=1e-9, atol=0)
    assert samples.gyro_s is not None
    np.testing.assert_allclose(samples.gyro_s, ref[:, 4:7], rtol=1e-9, atol=0)


def digest(path: Path) -> tuple[str, int]:
    return hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns


# --------------------------------------------------------------------------- 1. vectorized = per message


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.ZSTD, CompressionType.LZ4])
@pytest.mark.parametrize("chunk_size", [600, 4096, 1 << 20])
@pytest.mark.parametrize("frame_ids", [("imu_link",), ("", "imu", "imu_link", "a_rather_long_frame_name/imu_0")])
def test_vectorized_equals_per_message(
    tmp_path: Path, compression: CompressionType, chunk_size: int, frame_ids: tuple[str, ...]
) -> None:
    path = write_log(tmp_path / "log.mcap", chunk_size=chunk_size, compression=compression, frame_ids=frame_ids)
    assert_matches_reference(path)


LAYOUTS: dict[str, dict[str, Any]] = {
    "no message index": {"index_types": IndexType.CHUNK},
    "no chunks": {"use_chunking": False},
    "no summary": {
        "index_types": IndexType.NONE,
        "repeat_channels": False,
        "repeat_schemas": False,
        "use_statistics": False,
        "use_summary_offsets": False,
    },
    "lz4, small chunks, no index": {
        "compression": CompressionType.LZ4,
        "chunk_size": 700,
        "index_types": IndexType.NONE,
    },
}


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("aux", [False, True], ids=["imu only", "mixed topics"])
@pytest.mark.parametrize("frame_ids", [("imu_link",), ("i", "imu_link_12")], ids=["fixed frame_id", "varying"])
def test_vectorized_equals_per_message_in_every_layout(
    tmp_path: Path, layout: str, aux: bool, frame_ids: tuple[str, ...]
) -> None:
    # Without message indexes the reader finds records by stride or by walking them; unchunked
    # logs and logs without a summary take other paths again: all must agree with the decoder.
    original = write_log(tmp_path / "log.mcap", aux=aux, frame_ids=frame_ids)
    path = rewrite(original, tmp_path / "rewritten.mcap", **LAYOUTS[layout])
    assert_matches_reference(path)
    if aux:
        ours, theirs = read_mcap(path).channels, read_mcap(original).channels
        assert (
            sorted(ours)
            == sorted(theirs)
            == ["alt_m", "heading_deg", "lat_deg", "lon_deg", "speed_mps", "temperature_c"]
        )
        for key in ours:
            np.testing.assert_array_equal(ours[key].value, theirs[key].value)


def _shift_message_indexes(src: Path, dst: Path, by: int) -> Path:
    """Copy ``src`` with every message index entry pointing ``by`` bytes off its message."""
    data = bytearray(src.read_bytes())
    pos = 8  # after the magic
    while pos < len(data) - 8:
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x07:  # message index: channel id u16, byte length u32, (log time, offset) u64 pairs
            (records_len,) = struct.unpack_from("<I", data, pos + 11)
            for entry in range(pos + 15, pos + 15 + records_len, 16):
                (offset,) = struct.unpack_from("<Q", data, entry + 8)
                struct.pack_into("<Q", data, entry + 8, offset + by)
        if opcode == 0x0F:  # data end
            break
        pos += 9 + length
    dst.write_bytes(bytes(data))
    return dst


@pytest.mark.parametrize("aux", [False, True], ids=["imu only", "mixed topics"])
def test_a_message_index_that_does_not_fit_its_chunk_is_not_trusted(tmp_path: Path, aux: bool) -> None:
    path = _shift_message_indexes(write_log(tmp_path / "log.mcap", aux=aux), tmp_path / "bad_index.mcap", by=1)
    assert_matches_reference(path)


_finite_or_not = st.one_of(st.floats(-200.0, 200.0, allow_nan=False), st.sampled_from([math.nan, math.inf, -math.inf]))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    frame_ids=st.lists(st.text(max_size=12), min_size=1, max_size=5),
    values=st.lists(st.tuples(*[_finite_or_not] * 6), min_size=1, max_size=40),
    order=st.randoms(use_true_random=False),
)
def test_any_frame_ids_and_values_round_trip(frame_ids: list[str], values: list[tuple[float, ...]], order: Any) -> None:
    # Arbitrary (unicode) frame_ids, shuffled stamps and non-finite values: same as the decoder,
    # with every non-finite sample dropped and counted.
    stamps = [T0_NS + i * DT_NS for i in range(len(values))]
    order.shuffle(stamps)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.mcap"
        with open(path, "wb") as f, Ros2Writer(f, chunk_size=1500) as writer:
            imu = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
            for i, (t_ns, v) in enumerate(zip(stamps, values, strict=True)):
                msg = imu_msg(t_ns, v[:3], v[3:], frame_ids[i % len(frame_ids)])
                writer.write_message("/imu", imu, msg, log_time=T0_NS + i)
        n_bad = sum(not all(map(math.isfinite, v)) for v in values)
        if n_bad == len(values):
            with pytest.raises(InputError, match="NaN or infinite"):
                read_mcap(path)
            return
        samples = read_mcap(path)
        assert samples.dropped == ({"imu_nonfinite": n_bad} if n_bad else {})
        assert np.all(np.diff(samples.t_s) >= 0)
        assert_matches_reference(path, "/imu")


def test_zero_stamp_falls_back_to_log_time(tmp_path: Path) -> None:
    path = tmp_path / "log.mcap"
    log_ns = [T0_NS + 123_456_789, T0_NS + 2 * 10**9 + 1]
    with open(path, "wb") as f, Ros2Writer(f) as writer:
        imu = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
        writer.write_message("/imu", imu, imu_msg(0, [0, 0, 9.8], [0, 0, 0]), log_time=log_ns[0])
        writer.write_message("/imu", imu, imu_msg(T0_NS + 10**9, [0, 0, 9.8], [0, 0, 0]), log_time=log_ns[1])
    samples = read_mcap(path)
    assert samples.t_s.tolist() == [1_700_000_000 + 0.123456789, 1_700_000_001.0]


def test_json_encoded_messages(tmp_path: Path) -> None:
    path = tmp_path / "json.mcap"
    rng = np.random.default_rng(1)
    expected = []
    with open(path, "wb") as f:
        writer = McapWriter(f, chunk_size=2000)
        writer.start()
        schema = writer.register_schema("sensor_msgs/msg/Imu", "jsonschema", b"{}")
        channel = writer.register_channel("/imu", "json", schema)
        for i in range(60):
            t_ns = T0_NS + (59 - i) * DT_NS  # newest first: the reader sorts
            acc, gyro = rng.normal(size=3), rng.normal(size=3)
            payload = json.dumps(imu_msg(t_ns, acc.tolist(), gyro.tolist())).encode()
            writer.add_message(channel, log_time=T0_NS + i, data=payload, publish_time=T0_NS + i)
            expected.append((t_ns // 10**9 + (t_ns % 10**9) * 1e-9, *acc, *gyro))
        writer.finish()
    ref = _sorted_rows(expected)
    samples = read_mcap(path)
    assert samples.gyro_s is not None
    np.testing.assert_allclose(np.column_stack([samples.t_s, samples.acc_s, samples.gyro_s]), ref, rtol=1e-12)


@pytest.mark.parametrize("encoding", ["cdr", "json"])
@pytest.mark.parametrize("unknown_every", [1, 7])
def test_a_gyro_marked_unknown_is_not_used(tmp_path: Path, encoding: str, unknown_every: int) -> None:
    """REP 145: angular_velocity_covariance[0] = −1 marks a gyro the device does not provide (an
    accelerometer alone publishes zeros there). Such rates are not used — not even when only some
    messages say so — and the count is reported; the accelerations are all kept."""
    path = tmp_path / f"{encoding}.mcap"
    n = 70
    marked = [i for i in range(n) if i % unknown_every == 0]
    with open(path, "wb") as f:
        if encoding == "cdr":
            ros = Ros2Writer(f)
            schema = ros.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
        else:
            raw = McapWriter(f)
            raw.start()
            channel = raw.register_channel(
                "/imu", "json", raw.register_schema("sensor_msgs/msg/Imu", "jsonschema", b"{}")
            )
        for i in range(n):
            t_ns = T0_NS + i * DT_NS
            msg = imu_msg(t_ns, [0.1, 0.2, 9.8], [0.0, 0.0, 0.0])
            if i in marked:
                msg["angular_velocity_covariance"] = [-1.0] + [0.0] * 8
            if encoding == "cdr":
                ros.write_message("/imu", schema, msg, log_time=t_ns)
            else:
                raw.add_message(channel, log_time=t_ns, data=json.dumps(msg).encode(), publish_time=t_ns)
        ros.finish() if encoding == "cdr" else raw.finish()
    samples = read_mcap(path)
    assert samples.gyro_s is None
    assert len(samples) == n
    assert samples.dropped["imu_gyro_marked_unknown"] == len(marked)
    batches = list(iter_mcap(path, max_samples=n))  # one batch: the same decision streamed
    assert len(batches) == 1 and batches[0].gyro_s is None


# --------------------------------------------------------------------------- 2. streaming


@pytest.mark.parametrize("max_samples", [1, 37, 128, 10_000])
def test_iter_chunks_concatenate_to_read(tmp_path: Path, max_samples: int) -> None:
    path = write_log(tmp_path / "log.mcap", n=700, chunk_size=3000)
    whole = read_mcap(path)
    batches = list(iter_mcap(path, max_samples=max_samples))
    assert all(0 < len(b) <= max_samples for b in batches)
    assert len(batches) == math.ceil(700 / max_samples)
    np.testing.assert_array_equal(np.concatenate([b.t_s for b in batches]), whole.t_s)
    np.testing.assert_array_equal(np.concatenate([b.acc_s for b in batches]), whole.acc_s)
    np.testing.assert_array_equal(np.concatenate([b.gyro_s for b in batches if b.gyro_s is not None]), whole.gyro_s)
    assert all(b.source == str(path) for b in batches)
    assert whole.channels  # the auxiliary channels come with the batches, each sample once
    for key, channel in whole.channels.items():
        parts = [b.channels[key] for b in batches if key in b.channels]
        np.testing.assert_array_equal(np.concatenate([c.t_s for c in parts]), channel.t_s)
        np.testing.assert_array_equal(np.concatenate([c.value for c in parts]), channel.value)


def test_single_thread_path_equals_threaded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A process limited to one thread (OMP_NUM_THREADS=1, as fleet workers) decompresses inline."""
    path = write_log(tmp_path / "log.mcap", n=3000, chunk_size=3000)
    threaded = read_mcap(path)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    inline = read_mcap(path)
    np.testing.assert_array_equal(inline.t_s, threaded.t_s)
    np.testing.assert_array_equal(inline.acc_s, threaded.acc_s)
    np.testing.assert_array_equal(inline.gyro_s, threaded.gyro_s)


PEAKS = """
import json, sys, time, tracemalloc
from mountcal.io.mcap.read import iter_mcap, read_mcap

def peak(fn):
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()

short, long = sys.argv[1:]
def n(path):
    # a consumer slower than the read-ahead: the worker fills its queue every time, so the peak is the bound's
    # worst case however the threads are scheduled (a busy machine otherwise lets the short log's run stay lower)
    total = 0
    for batch in iter_mcap(path, max_samples=500):
        time.sleep(0.002)
        total += len(batch)
    return total
peak(lambda: n(short))  # first use: imports and caches are not the stream's memory
print(json.dumps([peak(lambda: n(short)), peak(lambda: n(long)), peak(lambda: read_mcap(long)), n(short), n(long)]))
"""


def test_iter_memory_does_not_grow_with_log_length(tmp_path: Path) -> None:
    # Chunks large enough that the data in flight, not the per-chunk index entries (which do grow
    # with the number of chunks, ~2 kB each), set the peak. Measured in a fresh process: tracemalloc
    # counts every thread's allocations, and threads other tests leave behind would be counted too.
    short = write_log(tmp_path / "short.mcap", n=6000, aux=False, chunk_size=128_000)
    long = write_log(tmp_path / "long.mcap", n=24_000, aux=False, chunk_size=128_000)
    done = subprocess.run([sys.executable, "-c", PEAKS, str(short), str(long)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    peak_short, peak_long, peak_read, n_short, n_long = json.loads(done.stdout)
    assert (n_short, n_long) == (6000, 24_000)
    assert peak_long < 1.3 * peak_short  # 4x the log, (about) the same memory
    assert peak_long < 0.5 * peak_read  # while reading it whole needs far more


def test_iter_can_be_abandoned_and_checks_eagerly(tmp_path: Path) -> None:
    path = write_log(tmp_path / "log.mcap", n=300, chunk_size=2000)
    for batch in iter_mcap(path, max_samples=50):
        assert len(batch) == 50
        break  # the generator closes the file and its worker; a leak would fail under -W error
    with pytest.raises(InputError, match="'/nope'"):
        iter_mcap(path, topic="/nope")  # before any iteration
    with pytest.raises(ValueError, match="max_samples"):
        iter_mcap(path, max_samples=0)


# --------------------------------------------------------------------------- 3. aux channels


def test_aux_channels_match_the_decoder(tmp_path: Path) -> None:
    path = write_log(tmp_path / "log.mcap", n=500, chunk_size=2500)
    samples = read_mcap(path)
    ch = samples.channels

    temp = _sorted_rows([(t, m.temperature) for t, m in decoded(path, "/imu/temperature")])
    np.testing.assert_allclose(ch["temperature_c"].t_s, temp[:, 0], rtol=1e-9)
    np.testing.assert_allclose(ch["temperature_c"].value, temp[:, 1], rtol=1e-9)

    fixes = [(t, m.latitude, m.longitude, m.altitude) for t, m in decoded(path, "/gps/fix") if m.status.status >= 0]
    fix = _sorted_rows(fixes)
    assert samples.dropped["fix_no_fix"] == 1  # the one message with status −1
    for col, key in enumerate(["lat_deg", "lon_deg", "alt_m"], start=1):
        np.testing.assert_allclose(ch[key].t_s, fix[:, 0], rtol=1e-9)
        np.testing.assert_allclose(ch[key].value, fix[:, col], rtol=1e-9)

    odom = []
    for t, m in decoded(path, "/odom"):
        q = m.pose.pose.orientation
        yaw = math.degrees(math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2)))
        odom.append((t, m.twist.twist.linear.x, (90.0 - yaw) % 360.0))
    ref = _sorted_rows(odom)
    np.testing.assert_allclose(ch["speed_mps"].t_s, ref[:, 0], rtol=1e-9)
    np.testing.assert_allclose(ch["speed_mps"].value, ref[:, 1], rtol=1e-9)
    np.testing.assert_allclose(ch["heading_deg"].value, ref[:, 2], rtol=1e-9)


@pytest.mark.parametrize(
    ("yaw_enu_deg", "heading_deg"), [(0, 90), (90, 0), (180, 270), (-90, 180), (45, 45), (-135, 225)]
)
def test_heading_is_compass_convention(tmp_path: Path, yaw_enu_deg: float, heading_deg: float) -> None:
    # ENU yaw is counter-clockwise from east; the compass heading is clockwise from north.
    path = tmp_path / "log.mcap"
    with open(path, "wb") as f, Ros2Writer(f) as writer:
        imu = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
        odom = writer.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY_MSGDEF)
        writer.write_message("/imu", imu, imu_msg(T0_NS, [0, 0, 9.8], [0, 0, 0]), log_time=T0_NS)
        pose = {"orientation": _yaw_quaternion(math.radians(yaw_enu_deg))}
        msg = {
            "header": {"stamp": _stamp(T0_NS)},
            "pose": {"pose": pose},
            "twist": {"twist": {"linear": _xyz([1, 0, 0])}},
        }
        writer.write_message("/odom", odom, msg, log_time=T0_NS)
    heading = read_mcap(path).channels["heading_deg"].value
    assert heading.shape == (1,)
    assert 0.0 <= heading[0] < 360.0
    assert heading[0] == pytest.approx(heading_deg, abs=1e-9)


def test_aux_topics_chosen_by_name_or_disabled(tmp_path: Path) -> None:
    path = write_log(tmp_path / "log.mcap", n=100)
    assert "temperature_c" not in read_mcap(path, temperature_topic="").channels
    assert len(read_mcap(path, fix_topic="/gps/fix").channels["lat_deg"].t_s) == 4  # i = 27, 47, 67, 87
    with pytest.raises(InputError, match="sensor_msgs/msg/Temperature") as err:
        read_mcap(path, temperature_topic="/odom")
    assert "nav_msgs/msg/Odometry" in str(err.value)


# --------------------------------------------------------------------------- 4. the real ROS 2 recording

REAL_MCAP = "robot_localization/test1_ros2_mcap/test1_ros2_mcap.mcap"


@pytest.mark.real_data
def test_real_ros2_recording(real_data: Path) -> None:
    path = real_data / REAL_MCAP
    before = digest(path)
    samples = read_mcap(path)
    assert len(samples) == 11865
    assert samples.dropped == {}
    np.testing.assert_allclose(samples.acc_s.mean(axis=0), [-0.22, 9.79, 0.08], atol=0.01)  # gravity on +y
    assert_matches_reference(path, "/imu/data")
    assert {"lat_deg", "lon_deg", "alt_m", "speed_mps", "heading_deg"} <= set(samples.channels)
    assert len(samples.channels["speed_mps"].t_s) == 3952
    assert digest(path) == before


@pytest.mark.real_data
def test_inspect_real_recording(real_data: Path) -> None:
    summary = inspect_mcap(real_data / REAL_MCAP)
    streams = {s.name: s for s in summary.streams}
    assert {name: (s.kind, s.count) for name, s in streams.items()} == {
        "/imu/data": ("sensor_msgs/msg/Imu", 11865),
        "/husky_velocity_controller/odom": ("nav_msgs/msg/Odometry", 3952),
        "/fix": ("sensor_msgs/msg/NavSatFix", 989),
    }
    assert summary.format == "mcap"
    assert summary.duration_s == pytest.approx(395.307116140, abs=1e-6)
    assert streams["/imu/data"].rate_hz == pytest.approx(30.0, rel=0.01)
    assert "linear_acceleration" in streams["/imu/data"].fields


def test_inspect_without_summary_scans(tmp_path: Path) -> None:
    path = write_log(tmp_path / "log.mcap", n=200)
    bare = rewrite(path, tmp_path / "bare.mcap", **LAYOUTS["no summary"])
    for summary in (inspect_mcap(path), inspect_mcap(bare)):
        streams = {s.name: s for s in summary.streams}
        assert streams["/imu/data"].count == 200
        assert streams["/imu/data"].rate_hz == pytest.approx(200.0)
        assert streams["/odom"].count == 40
        assert summary.duration_s == pytest.approx(199 * DT_NS * 1e-9)  # first to last IMU log time


# --------------------------------------------------------------------------- 5. bad inputs


def _two_imu_topics(tmp_path: Path) -> Path:
    return write_log(tmp_path / "two.mcap", n=50, imu_topics=("/imu/left", "/imu/right"), aux=False)


def _no_imu(tmp_path: Path) -> Path:
    path = tmp_path / "no_imu.mcap"
    with open(path, "wb") as f, Ros2Writer(f) as writer:
        temp = writer.register_msgdef("sensor_msgs/msg/Temperature", TEMPERATURE_MSGDEF)
        writer.write_message("/temp", temp, {"temperature": 20.0}, log_time=T0_NS)
    return path


def _two_temperature_topics(tmp_path: Path) -> Path:
    path = tmp_path / "two_temps.mcap"
    with open(path, "wb") as f, Ros2Writer(f) as writer:
        imu = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_MSGDEF)
        temp = writer.register_msgdef("sensor_msgs/msg/Temperature", TEMPERATURE_MSGDEF)
        writer.write_message("/imu", imu, imu_msg(T0_NS, [0, 0, 9.8], [0, 0, 0]), log_time=T0_NS)
        for topic in ("/temp/board", "/temp/imu"):
            writer.write_message(topic, temp, {"temperature": 20.0}, log_time=T0_NS)
    return path


def _truncated(tmp_path: Path) -> Path:
    data = write_log(tmp_path / "full.mcap", n=300).read_bytes()
    path = tmp_path / "truncated.mcap"
    path.write_bytes(data[: len(data) // 2])
    return path


def _corrupt(tmp_path: Path) -> Path:
    data = bytearray(write_log(tmp_path / "full.mcap", n=300, chunk_size=1 << 20).read_bytes())
    middle = len(data) // 2  # inside the one zstd chunk
    data[middle : middle + 16] = bytes(range(16))
    path = tmp_path / "corrupt.mcap"
    path.write_bytes(bytes(data))
    return path


def _empty(tmp_path: Path) -> Path:
    path = tmp_path / "empty.mcap"
    path.write_bytes(b"")
    return path


def _csv(tmp_path: Path) -> Path:
    path = tmp_path / "log.mcap"
    path.write_text("t,ax,ay,az\n0,0,0,9.8\n")
    return path


def _no_messages(tmp_path: Path) -> Path:
    path = tmp_path / "silent.mcap"
    with open(path, "wb") as f:
        writer = McapWriter(f)
        writer.start()
        schema = writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", IMU_MSGDEF.encode())
        writer.register_channel("/imu", "cdr", schema)
        writer.finish()
    return path


def _raw_imu_log(tmp_path: Path, name: str, encoding: str, schema_text: str, payload: bytes) -> Path:
    path = tmp_path / name
    with open(path, "wb") as f:
        writer = McapWriter(f)
        writer.start()
        schema = writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", schema_text.encode())
        channel = writer.register_channel("/imu", encoding, schema)
        writer.add_message(channel, log_time=T0_NS, data=payload, publish_time=T0_NS)
        writer.finish()
    return path


def _a_payload(tmp_path: Path) -> bytes:
    with open(write_log(tmp_path / "one.mcap", n=1, aux=False), "rb") as f:
        return next(iter(make_reader(f).iter_messages()))[2].data


def _ros1(tmp_path: Path) -> Path:
    return _raw_imu_log(tmp_path, "ros1.mcap", "ros1", IMU_MSGDEF, b"\x00" * 300)


def _big_endian(tmp_path: Path) -> Path:
    payload = b"\x00\x00" + _a_payload(tmp_path)[2:]
    return _raw_imu_log(tmp_path, "be.mcap", "cdr", IMU_MSGDEF, payload)


def _cut_message(tmp_path: Path) -> Path:
    return _raw_imu_log(tmp_path, "cut.mcap", "cdr", IMU_MSGDEF, _a_payload(tmp_path)[:200])


def _custom_schema(tmp_path: Path) -> Path:
    schema = "std_msgs/Header header\ngeometry_msgs/Vector3 linear_acceleration\n" + _HEADER + _VECTOR3
    return _raw_imu_log(tmp_path, "custom.mcap", "cdr", schema, _a_payload(tmp_path))


BAD_INPUTS = {
    # name: (make the file, read arguments, fragments the message must contain)
    "truncated": (_truncated, {}, ["truncated", "mcap recover"]),
    "corrupt bytes": (_corrupt, {}, ["chunk at byte", "decompress|CRC"]),
    "zero bytes": (_empty, {}, ["empty file (0 bytes)"]),
    "not mcap": (_csv, {}, ["an MCAP file", "74 2c 61 78"]),  # "t,ax"
    "no IMU topic": (_no_imu, {}, ["exactly one sensor_msgs/msg/Imu topic", "'/temp'", "--topic"]),
    "wrong topic": (lambda p: write_log(p / "log.mcap", n=20), {"topic": "/imu"}, ["'/imu'", "'/imu/data'", "--topic"]),
    "two IMU topics": (_two_imu_topics, {}, ["2: '/imu/left', '/imu/right'", "--topic"]),
    "two temperature topics": (_two_temperature_topics, {}, ["'/temp/board', '/temp/imu'", "--temperature-topic"]),
    "no messages": (_no_messages, {}, ["no messages on '/imu'"]),
    "ros1 encoding": (_ros1, {}, ["message encoding 'ros1'", "CDR"]),
    "big-endian CDR": (_big_endian, {}, ["encapsulation header 00 00", "big-endian"]),
    "message cut short": (_cut_message, {}, ["too short", "Imu"]),
    "custom schema": (_custom_schema, {}, ["standard sensor_msgs/msg/Imu fields", "Vector3 linear_acceleration"]),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_is_an_informative_input_error(tmp_path: Path, case: str) -> None:
    make, kwargs, fragments = BAD_INPUTS[case]
    path = make(tmp_path)
    before = digest(path)
    with pytest.raises(InputError) as err:
        read_mcap(path, **kwargs)
    text = str(err.value)
    assert text.startswith(f"{path}: expected ")
    for fragment in fragments:
        assert any(alt in text for alt in fragment.split("|")), f"{fragment!r} not in {text!r}"
    assert digest(path) == before


@pytest.mark.parametrize("case", ["truncated", "zero bytes", "not mcap"])
def test_bad_file_fails_inspect_and_iter_too(tmp_path: Path, case: str) -> None:
    path = BAD_INPUTS[case][0](tmp_path)
    with pytest.raises(InputError, match=re.escape(str(path))):
        inspect_mcap(path)
    with pytest.raises(InputError, match=re.escape(str(path))):
        list(iter_mcap(path))


def test_corrupt_chunk_found_by_iter_not_by_inspect(tmp_path: Path) -> None:
    # inspect reads the summary and the indexes only; damage inside a chunk shows when it is read.
    path = _corrupt(tmp_path)
    assert {s.name: s.count for s in inspect_mcap(path).streams}["/imu/data"] == 300
    with pytest.raises(InputError, match="chunk at byte"):
        list(iter_mcap(path))


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        read_mcap(tmp_path / "absent.mcap")
