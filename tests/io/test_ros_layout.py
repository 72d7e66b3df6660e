"""Field offsets from message definitions, on whole arrays, against rosbags' own serialisers.

Messages of a custom type (strings, sequences, fixed arrays and a wrapped Imu, in varied lengths)
are serialised by rosbags (CDR and ROS 1) and read back by :mod:`mountcal.io.ros.kinds`: every
value must come back exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from mountcal.io.ros.kinds import decode, target
from mountcal.io.ros.types import from_definition
from mountcal.io.ros2.cdr import CdrError, Rows, cdr_rows

WRAPPED = "test_msgs/msg/Wrapped"
DEFINITION = """std_msgs/Header header
uint8 flag
string note
float32[] samples
int16[3] triple
geometry_msgs/Point[] path
string[] names
sensor_msgs/Imu imu
bool ok
geometry_msgs/Vector3 extra
"""


def _store(ros1: bool) -> Any:
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(DEFINITION, WRAPPED))
    return store


def _message(store: Any, i: int, note: str, n_samples: int, n_path: int, names: list[str], ros1: bool) -> Any:
    t = store.types
    header_args: dict[str, Any] = {"stamp": t["builtin_interfaces/msg/Time"](sec=1000 + i, nanosec=7 * i + 1)}
    header_args["frame_id"] = f"imu{i % 3}"
    if ros1:
        header_args["seq"] = i
    header = t["std_msgs/msg/Header"](**header_args)
    vec = t["geometry_msgs/msg/Vector3"]
    imu_header_args = dict(header_args, stamp=t["builtin_interfaces/msg/Time"](sec=2000 + i, nanosec=3 * i))
    cov = np.zeros(9)
    cov[0] = -1.0 if i % 2 else 0.5
    imu = t["sensor_msgs/msg/Imu"](
        header=t["std_msgs/msg/Header"](**imu_header_args),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.zeros(9),
        angular_velocity=vec(x=0.1 * i, y=-0.2 * i, z=0.3),
        angular_velocity_covariance=cov,
        linear_acceleration=vec(x=1.5 + i, y=-2.5, z=9.8 - i * 1e-3),
        linear_acceleration_covariance=np.zeros(9),
    )
    point = t["geometry_msgs/msg/Point"]
    return t[WRAPPED](
        header=header,
        flag=i % 256,
        note=note,
        samples=np.arange(n_samples, dtype=np.float32),
        triple=np.array([1, -2, 3], dtype=np.int16),
        path=[point(x=float(k), y=0.0, z=-1.0) for k in range(n_path)],
        names=names,
        imu=imu,
        ok=bool(i % 2),
        extra=vec(x=float(i), y=2.0, z=3.0),
    )


def _rows(payloads: list[bytes], cdr: bool) -> Rows:
    sizes = np.array([len(p) for p in payloads], dtype=np.int64)
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    buf = np.frombuffer(b"".join(payloads), dtype=np.uint8)
    return cdr_rows(buf, start, sizes) if cdr else Rows(buf, start, sizes)


def _batch(ros1: bool, notes: list[str], n_samples: list[int], n_path: int, names: list[str]) -> tuple[list[Any], Rows]:
    store = _store(ros1)
    msgs = [
        _message(store, i, note, k, n_path, names, ros1)
        for i, (note, k) in enumerate(zip(notes, n_samples, strict=True))
    ]
    payloads = [bytes(store.serialize_ros1(m, WRAPPED) if ros1 else store.serialize_cdr(m, WRAPPED)) for m in msgs]
    return msgs, _rows(payloads, not ros1)


def _types(ros1: bool) -> Any:
    store = _store(ros1)
    text = store.generate_msgdef(WRAPPED, ros_version=1 if ros1 else 2)[0]
    return from_definition(text, WRAPPED)


@pytest.mark.parametrize("ros1", [False, True], ids=["cdr", "ros1"])
@given(
    notes=st.lists(st.text(max_size=9), min_size=1, max_size=6),
    lengths=st.lists(st.integers(0, 5), min_size=6, max_size=6),
    n_path=st.integers(0, 3),
    names=st.lists(st.text(max_size=4), max_size=3),
)
def test_a_wrapped_imu_reads_back_exactly(
    ros1: bool, notes: list[str], lengths: list[int], n_path: int, names: list[str]
) -> None:
    msgs, rows = _batch(ros1, notes, lengths[: len(notes)], n_path, names)
    types = _types(ros1)
    imu = target(types, WRAPPED, "imu")
    assert imu is not None and imu.kind == "imu" and imu.stamp == ("imu", "header", "stamp")
    got = decode(rows, types, imu, cdr=not ros1)
    want_acc = [[m.imu.linear_acceleration.x, m.imu.linear_acceleration.y, m.imu.linear_acceleration.z] for m in msgs]
    want_gyro = [[m.imu.angular_velocity.x, m.imu.angular_velocity.y, m.imu.angular_velocity.z] for m in msgs]
    np.testing.assert_array_equal(got.columns["acc"], want_acc)
    np.testing.assert_array_equal(got.columns["gyro"], want_gyro)
    np.testing.assert_array_equal(
        got.columns["gyro_unknown"], [m.imu.angular_velocity_covariance[0] == -1 for m in msgs]
    )
    np.testing.assert_array_equal(got.sec, [m.imu.header.stamp.sec for m in msgs])
    np.testing.assert_array_equal(got.nanosec, [m.imu.header.stamp.nanosec for m in msgs])
    vector = target(types, WRAPPED, "extra")
    assert vector is not None and vector.kind == "acc" and vector.stamp == ("header", "stamp")
    extra = decode(rows, types, vector, cdr=not ros1)
    np.testing.assert_array_equal(extra.columns["acc"], [[m.extra.x, m.extra.y, m.extra.z] for m in msgs])
    np.testing.assert_array_equal(extra.sec, [m.header.stamp.sec for m in msgs])


def test_fields_after_sequences_of_messages_of_varying_length_are_refused() -> None:
    store = _store(False)
    msgs = [_message(store, i, "n", 1, i, [], False) for i in range(3)]  # path holds 0, 1, 2 points
    rows = _rows([bytes(store.serialize_cdr(m, WRAPPED)) for m in msgs], True)
    types = _types(False)
    imu = target(types, WRAPPED, "imu")
    assert imu is not None
    with pytest.raises(CdrError, match="sequence path holds 0 to 2 elements"):
        decode(rows, types, imu, cdr=True)


def test_a_field_that_is_not_an_imu_or_vector_has_no_target() -> None:
    types = _types(False)
    assert target(types, WRAPPED, "note") is None
    assert target(types, WRAPPED, "imu.nothing") is None
    assert target(types, WRAPPED, "header") is None
    assert target(types, WRAPPED) is None  # not a standard type without --field


def test_a_short_message_is_an_error_not_a_read_past_its_end() -> None:
    msgs, rows = _batch(False, ["abc", "de"], [2, 2], 1, [])
    truncated = Rows(rows.buf, rows.start, rows.size - np.array([0, 150]))  # type: ignore[operator]
    types = _types(False)
    imu = target(types, WRAPPED, "imu")
    assert imu is not None and len(msgs) == 2
    with pytest.raises(CdrError, match="too short"):
        decode(truncated, types, imu, cdr=True)
