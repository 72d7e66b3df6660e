"""One memory and time budget per run (issue 27, reproductions 2, 3 and 7): totals, not blocks.

Each hostile input is built small, with the real writer (python-can's BLFWriter, mcap's Writer)
or by byte construction around it, and the budget lowered through its variable where the
default would need a big file: the refusal names the variable, so the mechanism is what is
tested. The big inputs of the issue are in ``benchmarks/attack.py``. Each command runs in its own
process whose peak RSS (``ru_maxrss``) and time are measured.
"""

from __future__ import annotations

import ast
import json
import os
import resource
import struct
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pandas as pd
import pytest
import zstandard
from mcap.writer import CompressionType, Writer

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.io.ros2.definitions import ros2_definition
from mountcal.io.ros2.imu import ImuMessages, encode_imu_messages

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
MIB = 1 << 20

_MEASURE = """
import resource, subprocess, sys, time
start = time.monotonic()
run = subprocess.run(sys.argv[2:], capture_output=True, text=True, timeout=float(sys.argv[1]))
peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
print(repr((run.returncode, run.stdout, run.stderr, peak_mb, time.monotonic() - start)))
"""


def cli(*args: str, env: dict[str, str] | None = None, timeout: float = 120) -> tuple[int, str, float, float]:
    """Exit code, stderr, peak RSS (MB) and seconds of ``mountcal ARGS`` alone in a measuring process
    (its address space capped at 3 GiB, so a regression fails here instead of exhausting the machine)."""
    environ = {**os.environ, "PYTHONPATH": str(REPO / "src"), **(env or {})}
    cmd = [sys.executable, "-c", _MEASURE, str(timeout), sys.executable, "-m", "mountcal", *args]

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    out = subprocess.run(cmd, capture_output=True, text=True, env=environ, timeout=timeout + 60, preexec_fn=cap)
    assert out.returncode == 0, out.stderr  # the measuring process itself (a timeout raises there)
    code, _, stderr, peak, seconds = ast.literal_eval(out.stdout)
    return code, stderr, peak, seconds


def refused(result: tuple[int, str, float, float], *words: str, peak_mb: float = 600) -> str:
    code, stderr, peak, _ = result
    assert code == 2 and "Traceback" not in stderr, stderr
    for word in words:
        assert word in stderr, stderr
    assert peak < peak_mb, f"peak RSS {peak:.0f} MB"
    return stderr


# --------------------------------------------------------------------------- the mechanism


def test_the_limits_in_the_docs_are_the_code_s() -> None:
    docs = (REPO / "docs" / "reliability.md").read_text(encoding="utf-8")
    assert budget.markdown() in docs, "regenerate: python -m mountcal.core.budget\n" + budget.markdown()


def test_totals_are_per_scope_and_refusals_name_the_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MOUNTCAL_MAX_ROWS", "10")
    with budget.scope() as totals:
        budget.charge("rows", 6, "a.csv", "table rows")
        with budget.scope():  # nested: the same totals
            with pytest.raises(InputError, match=r"a.csv: expected at most 10 table rows \(the MOUNTCAL_MAX_ROWS"):
                budget.charge("rows", 5, "a.csv", "table rows")
        assert totals.counts["rows"] == 11
    with budget.scope():  # a new run starts from zero
        budget.charge("rows", 6, "b.csv", "table rows")


@pytest.mark.parametrize("value", ["inf", "nan", "-1", "0", "1e400", "lots"])
def test_a_limit_variable_outside_its_range_is_refused_by_name(value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """MOUNTCAL_MAX_INPUT_MB=inf was an OverflowError traceback."""
    monkeypatch.setenv("MOUNTCAL_MAX_INPUT_MB", value)
    with pytest.raises(InputError, match="MOUNTCAL_MAX_INPUT_MB"):
        budget.setting("input")
    if value == "inf":  # the command line too
        code, stderr, _, _ = cli("calibrate", str(DATA / "zhang2011_stops.csv"), env={"MOUNTCAL_MAX_INPUT_MB": value})
        assert code == 2 and "MOUNTCAL_MAX_INPUT_MB" in stderr and "Traceback" not in stderr, stderr


def test_the_inflate_ratio_counts_every_block_of_the_run(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MOUNTCAL_MAX_BLOCK_MB", "1")
    monkeypatch.setenv("MOUNTCAL_MAX_INFLATE_RATIO", "10")
    with budget.scope():
        budget.inflate(1000, MIB, "x.mcap", "a chunk")  # one block is always allowed
        budget.inflate(100_000, 900_000, "x.mcap", "a chunk")  # 9×: within the ratio
        with pytest.raises(InputError, match="MOUNTCAL_MAX_INFLATE_RATIO"):
            budget.inflate(1000, MIB, "x.mcap", "a chunk")


# --------------------------------------------------------------------------- BLF


def _blf_of_empty_containers(path: Path, count: int) -> Path:
    """The header python-can's BLFWriter writes, then ``count`` empty log containers (32 bytes each)."""
    real = path.with_suffix(".real.blf")
    with can.BLFWriter(str(real)):
        pass
    raw = real.read_bytes()
    header = raw[: struct.unpack_from("<L", raw, 4)[0]]
    container = struct.pack("<4sHHLL", b"LOBJ", 16, 1, 32, 10) + struct.pack("<H6xL4x", 0, 0)
    body = header + container * count
    size = struct.calcsize("<4sLBBBBBBBB")  # the file's size follows these fields, as a closed writer records it
    path.write_bytes(body[:size] + struct.pack("<Q", len(body)) + body[size + 8 :])
    return path


def test_blf_of_empty_containers_costs_no_memory_per_container(tmp_path: Path) -> None:
    """Two million empty containers (64 MB) made `inspect` hold a future per container: 3.45 GB, then
    MemoryError. Here 300 000 (9.6 MB): the memory must not grow with them, and the records budget
    refuses them when lowered."""
    blf = _blf_of_empty_containers(tmp_path / "empty.blf", 300_000)
    code, stderr, peak, _ = cli("inspect", str(blf))
    assert code == 0 and "Traceback" not in stderr, stderr
    assert peak < 250, f"peak RSS {peak:.0f} MB"  # ~550 MB before: a future and a queue entry per container
    refused(cli("inspect", str(blf), env={"MOUNTCAL_MAX_RECORDS": "100000"}), "MOUNTCAL_MAX_RECORDS", str(blf))


def test_blf_of_a_million_ids_is_refused_by_the_streams_budget(tmp_path: Path) -> None:
    """A 6 MB BLF of a million distinct ids made `inspect` tally a Python object per id: 1 GB, 40 s."""
    blf = tmp_path / "ids.blf"
    with can.BLFWriter(str(blf)) as writer:
        for k in range(3000):
            writer.on_message_received(can.Message(timestamp=1 + k * 1e-3, arbitration_id=k, data=b""))
    refused(cli("inspect", str(blf), env={"MOUNTCAL_MAX_STREAMS": "1000"}), "MOUNTCAL_MAX_STREAMS", str(blf))
    assert cli("inspect", str(blf))[0] == 0


# --------------------------------------------------------------------------- MCAP


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def _mcap_with_chunks(path: Path, records: bytes, chunks: int) -> Path:
    """Header, schema and channel from mcap's Writer, then ``chunks`` zstd chunks each holding
    ``records`` (no index, no summary): the chunks compress thousands of times."""
    real = path.with_suffix(".real.mcap")
    with real.open("wb") as f:
        writer = Writer(f, compression=CompressionType.NONE, use_chunking=False)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(
            "sensor_msgs/msg/Imu", "ros2msg", ros2_definition("sensor_msgs/msg/Imu").encode()
        )
        writer.register_channel("/imu", "cdr", schema)
        writer.finish()
    raw = real.read_bytes()
    pos = 8 + 9 + struct.unpack_from("<Q", raw, 9)[0]
    out = bytearray(raw[:pos])
    while raw[pos] != 0x0F:  # the schema and channel records, up to the data end record
        length = struct.unpack_from("<Q", raw, pos + 1)[0]
        if raw[pos] in (0x03, 0x04):
            out += raw[pos : pos + 9 + length]
        pos += 9 + length
    data = zstandard.ZstdCompressor(level=19).compress(records)
    name = b"zstd"
    body = struct.pack("<QQQI", 0, 0, len(records), 0) + struct.pack("<I", len(name)) + name
    chunk = _record(0x06, body + struct.pack("<Q", len(data)) + data)
    out += chunk * chunks + _record(0x0F, struct.pack("<I", 0)) + _record(0x02, struct.pack("<QQI", 0, 0, 0)) + raw[:8]
    path.write_bytes(bytes(out))
    return path


def _messages(size: int) -> bytes:
    """Message records of the first channel alternating 31 and 32 bytes (no common stride), ``size`` bytes."""
    pair = _record(0x05, struct.pack("<HIQQ", 1, 0, 1, 1)) + _record(0x05, struct.pack("<HIQQ", 1, 0, 2, 2) + b"x")
    return pair * (size // len(pair))


def test_mcap_chunks_inflating_past_the_ratio_are_refused(tmp_path: Path) -> None:
    """A 268 KB MCAP of chunks inflating 10 000-fold: `inspect` walked 2 GiB of records for 92 s in
    1.2 GB. The run's ratio of inflated to compressed bytes refuses the second chunk (the block
    limit, lowered here, is the free allowance of one block)."""
    mcap = _mcap_with_chunks(tmp_path / "msgs.mcap", _messages(4 * MIB), 8)
    assert mcap.stat().st_size < 20_000
    env = {"MOUNTCAL_MAX_BLOCK_MB": "4"}
    refused(cli("inspect", str(mcap), env=env), "MOUNTCAL_MAX_INFLATE_RATIO", str(mcap))
    refused(cli("stops", str(mcap), "-o", str(tmp_path / "s.csv"), env=env), "MOUNTCAL_MAX_INFLATE_RATIO")
    assert not (tmp_path / "s.csv").exists()
    assert cli("inspect", str(mcap), env={**env, "MOUNTCAL_MAX_INFLATE_RATIO": "100000"})[0] == 0


def test_imu_mcap_of_repeated_messages_is_refused_before_it_is_held(tmp_path: Path) -> None:
    """A 3.4 MB MCAP of identical IMU messages inflated to millions of samples: 3 GB, MemoryError."""
    n = 20_000
    msgs = ImuMessages.unknown_orientation(np.full(n, 10**18, np.int64), None, np.tile([0.0, 0.0, 9.81], (n, 1)))
    payload = encode_imu_messages(msgs, "imu")[0].tobytes()
    record = _record(0x05, struct.pack("<HIQQ", 1, 0, 10**18, 10**18) + payload)
    mcap = _mcap_with_chunks(tmp_path / "imu.mcap", record * (4 * MIB // len(record)), 12)
    env = {"MOUNTCAL_MAX_BLOCK_MB": "4"}
    for args in (["calibrate", str(mcap)], ["stops", str(mcap), "-o", str(tmp_path / "s.csv")]):
        refused(cli(*args, env=env), "MOUNTCAL_MAX_INFLATE_RATIO", str(mcap))


# --------------------------------------------------------------------------- tables and documents


def test_a_table_of_too_many_columns_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    """A 32 MB CSV of 10⁶ columns: 2.4 GB in pandas. The header is counted first."""
    names = ["t_s", "ax", "ay", "az", *(f"c{k}" for k in range(20_000))]
    table = tmp_path / "wide.csv"
    table.write_text(",".join(names) + "\n" + ",".join(["0", "0", "0", "9.81"] + ["0"] * 20_000) + "\n")
    refused(cli("inspect", str(table)), "MOUNTCAL_MAX_COLUMNS", str(table))
    refused(cli("calibrate", str(table)), "MOUNTCAL_MAX_COLUMNS", str(table))  # read as a stop table


def test_a_stop_table_of_too_many_rows_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    """A 10⁶-row stop table took 2 GB, 10⁷ rows a traceback; the stops budget refuses them from the
    line count (lowered here: 200 rows against 50)."""
    stops = pd.read_csv(DATA / "zhang2011_stops.csv")
    big = tmp_path / "many.csv"
    pd.concat([stops] * 6, ignore_index=True).to_csv(big, index=False)
    refused(cli("calibrate", str(big), env={"MOUNTCAL_MAX_STOPS": "50"}), "MOUNTCAL_MAX_STOPS", str(big))
    parquet = tmp_path / "many.parquet"
    pd.concat([stops] * 6, ignore_index=True).to_parquet(parquet)
    refused(cli("calibrate", str(parquet), env={"MOUNTCAL_MAX_STOPS": "50"}), "MOUNTCAL_MAX_STOPS")


@pytest.mark.invalid_results
def test_a_big_result_json_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    """A 250 MB result JSON took 3.1 GB to parse; documents are counted against the run's budget
    (lowered here to 1 MiB against a 3 MB file)."""
    result = tmp_path / "r.json"
    assert cli("calibrate", str(DATA / "zhang2011_stops.csv"), "-o", str(result))[0] == 0
    doc = json.loads(result.read_text())
    doc["notes"] += ["x" * 1000] * 3000
    result.write_text(json.dumps(doc))
    env = {"MOUNTCAL_MAX_DOCUMENT_MB": "1"}
    for args in (
        ["export", str(result), "--to", "json", "-o", "-"],
        ["report", str(result), "-o", str(tmp_path / "r.html")],
    ):
        refused(cli(*args, env=env), "MOUNTCAL_MAX_DOCUMENT_MB", str(result))
    assert not (tmp_path / "r.html").exists()


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_a_sensor_spec_that_never_ends_is_refused_unread(device: str, tmp_path: Path) -> None:
    """`--sensor-spec /dev/zero` read it whole: 2.2 GB, then MemoryError."""
    stops = str(DATA / "zhang2011_stops.csv")
    refused(cli("calibrate", stops, "--sensor-spec", device, timeout=60), device, "character device", peak_mb=400)
    refused(cli("plan", "--target", "roll=1", "--noise", "1", "--sensor-spec", device, timeout=60), device)


def _orientations(path: Path) -> Path:
    """Stops of a still sensor in its six faces and twelve edges (a triad session), with their noise."""
    rng = np.random.default_rng(1)
    directions = [
        v for v in np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).reshape(3, -1).T if 0 < abs(v).sum() < 3
    ]
    acc = np.array([9.80665 * v / np.linalg.norm(v) for v in directions]) + rng.normal(0, 1e-3, (len(directions), 3))
    table = pd.DataFrame(acc, columns=["ax", "ay", "az"]).assign(sx=0.01, sy=0.01, sz=0.01, n=100)
    table.to_csv(path, index=False)
    return path


def _nested_quotes(path: Path) -> Path:
    """120 KB: an opening quote, then escaped quotes to the end (never closed)."""
    path.write_bytes(b'{"a": "' + b'\\"' * 60_000)
    return path


@pytest.mark.invalid_results
def test_nested_quotes_are_refused_in_linear_time(tmp_path: Path) -> None:
    """The depth check was a regular expression that is quadratic on escaped quotes: minutes for
    120 KB in export, rotate, report, calibrate --triad and triad --imucal."""
    bad = _nested_quotes(tmp_path / "q.json")
    stops = str(DATA / "zhang2011_stops.csv")
    commands = [
        ["export", str(bad), "--to", "json", "-o", "-"],
        ["rotate", stops, "--calibration", str(bad), "-o", str(tmp_path / "o.parquet")],
        ["report", str(bad), "-o", str(tmp_path / "o.html")],
        ["calibrate", stops, "--triad", str(bad)],
        ["triad", str(_orientations(tmp_path / "faces.csv")), "--imucal", str(bad), "-o", str(tmp_path / "t.json")],
    ]
    for args in commands:
        code, stderr, _, seconds = cli(*args, timeout=60)
        assert code == 2 and "Traceback" not in stderr and str(bad) in stderr, (args, stderr)
        assert seconds < 30, (args, seconds)
    start = time.perf_counter()
    assert budget.nesting_depth(b'"' + b'\\"' * 5_000_000) == 0  # 10 MB
    assert time.perf_counter() - start < 5


@pytest.mark.parametrize(
    ("suffix", "text"),
    [
        (".json", '{"scale": ' + "[" * 100_000 + "]" * 100_000 + "}"),
        (".toml", "scale = " + "[" * 100_000 + "]" * 100_000),
    ],
)
def test_deep_specs_and_mappings_are_refused_without_recursion(suffix: str, text: str, tmp_path: Path) -> None:
    """A deep JSON or TOML sensor spec or mapping ended in a RecursionError traceback."""
    spec = tmp_path / f"deep{suffix}"
    spec.write_text(text)
    refused(cli("calibrate", str(DATA / "zhang2011_stops.csv"), "--sensor-spec", str(spec)), "MOUNTCAL_MAX_DEPTH")
    if suffix == ".toml":
        log = str(DATA / "parking.blf")
        refused(cli("stops", log, "--dbc", str(DATA / "imu_mm5_10.dbc"), "--mapping", str(spec), "-o", "-"), "levels")


def test_nesting_depth_is_exact_for_json_and_linear() -> None:
    cases = {
        b"[]": 1,
        b'{"a": [1, {"b": "[[[["}]}': 3,
        b'["\\\\", ["\\"]]"]]': 2,
        b'"\\\\\\"[" [': 1,
        b"": 0,
    }
    for raw, depth in cases.items():
        assert budget.nesting_depth(raw) == depth, raw
    assert budget.nesting_depth(b'"[" [', strings=False) == 2  # TOML: every bracket counts


def test_nesting_depth_is_the_same_across_scan_pieces(monkeypatch: pytest.MonkeyPatch) -> None:
    doc = json.dumps({"a\\": ['"\\[', {"b": [[["]\\\\"]]]}], "c": "\\\\\\"}).encode()
    whole = budget.nesting_depth(doc)
    assert whole == 6
    for piece in (1, 2, 3, 7):
        monkeypatch.setattr(budget, "_SCAN_BYTES", piece)
        assert budget.nesting_depth(doc) == whole, piece


# --------------------------------------------------------------------------- time


def test_plan_with_a_million_stops_is_refused_at_once() -> None:
    """`plan --max-stops 1000000` never ended (3 000 stops took 155 s): the count has a stated maximum."""
    code, stderr, _, seconds = cli("plan", "--target", "roll=0.1", "--noise", "1", "--max-stops", "1000000", timeout=60)
    assert code == 2 and "--max-stops" in stderr and "[3, 100]" in stderr, stderr
    assert seconds < 30
