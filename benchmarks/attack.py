"""Hostile inputs against every command (issue 27): a reproducible harness, counted per category.

The inputs are generated into a temporary folder (the big ones of the issue too: a 64 MB BLF of
two million empty containers, a 32 MB CSV of a million columns, a 10⁷-row stop table, a 250 MB
result JSON, ...), from copies of the sample data, with the real writers (python-can, mcap) or by
byte construction around their output. Every command runs in its own process:

- under a memory cap: ``RLIMIT_AS`` (address space) of ``--cap-gb`` (default 4 GiB), set in the
  child before ``exec`` (a cgroup is not used: it needs privileges the CI runner may lack; the cap
  is per process, so fleet workers each have it);
- under a time bound (``--timeout``, default 180 s): the process group is killed past it (a hang);
- in a new session, its peak RSS read from ``wait4`` (``ru_maxrss``: the command and the children
  it waited for).

Counted per category, for each command:

- **traceback**: ``Traceback`` on stderr;
- **hang**: killed at the time bound;
- **input changed**: an input's bytes (SHA-256), or its kind (a FIFO, a device), differ afterwards;
- **unclear exit**: killed by a signal, an exit code outside 0, 2, 3, 4, 5, 129, 130, 143, or a non-zero exit
  without an ``error:`` line (or, for exit 3, the answer line saying not confident or not reachable);
- **over bound**: peak RSS above ``A · (input bytes) + B`` (the bound of docs/reliability.md);
- **other**: what the case checks beyond these (stdout that no longer parses, a NaN in a written
  file, an output written over an input, a temporary file left behind, ...).

Run from the repository root (``--only`` picks categories; ``--json`` keeps every run)::

    PYTHONPATH=src python benchmarks/attack.py --json /tmp/attack.json

The categories of issue 27 that other work fixes (outputs over inputs, library noise on stdout,
fleet and live faults, plugins, truncated files) are here too, so the harness can be re-run on
the merged code.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import shutil
import signal
import stat
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
MIB = 1 << 20
# The memory bound of docs/reliability.md: peak RSS ≤ A · (bytes of the command's inputs) + B.
BOUND_A = 64.0
BOUND_B_MB = 1024.0
CLEAR_EXITS = {0, 2, 3, 4, 5, 129, 130, 143}  # mountcal.cli.options.EXIT_CODES (129, 143: SIGHUP, SIGTERM)
CATEGORIES = {
    "readers": "every reader and command on sound inputs (the memory bound)",
    "memory": "2. memory bounded in total, not per block",
    "time": "3. time bounded",
    "numbers": "5. floats at the edge",
    "outputs": "1. outputs over inputs and devices",
    "noise": "4. library noise on stdout",
    "faults": "6. fleet and live under faults",
    "other": "7. everything else that was a traceback",
}


@dataclass
class Run:
    code: int | None  # None: killed at the time bound
    signal: int | None
    stdout: bytes
    stderr: str
    peak_mb: float
    seconds: float


@dataclass
class Case:
    category: str
    name: str
    args: list[str]
    inputs: list[Path] = field(default_factory=list)  # hashed before and after; their size sets the bound
    env: dict[str, str] = field(default_factory=dict)
    check: Callable[[Run], str | None] | None = None  # an "other" finding, or None
    close_stdout: bool = False
    terminate_after_s: float | None = None  # send SIGTERM to the command after this long
    timeout_s: float | None = None


# --------------------------------------------------------------------------- running one case


def _fingerprint(path: Path) -> str:
    """What must not change: a file's bytes, a folder's files, a special file's kind."""
    try:
        st = os.lstat(path)
    except OSError:
        return "absent"
    if stat.S_ISLNK(st.st_mode):
        return f"symlink to {os.readlink(path)} / {_fingerprint(path.resolve()) if path.exists() else 'dangling'}"
    if stat.S_ISDIR(st.st_mode):
        return hashlib.sha256(
            "".join(f"{p.relative_to(path)}:{_fingerprint(p)};" for p in sorted(path.rglob("*"))).encode()
        ).hexdigest()
    if not stat.S_ISREG(st.st_mode):
        return f"special {stat.S_IFMT(st.st_mode)}"
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(1 << 22):
            digest.update(chunk)
    return digest.hexdigest()


def _size(path: Path) -> int:
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink())
        return path.stat().st_size if path.is_file() else 0
    except OSError:
        return 0


def execute(case: Case, workdir: Path, src: Path, cap_bytes: int, timeout_s: float) -> Run:
    """Run ``mountcal ARGS`` in its own session under the caps; its peak RSS from ``wait4``."""
    extra = case.env.get("PYTHONPATH_EXTRA")  # a plugin's folder
    env = {**os.environ, **case.env, "PYTHONPATH": os.pathsep.join([str(src), *([extra] if extra else [])])}
    out_path, err_path = workdir / ".stdout", workdir / ".stderr"

    def limits() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (cap_bytes, cap_bytes))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        if case.close_stdout:
            os.close(1)

    start = time.monotonic()
    with out_path.open("wb") as out, err_path.open("wb") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "mountcal", *case.args],
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=err,
            cwd=workdir,
            env=env,
            preexec_fn=limits,
            start_new_session=True,
        )
    bound = case.timeout_s or timeout_s
    killed, termed = False, False
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        elapsed = time.monotonic() - start
        if case.terminate_after_s is not None and not termed and elapsed > case.terminate_after_s:
            os.kill(proc.pid, signal.SIGTERM)
            termed = True
        if elapsed > bound and not killed:
            os.killpg(proc.pid, signal.SIGKILL)
            killed = True
        time.sleep(0.05)
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
    if not killed:  # the command's own children (fleet workers) must not outlive it
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    code = None if killed else (proc.returncode if proc.returncode >= 0 else None)
    sig = -proc.returncode if proc.returncode < 0 and not killed else None
    return Run(
        code,
        sig,
        out_path.read_bytes(),
        err_path.read_text(errors="replace"),
        usage.ru_maxrss / 1024,
        time.monotonic() - start,
    )


def _said(run: Run) -> bool:
    """A non-zero exit came with a message: a ``mountcal: …`` or ``mountcal CMD: error: …`` line on
    stderr, or, for exit 3 (an answer that is not confident, a plan not reachable), the answer on the
    first line of stderr saying so."""
    first = run.stderr.lstrip().split("\n", 1)[0]
    answered = run.code == 3 and bool(re.search(r"not reachable|NOT CONFIDENT", first))
    return _message(run.stderr) or answered


def _message(stderr: str) -> bool:
    return bool(re.search(r"^mountcal( [a-z]+)?: \S", stderr, re.MULTILINE))


def judge(case: Case, run: Run, changed: list[str], size: int) -> dict[str, str]:
    """The findings of one run, by kind (empty: clean)."""
    found: dict[str, str] = {}
    if "Traceback" in run.stderr:
        found["traceback"] = run.stderr.strip().splitlines()[-1][:200]
    if run.code is None and run.signal is None:
        found["hang"] = f"killed after {run.seconds:.0f} s"
    if changed:
        found["input changed"] = ", ".join(changed)
    if run.signal is not None and not (case.terminate_after_s is not None and run.signal == signal.SIGTERM):
        found["unclear exit"] = f"killed by signal {run.signal}"
    elif run.code is not None and (run.code not in CLEAR_EXITS or (run.code != 0 and not _said(run))):
        found["unclear exit"] = f"exit {run.code}: {run.stderr.strip()[-200:]!r}"
    bound = BOUND_A * size / MIB + BOUND_B_MB
    if run.peak_mb > bound:
        found["over bound"] = f"peak RSS {run.peak_mb:.0f} MB > {bound:.0f} MB"
    if case.check is not None and run.code is not None:
        other = case.check(run)
        if other:
            found["other"] = other
    return found


# --------------------------------------------------------------------------- checks beyond the counts


def stdout_parses(kind: str) -> Callable[[Run], str | None]:
    def check(run: Run) -> str | None:
        if run.code != 0:
            return None
        text = run.stdout.decode("utf-8", errors="replace")
        try:
            if kind == "json":
                json.loads(text, parse_constant=_refuse_constant)
            else:
                import io

                import pandas as pd

                pd.read_csv(io.StringIO(text))
        except Exception as err:
            return f"stdout is not {kind}: {type(err).__name__}: {str(err)[:100]}"
        return None

    return check


def _refuse_constant(name: str) -> float:
    raise ValueError(f"the literal {name}")


def written_finite(path: Path) -> Callable[[Run], str | None]:
    """A written JSON or text file holds no NaN or infinity."""

    def check(run: Run) -> str | None:
        if not path.exists():
            return None
        text = path.read_text(errors="replace")
        if path.suffix == ".json":
            try:
                json.loads(text, parse_constant=_refuse_constant)
            except ValueError as err:
                return f"{path.name}: {err}"
            return None
        return f"{path.name} holds {m.group(0)}" if (m := re.search(r"\b(nan|NaN|inf|Infinity)\b", text)) else None

    return check


def nothing_left(folder: Path, keep: set[str]) -> Callable[[Run], str | None]:
    """No file beyond ``keep`` (hidden temporary files included) in ``folder`` after a refusal or a signal."""

    def check(run: Run) -> str | None:
        extra = sorted(p.name for p in folder.iterdir() if p.name not in keep and not p.name.startswith(".std"))
        return f"left {', '.join(extra)}" if extra else None

    return check


def both(*checks: Callable[[Run], str | None]) -> Callable[[Run], str | None]:
    def check(run: Run) -> str | None:
        return "; ".join(f for c in checks if (f := c(run))) or None

    return check


def refused(run: Run) -> str | None:
    return "accepted (exit 0)" if run.code == 0 else None


def wrote(path: Path) -> Callable[[Run], str | None]:
    def check(run: Run) -> str | None:
        return f"exit 0 without writing {path.name}" if run.code == 0 and not path.exists() else None

    return check


# --------------------------------------------------------------------------- inputs


def _mountcal(src: Path, *args: str, cwd: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(src)}
    done = subprocess.run([sys.executable, "-m", "mountcal", *args], cwd=cwd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"mountcal {' '.join(args)}: {done.stderr}")


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def mcap_of_chunks(path: Path, records: bytes, chunks: int, level: int = 19) -> Path:
    """Header, an Imu schema and channel from mcap's Writer, then ``chunks`` zstd chunks of ``records``."""
    import zstandard
    from mcap.writer import CompressionType, Writer

    from mountcal.io.ros2.definitions import ros2_definition

    real = path.with_suffix(".writer.mcap")
    with real.open("wb") as f:
        writer = Writer(f, compression=CompressionType.NONE, use_chunking=False)
        writer.start(profile="ros2", library="attack")
        schema = writer.register_schema(
            "sensor_msgs/msg/Imu", "ros2msg", ros2_definition("sensor_msgs/msg/Imu").encode()
        )
        writer.register_channel("/imu", "cdr", schema)
        writer.finish()
    raw = real.read_bytes()
    real.unlink()
    pos = 8 + 9 + struct.unpack_from("<Q", raw, 9)[0]
    out = bytearray(raw[:pos])
    while raw[pos] != 0x0F:
        length = struct.unpack_from("<Q", raw, pos + 1)[0]
        if raw[pos] in (0x03, 0x04):
            out += raw[pos : pos + 9 + length]
        pos += 9 + length
    data = zstandard.ZstdCompressor(level=level).compress(records)
    body = struct.pack("<QQQI", 0, 0, len(records), 0) + struct.pack("<I", 4) + b"zstd"
    chunk = _record(0x06, body + struct.pack("<Q", len(data)) + data)
    out += chunk * chunks + _record(0x0F, struct.pack("<I", 0)) + _record(0x02, struct.pack("<QQI", 0, 0, 0)) + raw[:8]
    path.write_bytes(bytes(out))
    return path


def blf_of_empty_containers(path: Path, count: int) -> Path:
    import can

    real = path.with_suffix(".writer.blf")
    with can.BLFWriter(str(real)):
        pass
    raw = real.read_bytes()
    real.unlink()
    header = raw[: struct.unpack_from("<L", raw, 4)[0]]
    container = struct.pack("<4sHHLL", b"LOBJ", 16, 1, 32, 10) + struct.pack("<H6xL4x", 0, 0)
    with path.open("wb") as f:
        f.write(header)
        for _ in range(count // 100_000):
            f.write(container * 100_000)
        f.write(container * (count % 100_000))
    return path


def blf_of_ids(path: Path, count: int) -> Path:
    """A BLF from python-can's BLFWriter: ``count`` frames, each with its own extended id."""
    import can

    with can.BLFWriter(str(path), compression_level=9) as writer:
        for k in range(count):
            writer.on_message_received(can.Message(timestamp=1 + k * 1e-4, arbitration_id=k, data=b""))
    return path


def imu_mcap(path: Path, chunk_bytes: int, chunks: int) -> Path:
    import numpy as np

    from mountcal.io.ros2.imu import ImuMessages, encode_imu_messages

    msgs = ImuMessages.unknown_orientation(np.full(1, 10**18, np.int64), None, np.array([[0.0, 0.0, 9.81]]))
    payload = encode_imu_messages(msgs, "imu")[0].tobytes()
    record = _record(0x05, struct.pack("<HIQQ", 1, 0, 10**18, 10**18) + payload)
    return mcap_of_chunks(path, record * (chunk_bytes // len(record)), chunks)


def stamped_imu_mcap(path: Path, chunk_bytes: int, chunks: int) -> Path:
    """IMU messages identical but for their stamps (5 ms apart), compressed at zstd's level 19: about
    60-fold, within the ratio, so the whole log is read: the worst a compressed log can hold per byte."""
    import numpy as np

    from mountcal.io.ros2.imu import ImuMessages, encode_imu_messages

    n = chunk_bytes // 347
    t = 10**18 + np.arange(n, dtype=np.int64) * 5_000_000
    rows = encode_imu_messages(ImuMessages.unknown_orientation(t, None, np.tile([0.0, 0.0, 9.81], (n, 1))), "imu")
    head = np.zeros((n, 31), np.uint8)
    head[:, 0] = 0x05
    head[:, 1:9] = np.full(n, 22 + rows.shape[1], "<u8").view(np.uint8).reshape(n, 8)
    head[:, 9] = 1  # channel id
    head[:, 15:23] = head[:, 23:31] = t.astype("<u8").view(np.uint8).reshape(n, 8)
    return mcap_of_chunks(path, np.concatenate([head, rows], axis=1).tobytes(), chunks, level=19)


def message_records(size: int) -> bytes:
    pair = _record(0x05, struct.pack("<HIQQ", 1, 0, 1, 1)) + _record(0x05, struct.pack("<HIQQ", 1, 0, 2, 2) + b"x")
    return pair * (size // len(pair))


def orientations(path: Path) -> Path:
    import numpy as np
    import pandas as pd

    grid = np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).reshape(3, -1).T
    directions = [v for v in grid if 0 < abs(v).sum() < 3]
    acc = np.array([9.80665 * v / np.linalg.norm(v) for v in directions])
    acc += np.random.default_rng(1).normal(0, 1e-3, acc.shape)
    pd.DataFrame(acc, columns=["ax", "ay", "az"]).assign(sx=0.01, sy=0.01, sz=0.01, n=100).to_csv(path, index=False)
    return path


def install_plugin(folder: Path, module: str, source: str) -> str:
    """A reader plugin the way pip leaves one: a module and its dist-info; the PYTHONPATH entry."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{module}.py").write_text(source)
    info = folder / f"{module}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[mountcal.readers]\n{module} = {module}:Reader\n")
    return str(folder)


PLUGIN_READER = """
from mountcal.io.reader import LogReader
{prelude}

class Reader(LogReader):
    name = "attack"
    suffixes = (".attack",)
    description = "attack"

    def claims(self, path, options):
        {claims}

    def read(self, path, options):
        {read}
"""


# --------------------------------------------------------------------------- the cases


def build(root: Path, src: Path, quick: bool, only: set[str]) -> list[Case]:
    """Generate the inputs under ``root`` and list the cases (``quick``: the big inputs smaller)."""
    import numpy as np
    import pandas as pd

    base = root / "base"
    base.mkdir()
    for name in ("zhang2011_stops.csv", "parking.mcap", "parking.blf", "parking.mf4", "parking_protocol.csv"):
        shutil.copy(DATA / name, base / name)
    dbc, mapping = base / "imu.dbc", base / "imu.toml"
    shutil.copy(DATA / "imu_mm5_10.dbc", dbc)
    shutil.copy(DATA / "imu_mm5_10.toml", mapping)
    stops, protocol = base / "zhang2011_stops.csv", base / "parking_protocol.csv"
    mcap, blf, mf4 = base / "parking.mcap", base / "parking.blf", base / "parking.mf4"
    result = base / "result.json"
    _mountcal(src, "calibrate", str(stops), "-o", str(result), "-q", cwd=base)
    text_logs = [base / f"sim.{fmt}" for fmt in ("asc", "log", "trc", "csv")]
    _mountcal(src, "simulate", "--log", *map(str, text_logs), "--dbc", str(dbc), "-q", cwd=base)
    samples_csv, samples_pq = base / "samples.csv", base / "samples.parquet"
    for out in (samples_csv, samples_pq):
        _mountcal(src, "rotate", str(mcap), "--calibration", str(result), "-o", str(out), "-q", cwd=base)
    faces = orientations(base / "faces.csv")
    triad = base / "triad.json"
    _mountcal(src, "triad", str(faces), "-o", str(triad), "-q", cwd=base)
    identity = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    imucal_doc = {"cal_type": "Ferraris", "acc_unit": "m/s^2", "K_a": identity, "R_a": identity, "b_a": [0, 0, 0]}
    spec = base / "spec.toml"
    spec.write_text("scale = 0.01\n")
    cases: list[Case] = []

    def case(category: str, name: str, args: list[str | Path], inputs: list[Path], **kw: object) -> None:
        cases.append(Case(category, name, [str(a) for a in args], inputs, **kw))  # type: ignore[arg-type]

    def fresh(name: str) -> Path:
        slug = re.sub(r"\W+", "_", name)[:60]
        folder = root / f"{len(list(root.iterdir())):03d}_{slug}"
        folder.mkdir()
        return folder

    # ---- readers: sound inputs, every reader and command (the bound on ordinary work)
    if "readers" in only:
        logs: list[tuple[Path, list[str | Path]]] = [
            (mcap, []),
            (blf, ["--dbc", dbc, "--protocol", protocol]),
            (mf4, ["--dbc", dbc, "--protocol", protocol]),
            *[(p, ["--dbc", dbc]) for p in text_logs],
            (samples_csv, []),
            (samples_pq, []),
        ]
        for log, options in logs:
            out = fresh(f"readers {log.name}")
            extra = [p for p in options if isinstance(p, Path)]
            case(
                "readers",
                f"inspect {log.name}",
                ["inspect", log, *[o for o in options if o == "--dbc" or o == dbc]],
                [log],
            )
            case("readers", f"stops {log.name}", ["stops", log, *options, "-o", out / "s.csv"], [log, *extra])
            case("readers", f"calibrate {log.name}", ["calibrate", log, *options, "-o", out / "r.json"], [log, *extra])
            case(
                "readers",
                f"rotate {log.name}",
                [
                    "rotate",
                    log,
                    *[o for o in options if o != "--protocol" and o != protocol],
                    "--calibration",
                    result,
                    "-o",
                    out / "v.parquet",
                    "--level-only",
                ],
                [log, result, *[p for p in extra if p != protocol]],
            )
        out = fresh("readers misc")
        case(
            "readers",
            "calibrate stop table",
            ["calibrate", stops, "-o", out / "r.json", "--report", out / "r.html"],
            [stops],
        )
        case("readers", "report", ["report", result, "--stops", stops, "-o", out / "rep.html"], [result, stops])
        case("readers", "export yaml", ["export", result, "--to", "yaml", "-o", out / "m.yaml"], [result])
        case("readers", "plan", ["plan", "--target", "roll=1,pitch=1,yaw=3", "--noise", "1"], [])
        case("readers", "plan --from-log", ["plan", "--target", "roll=0.2", "--from-log", mcap], [mcap])
        case("readers", "triad", ["triad", faces, "-o", out / "t.json"], [faces])
        case("readers", "simulate --log", ["simulate", "--log", out / "s.mcap", out / "s.blf", "--dbc", dbc], [dbc])
        case("readers", "fleet", ["fleet", stops, mcap, "-o", out / "fleet.parquet", "--workers", "1"], [stops, mcap])

    # ---- 2. memory
    if "memory" in only:
        big = root / "big"
        big.mkdir()
        empty = blf_of_empty_containers(big / "empty.blf", 200_000 if quick else 2_000_000)
        case("memory", f"inspect BLF of {_mb(empty)} of empty containers", ["inspect", empty], [empty])
        case("memory", "stops BLF of empty containers", ["stops", empty, "--dbc", dbc, "-o", "-"], [empty])
        msgs = mcap_of_chunks(big / "msgs.mcap", message_records(256 * MIB - 1024), 2 if quick else 12)
        case("memory", f"inspect MCAP of {_kb(msgs)} inflating 10⁴-fold", ["inspect", msgs], [msgs])
        case("memory", "stops MCAP inflating 10⁴-fold", ["stops", msgs, "-o", "-"], [msgs])
        imu = imu_mcap(big / "imu.mcap", 256 * MIB - 1024, 2 if quick else 14)
        case("memory", f"calibrate IMU MCAP of {_kb(imu)} of repeated messages", ["calibrate", imu], [imu])
        case(
            "memory",
            "rotate IMU MCAP of repeated messages",
            ["rotate", imu, "--calibration", result, "-o", fresh("memory rotate") / "v.parquet", "--level-only"],
            [imu, result],
        )
        stamped = stamped_imu_mcap(big / "stamped.mcap", 64 * MIB, 3 if quick else 16)
        ratio = 64 * MIB * (3 if quick else 16) / stamped.stat().st_size
        case(
            "memory",
            f"calibrate IMU MCAP of {_mb(stamped)} inflating {ratio:.0f}-fold (read whole)",
            ["calibrate", stamped, "--use", "stops"],
            [stamped],
        )
        case(
            "memory",
            f"rotate the same {_mb(stamped)}",
            [
                "rotate",
                stamped,
                "--calibration",
                result,
                "-o",
                fresh("memory rotate stamped") / "v.parquet",
                "--level-only",
            ],
            [stamped, result],
        )
        ids = blf_of_ids(big / "ids.blf", 100_000 if quick else 1_500_000)
        case("memory", f"inspect BLF of {_mb(ids)}, one id per frame", ["inspect", ids], [ids])
        wide = big / "wide.csv"
        columns = 100_000 if quick else 1_000_000
        wide.write_text(
            ",".join(["t_s", "ax", "ay", "az", *(f"column_{k:07d}" for k in range(columns))])
            + "\n"
            + ",".join(["0", "0", "0", "9.81", *(["0"] * columns)])
            + "\n"
        )
        case("memory", f"inspect CSV of {columns} columns ({_mb(wide)})", ["inspect", wide], [wide])
        case("memory", "calibrate CSV of many columns", ["calibrate", wide], [wide])
        for rows in (10**5, 10**6) if quick else (10**6, 10**7):
            long = big / f"stops_{rows}.csv"
            with long.open("w") as f:
                f.write("ax,ay,az\n")
                for _ in range(rows // 10**5):
                    f.write("0.1,0.2,9.8\n" * 10**5)
            case("memory", f"calibrate stop table of {rows} rows ({_mb(long)})", ["calibrate", long], [long])
        huge = big / "huge_result.json"
        doc = json.loads(result.read_text())
        doc["notes"] = doc["notes"] + ["x" * 1000] * (25_000 if quick else 250_000)
        huge.write_text(json.dumps(doc))
        for cmd in (
            ["export", huge, "--to", "json", "-o", "-"],
            ["report", huge, "-o", fresh("memory report") / "r.html"],
        ):
            case("memory", f"{cmd[0]} result JSON of {_mb(huge)}", cmd, [huge])
        case(
            "memory",
            "rotate with a result JSON of many MB",
            ["rotate", mcap, "--calibration", huge, "-o", fresh("memory rotate huge") / "v.parquet"],
            [mcap, huge],
        )
        for cmd in (["calibrate", stops], ["plan", "--target", "roll=1", "--noise", "1"]):
            case("memory", f"{cmd[0]} --sensor-spec /dev/zero", [*cmd, "--sensor-spec", "/dev/zero"], [stops])

    # ---- 3. time
    if "time" in only:
        quotes = root / "quotes.json"
        quotes.write_bytes(b'{"a": "' + b'\\"' * 60_000)
        imucal_quotes = root / "imucal_quotes.json"
        imucal_quotes.write_bytes(quotes.read_bytes())
        out = fresh("time")
        for name, cmd in (
            ("export", ["export", quotes, "--to", "json", "-o", "-"]),
            ("rotate", ["rotate", mcap, "--calibration", quotes, "-o", out / "v.parquet"]),
            ("report", ["report", quotes, "-o", out / "r.html"]),
            ("calibrate --triad", ["calibrate", stops, "--triad", quotes]),
            ("triad --imucal", ["triad", faces, "--imucal", imucal_quotes, "-o", out / "t.json"]),
        ):
            case(
                "time",
                f"{name}: 120 KB of nested quotes",
                cmd,
                [p for p in cmd if isinstance(p, Path) and p.parent != out],
            )
        case(
            "time",
            "plan --max-stops 1000000",
            ["plan", "--target", "roll=0.1", "--noise", "1", "--max-stops", "1000000"],
            [],
        )
        case(
            "time",
            "plan --max-stops 100, unreachable",
            ["plan", "--target", "roll=0.001", "--noise", "1", "--max-stops", "100"],
            [],
        )

    # ---- 5. numbers
    if "numbers" in only:
        table = pd.read_csv(stops)
        for column, value in (
            ("sx", 1e-170),
            ("sx", 1e-160),
            ("sx", 1e160),
            ("sx", 1e170),
            ("n", 1e308),
            ("n", -1e308),
            ("sx_mean", 1e308),
            ("sx_mean", -1e308),
            ("sx_mean", 1e-300),
            ("temperature_c", 1e308),
            ("temperature_c", -1e308),
            ("alt_m", 1e308),
            ("alt_m", -1e308),
            ("lat_deg", 1e308),
            ("t_s", 1e308),
        ):
            edge = table.assign(n=100.0)
            if column == "sx_mean":
                edge = edge.assign(sx_mean=0.001, sy_mean=0.001, sz_mean=0.001)
            edge[column] = edge[column].astype(float) if column in edge else np.arange(len(edge), dtype=float)
            edge.loc[0, column] = value
            path = root / f"edge_{column}_{value:g}.csv"
            edge.to_csv(path, index=False)
            models = ["auto"] + (["rotation,slope,temperature"] if column == "temperature_c" else [])
            for model in models:
                r = fresh(f"numbers {path.stem} {model}") / "r.json"
                case(
                    "numbers",
                    f"calibrate stop table {column} = {value:g} ({model})",
                    ["calibrate", path, "-o", r, "--model", model],
                    [path],
                    check=written_finite(r),
                )
        sigma = json.loads(result.read_text())
        sigma["uncertainty"] |= {"roll_deg": 1e300, "pitch_deg": 1e300, "rotation_about_vehicle_xyz_deg": [1e300] * 3}
        huge_sigma = root / "sigma_1e300.json"
        huge_sigma.write_text(json.dumps(sigma))
        out = fresh("numbers sigma")
        for to in ("json", "yaml"):
            case(
                "numbers",
                f"export --to {to} of a result with σ = 1e300",
                ["export", huge_sigma, "--to", to, "-o", out / f"m.{to}"],
                [huge_sigma],
                check=written_finite(out / f"m.{to}"),
            )
        case("numbers", "report of a result with σ = 1e300", ["report", huge_sigma, "-o", out / "r.html"], [huge_sigma])
        case("numbers", "--slope-reference 5 1e308", ["calibrate", stops, "--slope-reference", "5", "1e308"], [stops])
        case(
            "numbers", "MOUNTCAL_MAX_INPUT_MB=inf", ["calibrate", stops], [stops], env={"MOUNTCAL_MAX_INPUT_MB": "inf"}
        )
        for key, value in (
            ("K_a", [[1e308, 0, 0], [0, 1, 0], [0, 0, 1]]),
            ("R_a", [[1, 1e308, 0], [0, 1, 0], [0, 0, 1]]),
            ("b_a", [0, 0, 1e308]),
        ):
            imucal = root / f"imucal_{key}.json"
            imucal.write_text(json.dumps(imucal_doc | {key: value}))
            case(
                "numbers",
                f"triad --imucal with {key} at 1e308",
                ["triad", faces, "--imucal", imucal, "-o", fresh(f"numbers imucal {key}") / "t.json"],
                [faces, imucal],
            )
        for extra in (["--noise", "5e-324"], ["--noise", "1", "--stop-s", "nan"], ["--noise", "1e308"]):
            case(
                "numbers",
                f"plan {' '.join(extra)}",
                ["plan", "--target", "roll=1", *extra],
                [],
                check=lambda run: "a nan or an empty reason" if re.search(rb"nan|because \.", run.stdout) else None,
            )
        for extra in (
            ["--rate-hz", "0"],
            ["--rate-hz", "-5"],
            ["--rate-hz", "1e9"],
            ["--stop-s", "0"],
            ["--drive-s", "-1"],
            ["--stop-s", "1e300"],
            ["--start-time", "1e300"],
            ["--start-time", "nan"],
            ["--seed", "-1"],
            ["--seed", "99999999999999999999"],
            ["--slope", "nan"],
            ["--fix", "1e308", "0", "0"],
            ["--acc-lsb", "inf"],
            ["--gyro-bias-dps", "1e308", "0", "0"],
            ["--bias-mg", "1e308", "0", "0"],
        ):
            folder = fresh(f"numbers simulate {' '.join(extra)}")
            case(
                "numbers",
                f"simulate --log {' '.join(extra)}",
                ["simulate", "--log", folder / "s.mcap", "--truth", folder / "t.json", *extra],
                [],
                check=written_finite(folder / "t.json"),
            )
        for extra in (["--noise-g", "nan"], ["--noise-g", "1e308"], ["--slope", "90"], ["--roll", "inf"]):
            folder = fresh(f"numbers simulate table {' '.join(extra)}")
            case(
                "numbers",
                f"simulate -o {' '.join(extra)}",
                ["simulate", "-o", folder / "s.csv", "--truth", folder / "t.json", *extra],
                [],
                check=written_finite(folder / "t.json"),
            )

    # ---- 1. outputs over inputs and devices (paths)
    if "outputs" in only:
        out = fresh("outputs")
        t_copy, spec_copy, i_copy = out / "t.json", out / "spec.toml", out / "i.json"
        shutil.copy(triad, t_copy)
        shutil.copy(spec, spec_copy)
        i_copy.write_text(json.dumps(imucal_doc))
        log_copy = out / "log.csv"
        shutil.copy(samples_csv, log_copy)
        dbc_copy = out / "b.dbc"
        shutil.copy(dbc, dbc_copy)
        fifo = out / "fifo"
        os.mkfifo(fifo)
        loop = out / "loop"
        loop.symlink_to(loop.name)
        case(
            "outputs",
            "calibrate --triad t.json -o t.json",
            ["calibrate", stops, "--triad", t_copy, "-o", t_copy],
            [stops, t_copy],
        )
        case(
            "outputs",
            "calibrate --sensor-spec S -o S",
            ["calibrate", stops, "--sensor-spec", spec_copy, "-o", spec_copy],
            [spec_copy],
        )
        case(
            "outputs",
            "calibrate --triad T --report T",
            ["calibrate", stops, "--triad", t_copy, "--report", t_copy],
            [t_copy],
        )
        case("outputs", "triad --imucal i.json -o i.json", ["triad", faces, "--imucal", i_copy, "-o", i_copy], [i_copy])
        case(
            "outputs",
            "plan --from-log log.csv -o log.csv",
            ["plan", "--target", "roll=1", "--from-log", log_copy, "-o", log_copy],
            [log_copy],
        )
        case(
            "outputs", "plan -o FIFO", ["plan", "--target", "roll=1", "--noise", "1", "-o", fifo], [fifo], timeout_s=60
        )
        case("outputs", "calibrate -o a symlink loop", ["calibrate", stops, "-o", loop], [loop])
        live = ["live", "--interface", "virtual", "--channel", "attack", "--timeout", "1"]
        case(
            "outputs",
            "live --json-events DBC",
            [*live, "--dbc", dbc_copy, "--json-events", dbc_copy],
            [dbc_copy],
            timeout_s=60,
        )
        case("outputs", "live --report DBC", [*live, "--dbc", dbc_copy, "--report", dbc_copy], [dbc_copy], timeout_s=60)
        case(
            "outputs",
            "live --json-events FIFO",
            [*live, "--dbc", dbc_copy, "--json-events", fifo],
            [fifo, dbc_copy],
            timeout_s=60,
        )

    # ---- 4. library noise on stdout: an MF4 missing its last 360 bytes
    if "noise" in only:
        cut = root / "cut.mf4"
        cut.write_bytes(mf4.read_bytes()[:-360])
        can_args: list[str | Path] = ["--dbc", dbc, "--protocol", protocol]
        case(
            "noise",
            "inspect --json of a cut MF4",
            ["inspect", cut, "--json", "--dbc", dbc],
            [cut],
            check=stdout_parses("json"),
        )
        case(
            "noise",
            "calibrate --json of a cut MF4",
            ["calibrate", cut, *can_args, "--json"],
            [cut],
            check=stdout_parses("json"),
        )
        case(
            "noise", "stops -o - of a cut MF4", ["stops", cut, *can_args, "-o", "-"], [cut], check=stdout_parses("csv")
        )

    # ---- 6. fleet and live under faults
    if "faults" in only:
        folder = fresh("faults fleet")
        shutil.copy(stops, folder / "a.csv")
        os.mkfifo(folder / "b.csv")
        folder2 = fresh("faults fleet loop")
        shutil.copy(stops, folder2 / "a.csv")
        (folder2 / "loop.csv").symlink_to("loop.csv")
        out = fresh("faults out")
        case(
            "faults",
            "fleet with a FIFO in its folder",
            ["fleet", folder, "-o", out / "f.parquet", "--workers", "1"],
            [folder],
            timeout_s=120,
        )
        case(
            "faults",
            "fleet with a symlink loop in its folder",
            ["fleet", folder2, "-o", out / "g.parquet", "--workers", "1"],
            [folder2],
        )
        case(
            "faults",
            "fleet --scheduler inproc://x",
            ["fleet", stops, "-o", out / "h.parquet", "--scheduler", "inproc://x"],
            [stops],
            timeout_s=60,
        )
        case("faults", "live --timeout -1", [*live[:-2], "--timeout", "-1", "--dbc", dbc], [dbc], timeout_s=60)
        case(
            "faults",
            "SIGTERM to fleet",
            ["fleet", stops, mcap, blf, "--dbc", dbc, "-o", out / "t.parquet", "--workers", "2"],
            [stops],
            terminate_after_s=8,
            timeout_s=60,
        )

    # ---- 7. everything else
    if "other" in only:
        for what, prelude, claims, read in (
            ("sys.exit(0) at import", "import sys\nsys.exit(0)", "return False", "raise RuntimeError"),
            ("a print at import", "print('plugin says hello')", "return False", "raise RuntimeError"),
            ("raising in claims()", "", "raise RuntimeError('claims')", "raise RuntimeError"),
            ("raising in read()", "", "return path.suffix == '.attack'", "raise RuntimeError('read')"),
        ):
            site = install_plugin(
                fresh(f"plugin {what}") / "site",
                "attack_plugin",
                PLUGIN_READER.format(prelude=prelude, claims=claims, read=read),
            )
            target = root / "x.attack"
            target.write_text("1 2 3\n")
            r = fresh(f"other plugin {what}") / "r.json"
            env = {"PYTHONPATH_EXTRA": site}
            case(
                "other",
                f"calibrate with a plugin {what}",
                ["calibrate", stops, "-o", r, "--json"],
                [stops],
                env=dict(env),
                check=both(wrote(r), stdout_parses("json")),
            )
            r2 = r.with_name("r2.json")
            case(
                "other",
                f"calibrate X.attack with a plugin {what}",
                ["calibrate", target, "-o", r2, "--json"],
                [target],
                env=dict(env),
                check=both(wrote(r2), stdout_parses("json")),
            )
        for suffix, text in (
            (".json", '{"scale": ' + "[" * 100_000 + "]" * 100_000 + "}"),
            (".toml", "scale = " + "[" * 100_000 + "]" * 100_000),
        ):
            deep = root / f"deep{suffix}"
            deep.write_text(text)
            case(
                "other",
                f"calibrate --sensor-spec of a deep {suffix}",
                ["calibrate", stops, "--sensor-spec", deep],
                [deep],
            )
        deep_mapping = root / "deep_mapping.toml"
        deep_mapping.write_text("[signals]\nax = " + "[" * 100_000 + "]" * 100_000)
        case(
            "other",
            "stops --mapping of a deep TOML",
            ["stops", blf, "--dbc", dbc, "--mapping", deep_mapping, "-o", "-"],
            [deep_mapping],
        )
        bad_mapping = root / "bad_mapping.toml"
        bad_mapping.write_bytes(mapping.read_bytes() + b"\n# \x81\n")
        bad_dbc = root / "bad.dbc"
        bad_dbc.write_bytes(dbc.read_bytes().replace(b'VERSION ""', b'VERSION "\x81"', 1))
        case(
            "other",
            "stops --mapping with byte 0x81",
            ["stops", blf, "--dbc", dbc, "--mapping", bad_mapping, "-o", "-"],
            [bad_mapping],
        )
        case("other", "stops --dbc with byte 0x81", ["stops", blf, "--dbc", bad_dbc, "-o", "-"], [bad_dbc])
        odd = fresh("other odd name")
        case(
            "other",
            "calibrate --report to a non-UTF-8 file name",
            ["calibrate", stops, "--report", os.fsdecode(bytes(odd) + b"/r\xff.html")],
            [stops],
        )
        can_dir = fresh("other can")
        import can

        messages = [
            can.Message(timestamp=1.0 + k * 0.01, arbitration_id=i, is_extended_id=False, data=bytes(8), channel=0)
            for k in range(100)
            for i in (0x070, 0x080, 0x576)
        ]
        candump, cancsv = can_dir / "a.log", can_dir / "a.csv"
        with can.CanutilsLogWriter(str(candump), channel="can0") as w1, can.CSVWriter(str(cancsv)) as w2:
            for msg in messages:
                w1.on_message_received(msg)
                w2.on_message_received(msg)
        for path, old, new, what in (
            (candump, "(1.000000)", "(nan)", "a NaN stamp"),
            (cancsv, "\n1.0,", "\nnan,", "a NaN stamp"),
            (cancsv, "\n1.01,0x70,", "\n1.01,-0x70,", "id -0x70"),
        ):
            bad = can_dir / f"{what.replace(' ', '_')}{path.suffix}"
            bad.write_text(path.read_text().replace(old, new, 1))
            for cmd in (
                ["inspect", bad, "--dbc", dbc],
                ["stops", bad, "--dbc", dbc, "-o", "-"],
                ["calibrate", bad, "--dbc", dbc],
            ):
                case("other", f"{cmd[0]} {path.suffix[1:]} log with {what}", cmd, [bad])
        case("other", "export >&-", ["export", result, "--to", "json", "-o", "-"], [result], close_stdout=True)
        sim = fresh("other simulate sigterm")
        case(
            "other",
            "SIGTERM to simulate",
            ["simulate", "--log", sim / "s.mcap", "--rate-hz", "1000", "--stop-s", "60"],
            [],
            terminate_after_s=3,
            check=nothing_left(sim, set()),
        )
    return cases


def _mb(path: Path) -> str:
    return f"{path.stat().st_size / 1e6:.1f} MB"


def _kb(path: Path) -> str:
    return f"{path.stat().st_size / 1e3:.0f} KB"


# --------------------------------------------------------------------------- main


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="+", choices=list(CATEGORIES), default=list(CATEGORIES))
    parser.add_argument("--cap-gb", type=float, default=4.0, help="RLIMIT_AS of each command (GiB)")
    parser.add_argument("--timeout", type=float, default=180.0, help="time bound of each command (s)")
    parser.add_argument("--quick", action="store_true", help="the big inputs at a tenth of their size")
    parser.add_argument("--src", type=Path, default=REPO / "src", help="the mountcal source to attack")
    parser.add_argument("--json", type=Path, default=None, help="write every run here")
    parser.add_argument("--keep", type=Path, default=None, help="generate into this folder and keep it")
    parser.add_argument("-k", default=None, help="only the cases whose name contains this")
    parser.add_argument("--table-from", type=Path, nargs="+", default=None, help="print the table of --json files")
    args = parser.parse_args()
    if args.table_from:  # the table of earlier runs (their findings; the bound recomputed)
        print(table([r for path in args.table_from for r in json.loads(path.read_text())]))
        return
    sys.path.insert(0, str(args.src))
    root = args.keep or Path(tempfile.mkdtemp(prefix="mountcal-attack-"))
    root.mkdir(parents=True, exist_ok=True)
    try:
        started = time.monotonic()
        cases = [
            c
            for c in build(root, args.src, args.quick, set(args.only))
            if c.category in args.only and (not args.k or args.k in c.name)
        ]
        print(f"generated {len(cases)} cases in {time.monotonic() - started:.0f} s under {root}", file=sys.stderr)
        records = []
        for n, case in enumerate(cases, 1):
            work = root / f"run_{n:03d}"
            work.mkdir()
            before = {str(p): _fingerprint(p) for p in case.inputs}
            size = sum(_size(p) for p in case.inputs)
            run = execute(case, work, args.src, int(args.cap_gb * (1 << 30)), args.timeout)
            changed = [Path(p).name for p, fp in before.items() if _fingerprint(Path(p)) != fp]
            found = judge(case, run, changed, size)
            records.append(
                {
                    "category": case.category,
                    "case": case.name,
                    "args": case.args,
                    "exit": run.code,
                    "signal": run.signal,
                    "seconds": round(run.seconds, 2),
                    "peak_mb": round(run.peak_mb, 1),
                    "input_mb": round(size / MIB, 3),
                    "findings": found,
                    "stderr_tail": run.stderr.strip()[-300:],
                }
            )
            mark = "; ".join(f"{k}: {v}" for k, v in found.items()) or "clean"
            print(
                f"[{n}/{len(cases)}] {case.category:<8} {case.name[:70]:<70} exit {run.code} "
                f"{run.seconds:6.1f} s {run.peak_mb:6.0f} MB  {mark[:160]}",
                file=sys.stderr,
                flush=True,
            )
        print(table(records))
        if args.json:
            args.json.write_text(json.dumps(records, indent=1))
    finally:
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)


KINDS = ("traceback", "hang", "input changed", "unclear exit", "over bound", "other")


def table(records: list[dict[str, object]]) -> str:
    """The result table of docs/reliability.md: per category, the cases and each kind of finding."""
    head = "| category | commands | " + " | ".join(KINDS) + " | clean | slowest | highest peak RSS (× bound) |"
    lines = [head, "|" + "---|" * (len(KINDS) + 5)]
    for category, label in CATEGORIES.items():
        rows = [r for r in records if r["category"] == category]
        if not rows:
            continue
        for r in rows:  # the bound and the message rule as stated now (a kept run may have used others)
            over = float(r["peak_mb"]) > BOUND_A * float(r["input_mb"]) + BOUND_B_MB  # type: ignore[arg-type]
            findings = {k: v for k, v in r["findings"].items() if k != "over bound"}  # type: ignore[attr-defined]
            if r["signal"] is None and r["exit"] in CLEAR_EXITS and _message(str(r["stderr_tail"])):
                findings.pop("unclear exit", None)
            r["findings"] = findings | ({"over bound": f"peak RSS {r['peak_mb']} MB"} if over else {})
        counts = [sum(1 for r in rows if kind in r["findings"]) for kind in KINDS]  # type: ignore[operator]
        clean = sum(1 for r in rows if not r["findings"])
        slowest = max(float(r["seconds"]) for r in rows)  # type: ignore[arg-type]
        worst = max(rows, key=lambda r: float(r["peak_mb"]) / (BOUND_A * float(r["input_mb"]) + BOUND_B_MB))  # type: ignore[arg-type]
        ratio = float(worst["peak_mb"]) / (BOUND_A * float(worst["input_mb"]) + BOUND_B_MB)  # type: ignore[arg-type]
        lines.append(
            f"| {label} | {len(rows)} | "
            + " | ".join(str(c) for c in counts)
            + f" | {clean} | {slowest:.1f} s | {float(worst['peak_mb']):.0f} MB ({ratio:.2f}) |"  # type: ignore[arg-type]
        )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
